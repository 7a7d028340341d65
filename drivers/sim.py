"""The simulated rig: a peer backend of the serial and CAN drivers, stepping the plant model.

The plant advances to the host time each ``read`` is given, so the same backend runs on a
virtual clock (deterministic, as fast as the CPU allows) or on the real clock; the loop chooses.
The sensor model quantises both encoders (counts per revolution from the config) and adds
seeded Gaussian noise to the angles and the measured current when the config asks for it.
Each encoder's last count change is timed on the plant's continuous trajectory
(:mod:`sashil.drivers.encoder_edges`): the samples carry it as a board's timer capture does. The
backend can play the drop-test operator (:meth:`operator_hold`), and its road wheel obeys
``RigCommand.road_speed_rad_s`` as a real board's road motor does (:class:`RoadWheel`), so a plan
drives the road the same way on every backend. Being a simulation it also reports what no sensor
measures, the plant's true damper torque and arm acceleration (:meth:`plant_truth`, declared as
the capability ``true_torque``).
"""

from __future__ import annotations

import math
import random
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from sashil.config.parts import RigParts
from sashil.drivers.interface import (
    FLAG_HELD,
    NO_EDGE,
    TWO_PI,
    PlantTruth,
    RigCapabilities,
    RigCommand,
    RigInterface,
    RigSample,
    RigState,
    clamp_current,
)
from sashil.drivers.mismatch import plant_parts
from sashil.drivers.sim_advance import advance
from sashil.errors import DriverError
from sashil.models.hysteresis import rig_params
from sashil.models.plant import RigPlant


class RoadWheel:
    """Road-side angle under speed commands: theta1(t) = theta1(t_k) + w_k (t - t_k) (a road profile).

    A speed command is a step of the road wheel's speed (a motor with a fast speed loop), an
    impulse of road acceleration that the plant's smooth road force -J*theta1_ddot cannot carry:
    :meth:`set_speed` applies it to the plant as the jump it causes. The arm keeps its absolute
    rate theta2_dot, so the relative rate theta_dot = theta2_dot - theta1_dot drops by the speed
    change (unless the operator holds the arm).
    """

    #: theta1_ddot is 0 between speed commands (the plant skips the road's force)
    accelerates = False

    def __init__(self) -> None:
        self._t0 = 0.0
        self._theta0 = 0.0
        self.speed_rad_s = 0.0

    def set_speed(self, plant: RigPlant, speed_rad_s: float) -> None:
        """Step the wheel to ``speed_rad_s`` at the plant's present time."""
        t_s = plant.state.time_s
        self._theta0 = self(t_s)[0]
        self._t0 = t_s
        if not plant.held:
            plant.state.theta_dot_rad_s -= speed_rad_s - self.speed_rad_s
        plant.state.theta_road_dot_rad_s = speed_rad_s
        self.speed_rad_s = speed_rad_s

    def __call__(self, t_s: float) -> tuple[float, float, float]:
        return self._theta0 + self.speed_rad_s * (t_s - self._t0), self.speed_rad_s, 0.0


class SimulatedRig(RigInterface):
    """The SAS rig simulated in-process (seed 001 model + coil lag + encoder + noise).

    Its plant's road is its own wheel (:class:`RoadWheel`) and the plant has no input torque: a read
    steps the plant with :func:`sashil.drivers.sim_advance.advance`, which knows that road."""

    name = "sim"
    capabilities = RigCapabilities(
        operator_hold=True,
        initial_current=True,
        road_actuator=True,
        max_rate_hz=10_000.0,
        simulated=True,
        true_torque=True,
    )

    def __init__(
        self,
        plant: RigPlant,
        counts_per_rev: int = 4096,
        angle_noise_rad: float = 0.0,
        current_noise_a: float = 0.0,
        noise_seed: int = 0,
    ):
        super().__init__()
        self.plant = plant
        self.counts_per_rev = int(counts_per_rev)
        self._counts_per_rad = self.counts_per_rev / TWO_PI
        self._count_rad = TWO_PI / self.counts_per_rev  # one count [rad]
        self.angle_noise_rad = float(angle_noise_rad)
        self.current_noise_a = float(current_noise_a)
        self._rng = random.Random(noise_seed)
        self._command = 0.0
        self._seq = 0
        self._t0_ns: int | None = None
        self._last_ns = 0
        self._release_at_s: float | None = None
        #: the road motor: the plant's road angle under the speed commands
        self.wheel = RoadWheel()
        plant.road = self.wheel
        #: each encoder's last count change: (host time [ns], direction +1/-1), or None (none yet)
        self.arm_edge: tuple[int, int] | None = None
        self.road_edge: tuple[int, int] | None = None
        self._arm_end: float | None = None  # the angles at the end of the last step (a jump since: an edge)
        self._road_end: float | None = None
        self._split_s = -1.0
        self._split = (1, 0.0, 0.0)  # a read's sub-steps, their length and the coil's decay over one
        #: the compiled step's arguments that stay for the run: one count [rad], the plant's coefficients
        self._constants = np.array((self._count_rad, *plant._coefficients), dtype=np.float64)

    #: the config keys the simulated rig is built from (:meth:`from_parts`)
    reads: ClassVar[Mapping[str, str]] = {"model": "model", "rig": "rig", "mismatch": "mismatch"}

    @classmethod
    def from_parts(cls, parts: RigParts) -> SimulatedRig:
        """The rig of the ``model`` and ``rig`` sections, after the ``mismatch`` section (the plant, not the model)."""
        if parts.model is None or parts.rig is None:
            raise DriverError("sim: the rig parts carry no model or rig section (SimulatedRig.reads names both)")
        model, rig = plant_parts(parts.model, parts.rig, parts.mismatch)
        plant = RigPlant(
            rig_params({"name": model.name, "params": model.params}),
            coil_tau_s=rig.coil_tau_s,
            current_max_a=rig.current_max_a,
            max_step_s=rig.plant_max_step_s,
        )
        return cls(
            plant,
            counts_per_rev=rig.encoder_counts_per_rev,
            angle_noise_rad=rig.angle_noise_rad,
            current_noise_a=rig.current_noise_a,
            noise_seed=rig.noise_seed,
        )

    # lifecycle -----------------------------------------------------------------------------
    def configure(self) -> None:
        if self.state is RigState.CLOSED:
            raise DriverError("sim: configure() after close()")
        self.state = RigState.CONFIGURED

    def activate(self) -> None:
        if self.state is not RigState.CONFIGURED:
            raise DriverError(f"sim: activate() in state {self.state.value} (configure() first)")
        self.state = RigState.ACTIVE

    def deactivate(self) -> None:
        self._command = 0.0
        if self.wheel.speed_rad_s != 0.0:  # the road to rest, as a board's deactivate does
            self.wheel.set_speed(self.plant, 0.0)
        if self.state is RigState.ACTIVE:
            self.state = RigState.CONFIGURED

    def close(self) -> None:
        self._command = 0.0
        self.state = RigState.CLOSED

    # cycle ---------------------------------------------------------------------------------
    def read(self, t_ns: int, dt_ns: int) -> RigSample:
        if self.state is not RigState.ACTIVE and self.state is not RigState.CONFIGURED:
            raise DriverError(f"sim: read() in state {self.state.value}")
        t0 = self._t0_ns
        if t0 is None:
            self._t0_ns = self._last_ns = t0 = t_ns
        plant = self.plant
        start_ns = self._last_ns
        elapsed = (t_ns - start_ns) * 1e-9
        if self._release_at_s is not None:
            release_in = self._release_at_s - plant.state.time_s
            if release_in <= elapsed:
                # step to the release instant, let go, then step the rest of the period
                if release_in > 0.0:
                    release_ns = start_ns + release_in * 1e9
                    self._advance(release_in, start_ns, release_ns)
                    start_ns = release_ns  # type: ignore[assignment]  # a float ns from here
                    elapsed -= release_in
                plant.release()
                self._release_at_s = None
        if elapsed > 0.0:
            self._advance(elapsed, start_ns, t_ns)
        else:
            self._jumps(start_ns)
        self._last_ns = t_ns
        st = plant.state
        theta_road = st.theta_road_rad
        theta_arm = st.theta_rad + theta_road
        current = st.current_a
        if self.angle_noise_rad or self.current_noise_a:
            theta_arm, theta_road, current = self._noise(theta_arm, theta_road, current)
        scale = self._counts_per_rad
        self._seq += 1
        arm_edge, road_edge = self.arm_edge, self.road_edge
        # positional: seq, time_ns, device_time_us, arm_counts, road_counts, current_a, flags, counts_per_rev,
        # then each encoder's last edge (device time [us], direction)
        return RigSample(
            self._seq,
            t_ns,
            (t_ns - t0) // 1000,
            round(theta_arm * scale),
            round(theta_road * scale),
            current,
            0 if plant._held_at is None else FLAG_HELD,
            self.counts_per_rev,
            NO_EDGE if arm_edge is None else (arm_edge[0] - t0) // 1000,
            0 if arm_edge is None else arm_edge[1],
            NO_EDGE if road_edge is None else (road_edge[0] - t0) // 1000,
            0 if road_edge is None else road_edge[1],
        )

    def _noise(self, theta_arm: float, theta_road: float, current: float) -> tuple[float, float, float]:
        """The sensors' seeded Gaussian noise on the two angles and the measured current."""
        if self.angle_noise_rad:
            theta_arm += self._rng.gauss(0.0, self.angle_noise_rad)
            theta_road += self._rng.gauss(0.0, self.angle_noise_rad)
        if self.current_noise_a:
            current += self._rng.gauss(0.0, self.current_noise_a)
        return theta_arm, theta_road, current

    # encoder edges ---------------------------------------------------------------------------
    def _angles(self) -> tuple[float, float]:
        """(arm, road) angle of the plant now, noise-free."""
        st = self.plant.state
        return st.theta_rad + st.theta_road_rad, st.theta_road_rad

    def _jumps(self, at_ns: float) -> None:
        """A count changed without motion since the last step (the operator pressed the arm to its hold
        angle): an edge at ``at_ns``."""
        arm, road = self._angles()
        q = TWO_PI / self.counts_per_rev
        for which, now, before in (("arm", arm, self._arm_end), ("road", road, self._road_end)):
            if before is not None and round(now / q) != round(before / q):
                setattr(self, f"{which}_edge", (int(at_ns), 1 if now > before else -1))
        self._arm_end, self._road_end = arm, road

    def _advance(self, seconds: float, from_ns: float, to_ns: float) -> None:
        """Step the plant ``seconds`` (host time ``from_ns`` to ``to_ns``) in the sub-steps it would take
        in one call, timing each encoder's last count change on the way (module docstring), in one
        compiled call (:func:`sashil.drivers.sim_advance.advance`): the curves between the sub-step's
        ends are searched only when the quick test
        (:func:`~sashil.drivers.encoder_edges.quick_test`) cannot rule a count change out."""
        plant = self.plant
        st = plant.state
        if st.theta_rad + st.theta_road_rad != self._arm_end or st.theta_road_rad != self._road_end:
            self._jumps(from_ns)  # moved since the last step's end (an operator's hold)
        if seconds != self._split_s:
            count = max(1, math.ceil(seconds / plant.max_step_s - 1e-9))  # the plant's own split of the step
            h = seconds / count
            decay = math.exp(-h / plant.coil_tau_s) if plant.coil_tau_s > 0.0 else 0.0
            self._split_s, self._split = seconds, (count, h, decay)
        count, h, decay = self._split
        wheel = self.wheel
        t, theta, v, z, i, road, arm_j, arm_s, arm_dir, road_j, road_s, road_dir = advance(
            st.time_s,
            st.theta_rad,
            st.theta_dot_rad_s,
            st.z,
            st.current_a,
            st.theta_road_rad,
            st.theta_road_dot_rad_s,
            wheel._theta0,
            wheel.speed_rad_s,
            wheel._t0,
            count,
            h,
            self._command,  # clamped where it is set (write, set_initial_current)
            decay,
            plant._held_at is not None,
            self._constants,
        )
        st.time_s, st.theta_rad, st.theta_dot_rad_s, st.z, st.current_a = t, theta, v, z, i
        st.theta_road_rad, st.theta_road_dot_rad_s, st.torque_in_nm = road, wheel.speed_rad_s, 0.0
        if arm_j >= 0 or road_j >= 0:
            h_ns = (to_ns - from_ns) / count
            if arm_j >= 0:
                self.arm_edge = (math.ceil(from_ns + arm_j * h_ns + arm_s * h_ns), arm_dir)
            if road_j >= 0:
                self.road_edge = (math.ceil(from_ns + road_j * h_ns + road_s * h_ns), road_dir)
        self._arm_end, self._road_end = theta + road, road

    def write(self, cmd: RigCommand, t_ns: int, dt_ns: int) -> None:
        if self.state is not RigState.ACTIVE:
            self._command = 0.0
            return
        self._command = clamp_current(cmd.current_a, self.plant.current_max_a)
        speed = cmd.road_speed_rad_s
        if speed is not None and speed == speed and speed != self.wheel.speed_rad_s:  # None/NaN: unchanged
            self.wheel.set_speed(self.plant, speed)

    def plant_truth(self) -> PlantTruth:
        """The plant's damper torque T and arm acceleration theta2_ddot = (-k*theta - T)/J now (the
        state of the last ``read``; seed 001 eqs. 9 and 13)."""
        plant = self.plant
        torque = plant.damper_torque()
        p = plant.params
        return PlantTruth(torque, (-p.k * plant.state.theta_rad - torque) / p.J)

    # operator ------------------------------------------------------------------------------
    def operator_hold(self, theta_rad: float, release_after_s: float) -> bool:
        """Hold the simulated arm at ``theta_rad`` now and release it ``release_after_s`` later."""
        self.plant.hold(theta_rad)
        self._release_at_s = self.plant.state.time_s + release_after_s
        return True

    def set_initial_current(self, current_a: float) -> None:
        """Start with the coil already carrying ``current_a`` (as if it had flowed for a while)."""
        self.plant.state.current_a = clamp_current(float(current_a), self.plant.current_max_a)
        self._command = self.plant.state.current_a

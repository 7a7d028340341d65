"""A calibration step in the loop: the stage a drop hands over to at its release in each run of
``sashil calibrate``, and the step it runs (plain data a loop process rebuilds it from).

A step is a drop from ``theta0_deg`` with the coil at ``current_a`` throughout; a *road* step also
drives the road wheel from the release on with a chirp theta1(t) = A*w(t)*sin(phi(t)) through the
resonance (sqrt(k/J)/2pi, ~1.66 Hz with the seed values: seed 001 section 8), so that the damper
keeps moving at high current where a drop stops within a cycle. Every backend's road wheel obeys
the speed commands (the simulated rig's :class:`~sashil.drivers.sim.RoadWheel` as the emulator's
and the bench's motor).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from sashil.drivers.interface import FLAG_STUCK_SENSOR, RigCommand, RigSample
from sashil.errors import DriverError

__all__ = ["KIND", "ROAD_UPDATE_CYCLES", "RoadChirp", "Step", "StepStage", "StuckEncoderError"]

#: the stage's kind in a drop's spec (``{"kind": KIND, "step": ...}``): a built-in stage of
#: :data:`sashil.plans.BUILT_IN_STAGES`
KIND = "calibration-step"

#: the road wheel's speed is updated every this many cycles (4 ms at 1 kHz): a staircase (the
#: commanded speeds are recorded, and shape the applied road between the road encoder's edges), at a
#: quarter of the link traffic per cycle
ROAD_UPDATE_CYCLES = 4


class StuckEncoderError(DriverError):
    """The rig reports a frozen encoder, or the arm never moved: nothing to calibrate (exit 2)."""


@dataclass(frozen=True)
class RoadChirp:
    """theta1(t) = A*w(t)*sin(phi(t)), phi' = 2*pi*f(t), f linear from f0 to f1 between the ramps;
    w(t) a raised-cosine ramp up over ``ramp_s`` and down over the last ``ramp_s`` of ``duration_s``
    (the wheel ends at rest, so the next run starts with a still road)."""

    amplitude_rad: float
    f_start_hz: float
    f_stop_hz: float
    duration_s: float
    ramp_s: float

    def _window(self, t: float) -> tuple[float, float]:
        """w(t) and w'(t)."""
        r, d = self.ramp_s, self.duration_s
        if t <= 0.0 or t >= d:
            return 0.0, 0.0
        if r > 0.0 and t < r:
            return 0.5 - 0.5 * math.cos(math.pi * t / r), 0.5 * math.pi / r * math.sin(math.pi * t / r)
        if r > 0.0 and t > d - r:
            u = d - t
            return 0.5 - 0.5 * math.cos(math.pi * u / r), -0.5 * math.pi / r * math.sin(math.pi * u / r)
        return 1.0, 0.0

    def _phase(self, t: float) -> tuple[float, float]:
        """phi(t) and phi'(t) (the frequency sweeps over the whole record)."""
        rate = (self.f_stop_hz - self.f_start_hz) / self.duration_s
        return 2.0 * math.pi * (self.f_start_hz * t + 0.5 * rate * t * t), 2.0 * math.pi * (self.f_start_hz + rate * t)

    def angle(self, t: float) -> float:
        w, _ = self._window(t)
        return self.amplitude_rad * w * math.sin(self._phase(t)[0])

    def speed(self, t: float) -> float:
        """theta1'(t) [rad/s]: the road wheel's speed command."""
        w, dw = self._window(t)
        phi, dphi = self._phase(t)
        return self.amplitude_rad * (dw * math.sin(phi) + w * dphi * math.cos(phi))


@dataclass(frozen=True)
class Step:
    """One run of the calibration plan: a drop from ``theta0_deg`` at ``current_a``, with a road
    chirp or not; its ``role`` is ``fit`` (the identification sees it) or ``validate`` (held out)."""

    name: str
    role: str  # "fit" | "validate"
    theta0_deg: float
    current_a: float
    duration_s: float
    road: RoadChirp | None = None

    @property
    def kind(self) -> str:
        return "road" if self.road is not None else "drop"

    def describe(self) -> str:
        what = f"road chirp {self.road.f_start_hz:g}-{self.road.f_stop_hz:g} Hz" if self.road else "drop"
        return f"{what} from {self.theta0_deg:g} deg at {self.current_a:g} A, {self.duration_s:g} s ({self.role})"


class StepStage:
    """The drop test's controller stage of a step: the constant current throughout, and after the
    release (``held`` False, set by the drop test) the road chirp's speed. A sample flagged with a
    stuck encoder ends the step at once. It keeps no data: the runner's stream records each
    cycle's device time, ``seq`` and the road speed commanded."""

    def __init__(self, step: Step):
        self.step_def = step
        self.held = True
        self.current_cmd_a = step.current_a
        self.theta_dot_rad_s = self.z_hat = self.torque_hat_nm = self.torque_cmd_nm = math.nan
        self._t0_ns: int | None = None
        self._road_speed = 0.0
        self._cycle = 0

    def spec(self) -> dict[str, Any]:
        """What a loop process builds this stage from (:meth:`from_spec`): the step."""
        return {"kind": KIND, "step": dataclasses.asdict(self.step_def)}

    @classmethod
    def from_spec(cls, spec: dict[str, Any]) -> StepStage:
        """The stage of a :meth:`spec`."""
        fields = dict(spec["step"])
        road = fields.pop("road", None)
        return cls(Step(**fields, road=RoadChirp(**road) if road is not None else None))

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand:
        if sample.flags & FLAG_STUCK_SENSOR:
            raise StuckEncoderError(f"{self.step_def.name}: the rig reports a stuck encoder (the angle is frozen)")
        road = self.step_def.road
        if not self.held and road is not None:
            if self._t0_ns is None:
                self._t0_ns = t_ns
            if self._cycle % ROAD_UPDATE_CYCLES == 0:
                self._road_speed = road.speed((t_ns - self._t0_ns) * 1e-9)
            self._cycle += 1
            return RigCommand(self.step_def.current_a, self._road_speed)
        return RigCommand(self.step_def.current_a)

"""The host-side safety supervisor: what may reach the damper coil, and when the run must stop.

Two jobs, both once per cycle and free of I/O (the loop does the I/O):

* ``check(sample, t_ns)`` after ``rig.read``: the **angle interlock** (|theta| beyond the rig's
  mechanical limit, ``rig.angle_limit_deg``), the **sensor timeout** (no fresh sample for
  ``safety.sensor_timeout_cycles`` cycles; a sample is fresh when its sequence number advanced,
  modulo the 16-bit wire counter, so a repeated or backward sequence number is a stale sample), and
  the device's own **fault / overcurrent flags**. A violation is recorded as a :class:`Trip` (time
  from the start of the run, reason) and raised as :class:`~sashil.errors.SafetyTrip`; the loop
  then commands 0 A, deactivates and closes the rig.
* ``limit(cmd, dt_ns)`` before ``rig.write``: the **current clamp** to [0, i_max] (NaN -> 0 A) and
  the optional **slew limit** |di/dt| <= ``safety.slew_a_per_s`` over the measured period. These
  never stop the run; the clamped cycles are counted.

MR dampers fail passive, so the safe state is 0 A (docs/architecture.md); the shutdown path writes it
directly and is not slew limited.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NoReturn

from sashil.drivers.interface import (
    FLAG_FAULT,
    FLAG_OVERCURRENT,
    FLAG_STUCK_SENSOR,
    RigCommand,
    RigSample,
    clamp_current,
)
from sashil.errors import SafetyTrip

if TYPE_CHECKING:
    from sashil.config.parts import SafetyParts

#: the data.csv ``trip_code`` column: 0 = no trip, else the kind below
TRIP_CODES = {"angle_interlock": 1, "sensor_timeout": 2, "device_fault": 3}

SEQ_MODULUS = 1 << 16  # sequence numbers wrap at 2**16 on the wire
SEQ_HALF = SEQ_MODULUS // 2


@dataclass
class Trip:
    """One safety trip: when (s from the start of the run), which kind, and why."""

    time_s: float
    kind: str
    reason: str

    @property
    def code(self) -> int:
        return TRIP_CODES[self.kind]

    def as_dict(self) -> dict[str, Any]:
        return {"time_s": round(self.time_s, 9), "kind": self.kind, "code": self.code, "reason": self.reason}


#: the sample flags that trip the supervisor (``safety.trip_on_device_fault``) and their names
DEVICE_FAULTS = ((FLAG_FAULT, "fault"), (FLAG_OVERCURRENT, "overcurrent"), (FLAG_STUCK_SENSOR, "a stuck sensor"))


class SafetySupervisor:
    """Limits and interlocks between the control law and the damper (see module doc)."""

    def __init__(
        self,
        current_max_a: float,
        angle_limit_rad: float | None = None,
        slew_a_per_s: float = 0.0,
        sensor_timeout_cycles: int = 20,
        trip_on_device_fault: bool = True,
    ):
        self.current_max_a = float(current_max_a)
        self.angle_limit_rad = None if angle_limit_rad is None else float(angle_limit_rad)
        self.slew_a_per_s = float(slew_a_per_s)
        self.sensor_timeout_cycles = int(sensor_timeout_cycles)
        self.fault_mask = (FLAG_FAULT | FLAG_OVERCURRENT | FLAG_STUCK_SENSOR) if trip_on_device_fault else 0
        self.trips: list[Trip] = []
        self.clamped_cycles = 0  # commands outside [0, i_max] or NaN
        self.slew_limited_cycles = 0
        self.stale_samples = 0  # samples whose sequence number did not advance
        self.start_ns = 0
        self._last_seq: int | None = None
        self._not_fresh = 0
        self._last_current = 0.0
        self._out = RigCommand(0.0)

    @classmethod
    def from_parts(cls, limits: SafetyParts) -> SafetySupervisor:
        """The supervisor of a run's limits (the angle interlock off when ``angle_limit_deg`` is None)."""
        limit = limits.angle_limit_deg
        return cls(
            current_max_a=limits.current_max_a,
            angle_limit_rad=math.radians(limit) if limit is not None else None,
            slew_a_per_s=limits.slew_a_per_s,
            sensor_timeout_cycles=limits.sensor_timeout_cycles,
            trip_on_device_fault=limits.trip_on_device_fault,
        )

    def start(self, t_ns: int) -> None:
        """The run starts at ``t_ns`` (trip times count from here); the coil is at 0 A."""
        self.start_ns = t_ns
        self._last_seq = None
        self._not_fresh = 0
        self._last_current = 0.0

    @property
    def trip_code(self) -> int:
        return self.trips[-1].code if self.trips else 0

    # after read -------------------------------------------------------------------------------
    def check(self, sample: RigSample | None, t_ns: int) -> None:
        """Raise SafetyTrip (after recording it) if the sample breaks an interlock."""
        if sample is None or not self._advances(sample.seq):
            self._stale(sample, t_ns)
            return  # a stale sample is not judged again
        self._not_fresh = 0
        if sample.flags & self.fault_mask:
            kinds = [name for bit, name in DEVICE_FAULTS if sample.flags & bit]
            self._trip(t_ns, "device_fault", f"device reports {' and '.join(kinds)} (flags 0x{sample.flags:02x})")
        limit = self.angle_limit_rad
        if limit is not None:
            theta = sample.theta_rad
            if not -limit <= theta <= limit:
                self._trip(
                    t_ns,
                    "angle_interlock",
                    f"angle interlock: |theta| = {abs(math.degrees(theta)):.2f} deg beyond the limit "
                    f"{math.degrees(limit):g} deg (rig.angle_limit_deg)",
                )

    def _advances(self, seq: int) -> bool:
        """Whether ``seq`` is fresh: the first one, or ahead of the last by less than half the counter."""
        last = self._last_seq
        fresh = last is None or 0 < (seq - last) % SEQ_MODULUS < SEQ_HALF
        if fresh:
            self._last_seq = seq
        return fresh

    def _stale(self, sample: RigSample | None, t_ns: int) -> None:
        """Count a cycle without a fresh sample; trip after ``sensor_timeout_cycles`` of them."""
        self.stale_samples += 1
        self._not_fresh += 1
        if self._not_fresh >= self.sensor_timeout_cycles:
            what = "no sample" if sample is None else f"sequence number stuck at or behind {self._last_seq}"
            self._trip(
                t_ns,
                "sensor_timeout",
                f"sensor timeout: no fresh sample for {self._not_fresh} cycles ({what}; "
                f"safety.sensor_timeout_cycles = {self.sensor_timeout_cycles})",
            )

    def _trip(self, t_ns: int, kind: str, reason: str) -> NoReturn:
        trip = Trip((t_ns - self.start_ns) * 1e-9, kind, reason)
        self.trips.append(trip)
        self._last_current = 0.0
        raise SafetyTrip(reason)

    # before write -----------------------------------------------------------------------------
    def limit(self, cmd: RigCommand, dt_ns: int) -> RigCommand:
        """The command that may reach the coil: clamped to [0, i_max], slew limited.

        Returns one reused RigCommand (no allocation per cycle); the driver copies what it needs.
        """
        current = clamp_current(cmd.current_a, self.current_max_a)
        if current != cmd.current_a:  # outside [0, i_max], or NaN (never equal to itself)
            self.clamped_cycles += 1
        if self.slew_a_per_s > 0.0:
            step = self.slew_a_per_s * dt_ns * 1e-9
            last = self._last_current
            if current > last + step:
                current = last + step
                self.slew_limited_cycles += 1
            elif current < last - step:
                current = last - step
                self.slew_limited_cycles += 1
        self._last_current = current
        out = self._out
        out.current_a = current
        out.road_speed_rad_s = cmd.road_speed_rad_s
        return out

    def safe_state(self) -> None:
        """The shutdown path commanded 0 A (the next ``limit`` slews up from 0)."""
        self._last_current = 0.0

    def summary(self) -> dict[str, Any]:
        """The ``safety`` block of summary.json (trips go under the top-level ``trips``)."""
        return {
            "clamped_cycles": self.clamped_cycles,
            "slew_limited_cycles": self.slew_limited_cycles,
            "stale_samples": self.stale_samples,
            "sensor_timeout_cycles": self.sensor_timeout_cycles,
            "angle_limit_deg": None if self.angle_limit_rad is None else round(math.degrees(self.angle_limit_rad), 9),
            "slew_a_per_s": self.slew_a_per_s or None,
        }

"""The host-side safety supervisor: what may reach the damper coil, and when the run must stop.

Two jobs, both once per cycle and free of I/O (the loop does the I/O):

* ``check(sample, t_ns)`` after ``rig.read``: the **angle interlock** (|theta| beyond the rig's
  mechanical limit, ``rig.angle_limit_deg``), the **sensor timeout** (no fresh sample for
  ``safety.sensor_timeout_cycles`` cycles; a sample is fresh when its sequence number advanced,
  modulo the 16-bit wire counter, so a repeated or backward sequence number is a stale sample),
  the device's own **fault / overcurrent flags**, an **encoder step** no rig can make between two
  samples (faster than ``safety.max_angle_rate_rad_s``, plus one count: an index reset, a wrong
  counts per revolution), the **arm's travel** (|theta2| beyond ``safety.arm_travel_deg``), and what a
  backend that closes the road's and the coil's loops on the host reports: the **road off its
  reference** (beyond ``safety.road_error_max_rad`` for ``safety.road_error_ms``), the **road output
  at its limit** (for ``safety.road_limit_ms``; neither judged for ``safety.road_grace_ms`` after a
  host pause, a gap of more than three periods, while the road catches up with what the board held) and the **coil's current loop at its authority
  limit** (its sense disagrees with the command, for ``safety.coil_authority_ms``). A violation is
  recorded as a :class:`Trip` (time from the start of the run, reason) and raised as
  :class:`~sashil.errors.SafetyTrip`; the loop then commands 0 A, deactivates and closes the rig.
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
    TWO_PI,
    RigCommand,
    RigSample,
    clamp_current,
)
from sashil.errors import SafetyTrip

if TYPE_CHECKING:
    from sashil.config.parts import SafetyParts

#: the data.csv ``trip_code`` column: 0 = no trip, else the kind below
TRIP_CODES = {
    "angle_interlock": 1,
    "sensor_timeout": 2,
    "device_fault": 3,
    "encoder_step": 4,
    "arm_travel": 5,
    "road_tracking": 6,
    "road_limit": 7,
    "coil_sense": 8,
}

#: a gap between two samples longer than this many of the loop's periods is a host pause
PAUSE_PERIODS = 3
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
        max_angle_rate_rad_s: float = 60.0,
        arm_travel_rad: float | None = None,
        road_error_max_rad: float = 0.02,
        road_error_ms: float = 5.0,
        road_limit_ms: float = 50.0,
        coil_authority_ms: float = 50.0,
        road_grace_ms: float = 150.0,
    ):
        self.current_max_a = float(current_max_a)
        self.road_grace_ns = round(road_grace_ms * 1e6)
        self._period_ns: int | None = None
        self._grace_until_ns = 0
        self.max_angle_rate_rad_s = float(max_angle_rate_rad_s)
        self.arm_travel_rad = None if arm_travel_rad is None else float(arm_travel_rad)
        self.road_error_max_rad = float(road_error_max_rad)
        self.road_error_ns = round(road_error_ms * 1e6)
        self.road_limit_ns = round(road_limit_ms * 1e6)
        self.coil_authority_ns = round(coil_authority_ms * 1e6)
        #: when each held condition (road off, road at limit, coil at authority) began; None: not held
        self._held_since: dict[str, int | None] = {"road_tracking": None, "road_limit": None, "coil_sense": None}
        #: (t_ns, arm, road, device_time_us) of the last fresh sample
        self._last_counts: tuple[int, int, int, int] | None = None
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
            max_angle_rate_rad_s=limits.max_angle_rate_rad_s,
            arm_travel_rad=math.radians(limits.arm_travel_deg) if limits.arm_travel_deg is not None else None,
            road_error_max_rad=limits.road_error_max_rad,
            road_error_ms=limits.road_error_ms,
            road_limit_ms=limits.road_limit_ms,
            coil_authority_ms=limits.coil_authority_ms,
            road_grace_ms=limits.road_grace_ms,
        )

    def start(self, t_ns: int) -> None:
        """The run starts at ``t_ns`` (trip times count from here); the coil is at 0 A."""
        self.start_ns = t_ns
        self._last_seq = None
        self._not_fresh = 0
        self._last_current = 0.0
        self._last_counts = None
        self._period_ns = None
        self._grace_until_ns = t_ns
        for name in self._held_since:
            self._held_since[name] = None

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
        self._check_encoders(sample, t_ns)
        self._check_loops(sample, t_ns)

    def _check_encoders(self, sample: RigSample, t_ns: int) -> None:
        """An encoder step faster than the rig can turn, and the arm beyond its travel."""
        last = self._last_counts
        self._last_counts = (t_ns, sample.arm_counts, sample.road_counts, sample.device_time_us)
        per_rad = sample.counts_per_rev / TWO_PI
        if last is not None:
            dt_ns = t_ns - last[0]
            period = dt_ns if self._period_ns is None else min(self._period_ns, dt_ns)
            self._period_ns = period  # the loop's period: the shortest gap between two samples
            if dt_ns > PAUSE_PERIODS * period:  # the host paused: the board held the road's output meanwhile
                self._grace_until_ns = t_ns + self.road_grace_ns
            # the longer of the host's gap and the device's: a link hands over samples the device took a
            # period apart in a burst (a device clock that steps back counts for nothing)
            device_ns = max(sample.device_time_us - last[3], 0) * 1000
            dt_s = max(dt_ns, device_ns) * 1e-9
            allowed = self.max_angle_rate_rad_s * dt_s * per_rad + 1.0
            for name, now, before in (("arm", sample.arm_counts, last[1]), ("road", sample.road_counts, last[2])):
                step = abs(now - before)
                if step > allowed:
                    self._trip(
                        t_ns,
                        "encoder_step",
                        f"encoder step: the {name} angle jumped {step} counts in {dt_s * 1e3:.1f} ms, more than "
                        f"{allowed:.0f} (safety.max_angle_rate_rad_s = {self.max_angle_rate_rad_s:g}): an index "
                        f"reset or a wrong counts per revolution",
                    )
        travel = self.arm_travel_rad
        if travel is not None:
            arm = sample.arm_counts / per_rad
            if not -travel <= arm <= travel:
                self._trip(
                    t_ns,
                    "arm_travel",
                    f"arm travel: |theta2| = {abs(math.degrees(arm)):.2f} deg beyond "
                    f"{math.degrees(travel):g} deg (safety.arm_travel_deg)",
                )

    def _check_loops(self, sample: RigSample, t_ns: int) -> None:
        """The road off its reference, the road output at its limit, the coil's loop at its authority,
        each held longer than its bound."""
        error = sample.road_error_rad
        judged = t_ns >= self._grace_until_ns  # not while the road catches up after a host pause
        off = judged and abs(error) > self.road_error_max_rad  # NaN: never off
        if self._held("road_tracking", off, t_ns, self.road_error_ns):
            self._trip(
                t_ns,
                "road_tracking",
                f"the road is {abs(error):.3f} rad off its reference, beyond {self.road_error_max_rad:g} rad for "
                f"{self.road_error_ns * 1e-6:g} ms (safety.road_error_max_rad, safety.road_error_ms): check the "
                f"road's encoder direction, counts per revolution and output channel",
            )
        if self._held("road_limit", judged and sample.road_at_limit, t_ns, self.road_limit_ns):
            self._trip(
                t_ns,
                "road_limit",
                f"the road motor's output held at its limit for {self.road_limit_ns * 1e-6:g} ms "
                f"(safety.road_limit_ms): the road cannot follow its command",
            )
        if self._held("coil_sense", sample.coil_at_authority, t_ns, self.coil_authority_ns):
            self._trip(
                t_ns,
                "coil_sense",
                f"the coil's sensed current disagrees with the command: its current loop held at its authority "
                f"limit for {self.coil_authority_ns * 1e-6:g} ms (safety.coil_authority_ms): check the coil "
                f"sense's channel and scale",
            )

    def _held(self, kind: str, now_held: bool, t_ns: int, bound_ns: int) -> bool:
        """Whether ``now_held`` has held for ``bound_ns`` without a break (its start kept by ``kind``)."""
        if not now_held:
            self._held_since[kind] = None
            return False
        since = self._held_since[kind]
        if since is None:
            self._held_since[kind] = since = t_ns
        return t_ns - since >= bound_ns

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

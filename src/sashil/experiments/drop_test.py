"""The drop test of seed 001 section 8: press the arm to theta0 (-5 deg), release, record.

The plan (:class:`DropTestPlan`) is a loop stage: it commands a constant current from the start
(so the current already flows at release), waits for a steady hold near theta0, detects the
release and records the free oscillation for the requested duration. The same plan runs on the
simulated rig (which plays the operator), the emulator and the bench (where a person does).

Release time. When the backend plays the operator it knows the instant it lets go. Otherwise the
plan estimates it from the departure: just after release the arm leaves the hold angle with
constant acceleration, ``|theta - theta_hold| = a/2 * (t - t_r)^2``, so ``sqrt|dtheta|`` is linear
in t and its zero is t_r (a least-squares line through the departure samples between two encoder
counts and the release threshold).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sashil.drivers import open_rig
from sashil.drivers.interface import FLAG_HELD, TWO_PI, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.errors import ConfigError, DriverTimeoutError, SashilError
from sashil.experiments.metrics import DropMetrics, drop_metrics
from sashil.runtime.clock import Clock, RealClock, VirtualClock
from sashil.runtime.loop import LoopResult
from sashil.runtime.runner import run_plan

#: columns of a drop test's data.csv (DESIGN.md names)
DROP_COLUMNS = ("time_s", "theta_rad", "theta_road_rad", "current_a", "current_cmd_a")
#: added when a controller acts after the release (its per-cycle values, DESIGN.md names)
CONTROLLER_COLUMNS = ("theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm")


def check_theta0(config: dict[str, Any], theta0_deg: float, option: str = "--theta0-deg") -> None:
    """Refuse a hold angle the release could not be detected from: the release is the arm moving
    ``drop_test.release_threshold_deg`` from the hold, and released at |theta0| below it, it swings less."""
    threshold = config["drop_test"]["release_threshold_deg"]
    if math.isfinite(theta0_deg) and abs(theta0_deg) < threshold:
        raise ConfigError(
            f"{option}: expected an angle at least drop_test.release_threshold_deg = {threshold:g} deg from 0 "
            f"(the release is detected when the arm moves that far from the hold), got {theta0_deg:g}"
        )


@dataclass
class DropTestSettings:
    theta0_rad: float
    current_a: float
    duration_s: float
    rate_hz: float
    hold_tolerance_rad: float
    hold_time_s: float
    release_threshold_rad: float
    hold_timeout_s: float
    known_release_after_s: float | None = None  # set when the backend plays the operator

    @classmethod
    def from_config(
        cls, config: dict[str, Any], theta0_deg: float, current_a: float, duration_s: float
    ) -> DropTestSettings:
        drop = config["drop_test"]
        check_theta0(config, theta0_deg, "theta0_deg")
        return cls(
            theta0_rad=math.radians(theta0_deg),
            current_a=current_a,
            duration_s=duration_s,
            rate_hz=config["loop"]["rate_hz"],
            hold_tolerance_rad=math.radians(drop["hold_tolerance_deg"]),
            hold_time_s=drop["hold_time_s"],
            release_threshold_rad=math.radians(drop["release_threshold_deg"]),
            hold_timeout_s=drop["hold_timeout_s"],
        )


@dataclass
class DropRecord:
    """The recorded free oscillation, time zero at the release."""

    columns: dict[str, np.ndarray]
    release_time_ns: int
    release_estimated: bool
    hold_angle_rad: float
    loop: LoopResult | None = None
    metrics: DropMetrics | None = None
    error: SashilError | None = None  # what ended the test early (the data up to it is kept)
    extra: dict[str, Any] = field(default_factory=dict)


def estimate_release_ns(times_ns: list[int], angles: list[float], hold_angle: float, resolution: float) -> int:
    """Release instant from departure samples: zero of the line through ``sqrt|theta - hold|``."""
    ts, roots = [], []
    for t, angle in zip(times_ns, angles, strict=True):
        moved = abs(angle - hold_angle)
        if moved >= 1.5 * resolution:
            ts.append(t)
            roots.append(math.sqrt(moved))
    if len(ts) >= 2:
        t_rel = np.asarray(ts, dtype=float) - ts[0]
        slope, intercept = np.polyfit(t_rel, np.asarray(roots), 1)
        if slope > 0:
            estimate = ts[0] + int(round(-intercept / slope))
            last_still = max(
                (t for t, a in zip(times_ns, angles, strict=True) if abs(a - hold_angle) < 0.5 * resolution),
                default=None,
            )
            if last_still is None or estimate >= last_still:
                return min(estimate, ts[0])
            return last_still
    still = [t for t, a in zip(times_ns, angles, strict=True) if abs(a - hold_angle) < resolution]
    return still[-1] if still else times_ns[0]


class DropTestPlan:
    """Loop stage: constant current; wait for the hold; detect the release; record ``duration_s``."""

    def __init__(
        self,
        settings: DropTestSettings,
        counts_per_rev: int,
        controller: Any = None,
        notify: Callable[[str], None] | None = None,
    ):
        self.s = settings
        # operator prompts and what the plan detected (one line at each phase change, never per cycle)
        self.notify = notify
        # optional loop stage (sashil.control) that commands the damper after the release
        self.controller = controller
        self.command = RigCommand(settings.current_a)
        self.resolution = TWO_PI / counts_per_rev
        self.phase = "wait-hold"
        self._start_ns: int | None = None
        self._still_since: int | None = None
        self._hold_sum = 0.0
        self._hold_count = 0
        self.hold_angle = settings.theta0_rad
        self.held_elsewhere = False  # a simulated operator held the arm away from theta0
        self._recent: deque[tuple] = deque(maxlen=max(16, int(settings.rate_hz)))  # rows before the release
        self.release_ns: int | None = None
        self.release_estimated = False
        self._capacity = int(math.ceil(settings.duration_s * settings.rate_hz)) + 8
        # seq last: the sample's number on the wire, so a run over a link joins the emulator's truth
        self.column_names = DROP_COLUMNS + (CONTROLLER_COLUMNS if controller is not None else ()) + ("seq",)
        self._data: tuple[list[float], ...] = tuple([] for _ in self.column_names)
        self._n = 0

    # the cycle -------------------------------------------------------------------------------
    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        theta = sample.theta_rad
        if self._start_ns is None:
            self._start_ns = t_ns
            if self.notify is not None and self.s.known_release_after_s is None:
                self.notify(
                    f"press the arm to {math.degrees(self.s.theta0_rad):g} deg (within "
                    f"±{math.degrees(self.s.hold_tolerance_rad):g} deg) and hold it still; now at "
                    f"{math.degrees(theta):.2f} deg"
                )
        ctl = None
        if self.controller is not None:
            self.controller.held = self.phase != "record"  # the operator's hand is outside the model
            ctl = self.controller.step(sample, t_ns, dt_ns)
        if self.phase == "record":
            out = self._record_cycle(t_ns, theta, sample.theta_road_rad, sample.current_a, sample.seq)
            return out if out is None or ctl is None else ctl
        self._recent.append(self._row(t_ns, theta, sample.theta_road_rad, sample.current_a, sample.seq))
        if self.phase == "wait-hold":
            self._wait_hold(t_ns, theta, sample.flags)
        elif self.phase == "held":
            if abs(theta - self.hold_angle) > self.s.release_threshold_rad:
                self._released(t_ns)
                if self.phase == "done":
                    return None
            elif (t_ns - self._start_ns) * 1e-9 > 2 * self.s.hold_timeout_s:
                raise DriverTimeoutError(
                    f"drop test: the arm was held at {math.degrees(self.hold_angle):.2f} deg but not released "
                    f"within {2 * self.s.hold_timeout_s:g} s"
                )
        if ctl is not None and self.phase == "record":
            return ctl
        return self.command

    def _wait_hold(self, t_ns: int, theta: float, flags: int = 0) -> None:
        target = self.s.theta0_rad
        if flags & FLAG_HELD and abs(theta - target) > self.s.hold_tolerance_rad:
            # a simulated operator (the emulator's --hold-deg) says it holds the arm: take the hold
            # where it is rather than wait for an angle it will never press to
            if not self.held_elsewhere:
                logging.getLogger("sashil").warning(
                    "drop test: the rig's operator holds the arm at %.2f deg, not at theta0 = %.2f deg; "
                    "the drop starts from there",
                    math.degrees(theta),
                    math.degrees(target),
                )
            self.held_elsewhere = True
            target = theta
        if abs(theta - target) <= self.s.hold_tolerance_rad:
            if (
                self._still_since is None
                or abs(theta - self._hold_sum / max(self._hold_count, 1)) > 2 * self.resolution
            ):
                self._still_since, self._hold_sum, self._hold_count = t_ns, 0.0, 0
            self._hold_sum += theta
            self._hold_count += 1
            if (t_ns - self._still_since) * 1e-9 >= self.s.hold_time_s:
                self.phase = "held"
                self.hold_angle = self._hold_sum / self._hold_count
                if self.notify is not None and self.s.known_release_after_s is None:
                    self.notify(
                        f"hold detected at {math.degrees(self.hold_angle):.2f} deg: release the arm when ready "
                        f"(detected when it moves {math.degrees(self.s.release_threshold_rad):g} deg)"
                    )
        else:
            self._still_since = None
        assert self._start_ns is not None  # step() sets it on the first cycle
        if self.phase == "wait-hold" and (t_ns - self._start_ns) * 1e-9 > self.s.hold_timeout_s:
            raise DriverTimeoutError(
                f"drop test: no steady hold within ±{math.degrees(self.s.hold_tolerance_rad):g} deg of "
                f"{math.degrees(self.s.theta0_rad):g} deg for {self.s.hold_time_s:g} s within "
                f"{self.s.hold_timeout_s:g} s (press the arm to theta0 and hold it still)"
            )

    def _released(self, t_ns: int) -> None:
        recent = list(self._recent)
        assert self._start_ns is not None  # step() sets it on the first cycle
        if self.s.known_release_after_s is not None:
            self.release_ns = self._start_ns + round(self.s.known_release_after_s * 1e9)
        else:
            self.release_ns = estimate_release_ns(
                [r[0] for r in recent], [r[1] for r in recent], self.hold_angle, self.resolution
            )
            self.release_estimated = True
        self.phase = "record"
        if self.notify is not None and self.release_estimated:  # a person let go (the backend knows when it did)
            self.notify(
                f"release detected: the arm left {math.degrees(self.hold_angle):.2f} deg; the release is dated "
                f"{(t_ns - self.release_ns) * 1e-6:.1f} ms before the detection; recording {self.s.duration_s:g} s"
            )
        for row in recent:
            if row[0] >= self.release_ns and self._record(row) is None:
                break

    def _row(self, t_ns: int, theta: float, road: float, current: float, seq: int) -> tuple:
        """One cycle's values in column order (time still in host ns)."""
        ctl = self.controller
        if ctl is None:
            return (t_ns, theta, road, current, self.s.current_a, seq)
        return (
            t_ns,
            theta,
            road,
            current,
            ctl.current_cmd_a,
            ctl.theta_dot_rad_s,
            ctl.z_hat,
            ctl.torque_hat_nm,
            ctl.torque_cmd_nm,
            seq,
        )

    def _record_cycle(self, t_ns: int, theta: float, road: float, current: float, seq: int) -> RigCommand | None:
        """Record this cycle (the common case, without building a row tuple)."""
        if self.controller is not None:
            return self._record(self._row(t_ns, theta, road, current, seq))
        assert self.release_ns is not None  # recording starts at the release
        time_s = (t_ns - self.release_ns) * 1e-9
        if time_s > self.s.duration_s + 1e-9 or self._n >= self._capacity:
            self.phase = "done"
            return None
        data = self._data
        data[0].append(time_s)
        data[1].append(theta)
        data[2].append(road)
        data[3].append(current)
        data[4].append(self.s.current_a)
        data[5].append(seq)
        self._n += 1
        return self.command

    def _record(self, row: tuple) -> RigCommand | None:
        assert self.release_ns is not None  # recording starts at the release
        time_s = (row[0] - self.release_ns) * 1e-9
        if time_s > self.s.duration_s + 1e-9 or self._n >= self._capacity:
            self.phase = "done"
            return None
        data = self._data
        data[0].append(time_s)
        for column, value in zip(data[1:], row[1:], strict=True):
            column.append(value)
        self._n += 1
        return self.command

    def columns(self) -> dict[str, np.ndarray]:
        return {
            name: np.asarray(values, dtype=np.int64 if name == "seq" else float)
            for name, values in zip(self.column_names, self._data, strict=True)
        }


def default_clock(config: dict[str, Any]) -> Clock:
    """Simulated time for a simulated backend unless the config asks for the real clock
    (:func:`sashil.drivers.on_virtual_clock`), else the real clock."""
    from sashil.drivers import on_virtual_clock

    if on_virtual_clock(config):
        return VirtualClock()
    return RealClock.for_rate(config["loop"]["spin_margin_us"], config["loop"]["rate_hz"])


def run_drop_test(
    config: dict[str, Any],
    theta0_deg: float = -5.0,
    current_a: float = 0.0,
    duration_s: float = 10.0,
    rig: RigInterface | None = None,
    clock: Clock | None = None,
    controller: Any = None,
    notify: Callable[[str], None] | None = None,
    data_path: str | Path | None = None,
) -> DropRecord:
    """One drop test at a constant current (or, after the release, under ``controller``).

    ``data_path``: where the runner streams every cycle of the loop as it runs (the hold included,
    time from the loop's start); the record returned is the part from the release.

    Returns the record from the release on. An error that ends the test early (a driver error, a
    safety trip, no hold) does not raise: the rig is already safe, and the record carries the data
    up to it and the error in ``record.error``.
    """
    settings = DropTestSettings.from_config(config, theta0_deg, current_a, duration_s)
    rig = rig if rig is not None else open_rig(config)
    clock = clock if clock is not None else default_clock(config)
    release_after = max(settings.hold_time_s + 0.1, 0.3)
    if rig.operator_hold(settings.theta0_rad, release_after):
        settings.known_release_after_s = release_after
        if capabilities_of(rig).initial_current:
            rig.set_initial_current(current_a)  # type: ignore[attr-defined]  # declared by the backend
    plan = DropTestPlan(settings, config["rig"]["encoder_counts_per_rev"], controller, notify)
    log = logging.getLogger("sashil")
    # the one runner: real-time set-up on the real clock, signals, safety, the stream of every cycle
    outcome = run_plan(
        config, rig, plan, clock, data_path=data_path, rate_hz=settings.rate_hz, say=log.warning, note=log.debug
    )
    # whatever ended the test early, the rig is at 0 A, deactivated and closed
    error = outcome.error if outcome.error is not None else outcome.stop_error()
    if error is not None and not isinstance(error, SashilError):
        raise error
    columns = plan.columns()
    record = DropRecord(columns, plan.release_ns or 0, plan.release_estimated, plan.hold_angle, outcome.result)
    record.error = error
    if outcome.link is not None:
        record.extra["link"] = outcome.link
    if outcome.realtime:
        record.extra["realtime"] = outcome.realtime
    if outcome.recording is not None:
        record.extra["recording"] = outcome.recording
    record.metrics = drop_metrics(
        columns["time_s"],
        columns["theta_rad"],
        settle_band_deg=config["drop_test"]["settle_band_deg"],
        resolution_rad=plan.resolution,
    )
    return record

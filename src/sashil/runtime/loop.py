"""The fixed-rate control loop: absolute deadlines, measured period, safe state on any exit.

One cycle (after ros2_control's read/update/write):

    wait for the deadline -> sample = rig.read(t, dt) -> safety.check(sample)
    -> [a pending live parameter change] -> cmd = stage.step(sample, t, dt) -> cmd = safety.limit(cmd, dt) -> record the row
    -> rig.write(cmd, t, dt)

``t`` is the measured wake-up time and ``dt`` the measured period (integer ns from the clock).
``stage.step`` returning ``None`` ends the run (a finished plan). Deadlines are absolute
(``start + k * period``), so lateness never accumulates. A cycle that starts a whole period or
more after its deadline has missed that deadline: with overrun policy ``skip`` the whole missed
periods are skipped and counted (``missed_deadlines``) with a rate-limited warning; with ``fail``
the run stops with :class:`~sashil.errors.DeadlineMissedError` (exit 4).

The loop is run by :func:`sashil.runtime.runner.run_plan`, which adds the safety supervisor, the
recorder and signal handling; it is not a second way to run a rig.

Whatever ends the loop (the duration, the stage, a stop flag set by SIGINT/SIGTERM, a safety
trip, an exception anywhere) the rig gets the safe command (0 A), then ``deactivate()`` and
``close()``, each exactly once, before the loop returns or re-raises. ``LoopResult`` (also on
``ControlLoop.result`` when the loop raised) says how it ended and holds the timing statistics.

Per cycle the loop allocates no dicts or strings: timing goes into preallocated integer arrays
(:mod:`sashil.runtime.timing`), the data row into the recorder's preallocated ring.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import attrgetter
from typing import Any, Protocol

from sashil.drivers.interface import SAFE_COMMAND, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.errors import DeadlineMissedError, DriverIOError, RecordingError, SafetyTrip, status_of
from sashil.recording.data_file import OPTIONAL_COLUMNS
from sashil.runtime.clock import Clock
from sashil.runtime.timing import FOLD, TimingStats

log = logging.getLogger("sashil.loop")

#: the columns the loop records for every cycle (docs/architecture.md names first), then the stage's
#: signals (see ``stage_signals``), then what plans derive their records from: the sample's ``seq``
#: and device time, each encoder's last edge as the sample carried it (device time [us], -1: none;
#: direction +1/-1, 0: none; a replay needs them), the road speed the cycle commanded (NaN: none),
#: the plan's ``phase`` (its
#: ``phase_code``: a drop test's hold, release, ...; 0 for a stage without phases) and the safety
#: supervisor's ``trip_code`` (sashil.safety.TRIP_CODES)
BASE_COLUMNS = ("time_s", "theta_rad", "current_a", "current_cmd_a", "theta_road_rad")
TAIL_COLUMNS = (
    "seq",
    "device_time_us",
    "arm_edge_us",
    "arm_edge_dir",
    "road_edge_us",
    "road_edge_dir",
    "road_speed_cmd_rad_s",
    "phase",
    "trip_code",
)
NAN = float("nan")
#: docs/architecture.md data.csv columns a stage may provide as per-cycle attributes
STAGE_SIGNALS = tuple(name for name in OPTIONAL_COLUMNS if name != "theta_road_rad")


#: after a stop the loop reads on at 0 A until the coil's measured current is at most this [A]
SAFE_CURRENT_A = 0.05
#: ... or for at most this long [s] (the coil's lag is tens of milliseconds)
SETTLE_S = 0.5
#: the ``phase`` of the rows read while settling at 0 A after a stop (no law ran in them)
SETTLE_PHASE = -1

#: the recorder may use the interpreter until this long before the loop's next wake-up
WRITER_GUARD_NS = 50_000


class CycleStage(Protocol):
    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None: ...


class _Recorder(Protocol):
    window_end_ns: int | None
    error: BaseException | None
    path: Any

    def begin_row(self) -> list[Any]: ...

    def commit_row(self) -> None: ...


@dataclass
class LoopResult:
    cycles: int = 0
    missed_deadlines: int = 0
    exit_status: str = "ok"
    error: str | None = None
    trips: list[dict] = field(default_factory=list)
    timing: TimingStats | None = None
    stop_reason: str | None = None
    shutdown_errors: list[str] = field(default_factory=list)
    #: after a stop, how the coil's measured current settled at 0 A (:meth:`ControlLoop._settle`)
    safe_state: dict | None = None


def stage_signals(stage: object) -> tuple[str, ...]:
    """The per-cycle values a stage exposes for recording: ``stage.signal_names`` when it says,
    else those of its attributes named like the docs/architecture.md columns (``theta_dot_rad_s``, ``z_hat``,
    ``torque_hat_nm``, ``torque_cmd_nm``, ``torque_in_nm``), read after every ``step`` (from the
    stage's ``signal_source`` when it names one)."""
    names = getattr(stage, "signal_names", None)
    if names is None:
        names = tuple(name for name in STAGE_SIGNALS if hasattr(stage, name))
    return tuple(names)


def record_columns(stage: object) -> tuple[str, ...]:
    """The data.csv columns of a loop run with ``stage`` (see BASE_COLUMNS)."""
    return BASE_COLUMNS + stage_signals(stage) + TAIL_COLUMNS


class ControlLoop:
    """One run of ``stage`` on ``rig`` at ``rate_hz``; ``run()`` once."""

    def __init__(
        self,
        rig: RigInterface,
        stage: CycleStage,
        clock: Clock,
        rate_hz: float,
        duration_s: float | None = None,
        *,
        safety: Any | None = None,
        recorder: _Recorder | None = None,
        stop: Any | None = None,
        overrun_policy: str = "skip",
        warn_interval_s: float = 1.0,
        warn: Callable[[str], None] | None = None,
        tuning: Any | None = None,
        timing: TimingStats | None = None,
    ):
        """``timing``: statistics to fill (the run's stream's shared rings); None: private ones."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        if overrun_policy not in ("skip", "fail"):
            raise ValueError(f"overrun_policy must be 'skip' or 'fail', got {overrun_policy!r}")
        self.rig, self.stage, self.clock = rig, stage, clock
        self.rate_hz = float(rate_hz)
        self.period_ns = round(1e9 / rate_hz)
        self.max_cycles = None if duration_s is None else int(round(duration_s * rate_hz))
        self.safety, self.recorder, self.stop = safety, recorder, stop
        #: live parameter changes (sashil.runtime.tuning.LiveTuning), applied before a cycle's step
        self.tuning = tuning
        self.overrun_policy = overrun_policy
        self.warn_interval_ns = int(warn_interval_s * 1e9)
        self.warn = warn if warn is not None else log.warning
        self.timing = timing if timing is not None else TimingStats(rate_hz)
        #: called with the timing after each overrun (off the per-cycle path): the loop process
        #: publishes its missed deadlines to the stream
        self.on_overrun: Callable[[TimingStats], None] | None = None
        if tuning is not None:
            tuning.timing = self.timing  # a change's arrival is dated in the loop's cycles
        self.result = LoopResult(timing=self.timing)
        self.start_ns = 0
        self._last_warn_ns: int | None = None
        self._suppressed = 0
        names = stage_signals(stage)
        self._n_signals = len(names)
        self._signals = attrgetter(*names) if names else None
        #: the object the signals are read from: the one the stage names as their ``signal_source``
        #: (a plan that runs a controller: its plain attributes, read directly) when it has them all
        #: (a wrapper that forwards the name may add signals of its own), else the stage
        source = getattr(stage, "signal_source", stage)
        self._signal_source = source if all(hasattr(source, name) for name in names) else stage
        #: the recorder's rows are float64 slots (the run's stream: :mod:`sashil.runtime.stream`)
        self._typed_rows = bool(getattr(recorder, "typed_rows", False))

    # the run ---------------------------------------------------------------------------------
    def run(self) -> LoopResult:
        """Run the loop once. It stops at the next cycle when ``stop.requested`` (the runner routes
        SIGINT, SIGTERM and SIGHUP to that flag: :func:`sashil.runtime.runner.run_plan`)."""
        rig, stage, clock, result, timing = self.rig, self.stage, self.clock, self.result, self.timing
        safety, recorder, stop, tuning = self.safety, self.recorder, self.stop, self.tuning
        period = self.period_ns
        max_cycles = self.max_cycles
        now = clock.now_ns
        sleep_until = clock.sleep_until
        spin_ns = getattr(clock, "spin_ns", 0)
        windowed = recorder is not None and not getattr(clock, "virtual", False)
        t = now()
        sample: RigSample | None = None
        try:
            rig.configure()
            rig.activate()
            log.debug("loop: running at %g Hz", self.rate_hz)  # after activate: stops from here are clean
            read, write, step = rig.read, rig.write, stage.step
            check = safety.check if safety is not None else None
            limit = safety.limit if safety is not None else None
            record = self._record if recorder is not None else None
            lateness, read_ns, compute_ns, write_ns = timing.lateness, timing.read, timing.compute, timing.write
            mask, fold_mask = timing.mask, FOLD - 1
            # a device-paced link (sashil.drivers.link_rig) streams samples on its own clock; sleeping
            # to a host deadline as well would beat the two clocks against each other
            paced = capabilities_of(rig).device_paced
            late = 0
            start = deadline = last = now()
            self.start_ns = start
            if safety is not None:
                safety.start(start)
            cycles = 0
            while max_cycles is None or cycles < max_cycles:
                if stop is not None and stop.requested:
                    result.exit_status = "stopped"
                    result.stop_reason = getattr(stop, "signal_name", None) or "stop requested"
                    break
                if windowed:
                    recorder.window_end_ns = deadline - spin_ns - WRITER_GUARD_NS  # type: ignore[union-attr]
                if paced:
                    t = now()  # the device's sample timer paces the cycle: read() blocks for it
                else:
                    sleep_until(deadline)
                    t = now()
                    late = t - deadline
                    if late >= period:
                        self._overrun(t, late)
                        deadline += (late // period) * period
                dt = t - last
                last = t
                sample = read(t, dt)
                t_read = now()
                if paced:
                    # lateness of a sample against one period after the previous one: jitter of
                    # the device's stream as the host sees it; a lost sample counts as a miss
                    late = t_read - deadline if cycles else 0
                    if late >= period:
                        self._overrun(t_read, late)
                    deadline = t_read
                    if late < 0:
                        late = 0
                if check is not None:
                    check(sample, t)
                if tuning is not None and tuning.busy:  # a live change: between two steps of the law
                    tuning.service((t - start) * 1e-9, cycles)
                cmd = step(sample, t, dt)
                if cmd is None:
                    break
                if limit is not None:
                    cmd = limit(cmd, dt)
                if record is not None:
                    record(t, sample, cmd.current_a, cmd.road_speed_rad_s, 0)
                    if recorder is not None and recorder.error is not None:  # the disk failed: 0 A now
                        raise RecordingError(f"{recorder.path}: recording failed: {recorder.error}")
                t_write = now()
                write(cmd, t, dt)
                t_end = now()
                slot = cycles & mask  # the timing rings: constant memory however long the run
                lateness[slot] = late
                read_ns[slot] = t_read - t
                compute_ns[slot] = t_write - t_read
                write_ns[slot] = t_end - t_write
                cycles += 1
                timing.cycles = cycles
                if not cycles & fold_mask:  # every FOLD cycles, after the write: into the histograms
                    timing.fold()
                deadline += period
        except BaseException as err:
            result.exit_status = self._status_of(err)
            result.error = str(err) or type(err).__name__
            self._finish(t, sample, safety.trip_code if isinstance(err, SafetyTrip) and safety is not None else 0)
            raise
        if result.exit_status == "stopped" and sample is not None:
            try:
                t, sample = self._settle(t, sample)
            except Exception as err:  # the rig failed while settling: the shutdown below still runs
                result.shutdown_errors.append(f"settle at 0 A: {type(err).__name__}: {err}")
        self._finish(t, sample, 0)
        if result.shutdown_errors:
            result.exit_status = "error"
            result.error = "shutdown: " + "; ".join(result.shutdown_errors)
            raise DriverIOError(result.error)
        return result

    # helpers (off the per-cycle path unless noted) ---------------------------------------------
    def _record(
        self,
        t_ns: int,
        sample: RigSample | None,
        current_cmd: float,
        road_speed: float | None,
        trip_code: int,
        phase: int | None = None,
    ) -> None:
        """Fill one data row in the recorder's ring (per cycle; no allocation)."""
        recorder = self.recorder
        row = recorder.begin_row()  # type: ignore[union-attr]
        row[0] = (t_ns - self.start_ns) * 1e-9
        if sample is None:
            row[1] = row[2] = row[4] = NAN
            row[-9] = row[-8] = row[-7] = row[-5] = -1
            row[-6] = row[-4] = 0
        else:
            row[1] = sample.theta_rad
            row[2] = sample.current_a
            row[4] = sample.theta_road_rad
            row[-9] = sample.seq
            row[-8] = sample.device_time_us
            row[-7] = sample.arm_edge_us
            row[-6] = sample.arm_edge_dir
            row[-5] = sample.road_edge_us
            row[-4] = sample.road_edge_dir
        row[3] = current_cmd
        signals = self._signals
        if signals is not None:
            if self._n_signals == 1:
                value = signals(self._signal_source)
                if self._typed_rows:
                    row[5] = NAN if value is None else value
                else:
                    row[5] = value
            elif self._typed_rows:  # a slot of float64: element by element, None as NaN
                for k, value in enumerate(signals(self._signal_source), 5):
                    row[k] = NAN if value is None else value
            else:
                row[5 : 5 + self._n_signals] = signals(self._signal_source)
        row[-3] = NAN if road_speed is None else road_speed
        row[-2] = getattr(self.stage, "phase_code", 0) if phase is None else phase
        row[-1] = trip_code
        recorder.commit_row()  # type: ignore[union-attr]

    def _settle(self, t_ns: int, sample: RigSample) -> tuple[int, RigSample]:
        """After a stop: command 0 A with the road at rest and read on, one period apart, until the
        coil's measured current is at most :data:`SAFE_CURRENT_A` or :data:`SETTLE_S` have passed.
        Each read is a row (``current_cmd_a`` 0, ``phase`` :data:`SETTLE_PHASE`), so the record shows the current decaying with the
        coil's lag; :attr:`LoopResult.safe_state` says where and when it ended. Returns the last
        read's time and sample."""
        rig, clock, period = self.rig, self.clock, self.period_ns
        paced = capabilities_of(rig).device_paced
        start = last = t_ns
        deadline = t_ns + period
        reads = 0
        rig.write(SAFE_COMMAND, t_ns, 0)
        while abs(sample.current_a) > SAFE_CURRENT_A and deadline - start <= SETTLE_S * 1e9:
            if not paced:
                clock.sleep_until(deadline)
            t_ns = clock.now_ns()
            sample = rig.read(t_ns, t_ns - last)
            last = t_ns
            if self.recorder is not None:
                self._record(t_ns, sample, SAFE_COMMAND.current_a, 0.0, 0, SETTLE_PHASE)
            rig.write(SAFE_COMMAND, t_ns, 0)  # a host-paced board answers each command with a sample
            reads += 1
            deadline += period
        sensed = sample.current_a == sample.current_a  # NaN: no sense measures the coil
        self.result.safe_state = {
            "current_a": round(float(sample.current_a), 4) if sensed else None,
            "after_s": round((t_ns - start) * 1e-9, 4),
            "confirmed": abs(sample.current_a) <= SAFE_CURRENT_A,
            "sensed": sensed,
            "reads": reads,  # rows the settling added to the record
        }
        return t_ns, sample

    def _overrun(self, t_ns: int, late_ns: int) -> None:
        missed = late_ns // self.period_ns
        timing = self.timing
        timing.skip(late_ns, self.period_ns, missed)
        if self.overrun_policy == "fail":
            timing.missed_deadlines += missed
            timing.overruns += 1
            raise DeadlineMissedError(
                f"deadline missed: cycle {timing.cycles} started {late_ns / 1000:.0f} us late "
                f"(period {self.period_ns / 1000:g} us; loop.overrun_policy is 'fail')"
            )
        timing.missed_deadlines += missed
        timing.overruns += 1
        if self.on_overrun is not None:
            self.on_overrun(timing)
        if self._last_warn_ns is None or t_ns - self._last_warn_ns >= self.warn_interval_ns:
            more = f" (+{self._suppressed} more overrun(s) since the last warning)" if self._suppressed else ""
            self.warn(
                f"loop overrun: cycle {timing.cycles} started {late_ns / 1000:.0f} us late, "
                f"skipped {missed} period(s){more}"
            )
            self._last_warn_ns = t_ns
            self._suppressed = 0
        else:
            self._suppressed += 1

    @staticmethod
    def _status_of(err: BaseException) -> str:
        return status_of(err)

    def _finish(self, t_ns: int, sample: RigSample | None = None, trip_code: int = 0) -> None:
        """Safe state: 0 A, deactivate, close (each once), whatever failed before. The stream's last
        row is the safe command the shutdown sends (0 A, the road at rest), after the last cycle's."""
        result, rig = self.result, self.rig
        result.cycles = self.timing.cycles
        result.missed_deadlines = self.timing.missed_deadlines
        if self.safety is not None:
            self.safety.safe_state()
            result.trips = [trip.as_dict() for trip in self.safety.trips]
        if self.recorder is not None:
            self.recorder.window_end_ns = None
            if sample is not None:  # dated one period on: the state the rig is left in from then
                self._record(t_ns + self.period_ns, sample, SAFE_COMMAND.current_a, 0.0, trip_code)
        try:
            rig.write(SAFE_COMMAND, t_ns, 0)
        except Exception as err:
            write_error: Exception | None = err
        else:
            write_error = None
        for name, action in (("deactivate", rig.deactivate), ("close", rig.close)):
            try:
                action()
            except Exception as err:
                result.shutdown_errors.append(f"{name}(): {type(err).__name__}: {err}")
        if write_error is not None and result.shutdown_errors:
            result.shutdown_errors.insert(0, f"0 A write: {type(write_error).__name__}: {write_error}")

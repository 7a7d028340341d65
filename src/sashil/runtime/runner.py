"""The one loop runner: every verb that drives a rig runs its plan through :func:`run_plan`.

A *plan* is a loop stage (``step(sample, t_ns, dt_ns) -> RigCommand | None``): what to command and
when, what to measure. The runner owns everything around it, the same for ``run``, ``drop-test``,
``sweep`` and the calibration plan:

* the warm-up before the rig is touched (:mod:`sashil.runtime.warmup`: every numba kernel a cycle
  can call compiled or loaded, the law called once and reset), so the first cycle is on time;
* the disk checked before anything is energised (:func:`check_disk`, a :class:`DiskSpaceError`,
  exit 2, when the run folder's disk cannot hold the run);
* the best-effort real-time set-up on the real clock (``loop.rt``), undone afterwards;
* SIGINT, SIGTERM and SIGHUP → a stop flag → a clean stop at the next cycle;
* the safety supervisor of the config's ``safety`` section;
* recording: the loop's every cycle streamed to ``data_path`` by the threaded recorder (written at
  least once a second, so a kill -9 loses at most about a second); a write error mid-run stops the
  loop at 0 A (:class:`~sashil.errors.RecordingError`, exit 1);
* the rig's lifecycle: configure, activate, and whatever ends the run, 0 A, the road at rest,
  deactivate (which waits for the device to confirm it), close;
* the common part of ``summary.json`` (:attr:`RunOutcome.summary`).

Plans command; one stream records. A plan keeps no copy of the data: what a verb writes beyond
the stream (a drop test's record from the release, a sweep's transmissibility, a calibration
step on the device's clock) it derives after the run from the stream's columns
(``read_stream=True``: :attr:`RunOutcome.stream`), whose rows carry the sample's ``seq`` and device
time, the road speed commanded and the plan's ``phase``. On simulated time the recorder keeps those
rows in memory as well (the values the file parses back to), so nothing is parsed again, and without
a ``data_path`` no file is written. On the real clock the loop's hot path allocates nothing: the
stream goes to the file (a temporary one without a ``data_path``) and is read back after the run.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.drivers.interface import capabilities_of
from sashil.errors import DataFileError, DiskSpaceError, LossError, Stopped, error_fields, exit_code_of
from sashil.recording.data_file import read_data_csv
from sashil.recording.recorder import Recorder
from sashil.runtime.clock import Clock
from sashil.runtime.loop import ControlLoop, record_columns
from sashil.runtime.rt_setup import RealtimeSetup
from sashil.runtime.signals import StopFlag, catch_stop_signals, stopped_error
from sashil.runtime.tuning import EVENT_COLUMNS
from sashil.safety import SafetySupervisor
from sashil.writer.run_folder import DATA_FILES

if TYPE_CHECKING:
    from sashil.config.parts import LoopParts, RunSpec

#: the stream of every loop cycle in a verb's folder when its data.csv is derived after the run
#: (drop-test, sweep, calibrate: columns as ``sashil run``'s data.csv, time from the loop's start)
CYCLES_FILE = DATA_FILES[1]
#: bytes of CSV per data.csv value (a float's repr and its comma), for the disk check
BYTES_PER_VALUE = 22
#: a run of unknown length must find room for this many seconds of data
OPEN_ENDED_S = 600.0
#: headroom kept free beside the run's data (the summary, plots, the file system's own)
DISK_MARGIN_BYTES = 16 * 1024 * 1024


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def check_disk(folder: Path, columns: int, rate_hz: float, duration_s: float | None) -> int:
    """Bytes the run will write; DiskSpaceError if ``folder``'s disk has not that much free (plus
    a margin). A run without a duration is checked for OPEN_ENDED_S seconds."""
    seconds = OPEN_ENDED_S if duration_s is None else duration_s
    need = int(seconds * rate_hz * columns * BYTES_PER_VALUE)
    free = shutil.disk_usage(folder).free
    if free < need + DISK_MARGIN_BYTES:
        span = "10 minutes (no --duration)" if duration_s is None else f"{seconds:g} s"
        raise DiskSpaceError(
            f"{folder}: {free / 1e6:.1f} MB free on its disk; the run writes about {need / 1e6:.1f} MB "
            f"({span} at {rate_hz:g} Hz, {columns} columns) plus {DISK_MARGIN_BYTES // 2**20} MB of headroom: "
            "free some space or choose --out on another disk"
        )
    return need


def losses(loop: LoopParts, timing: Any, link: dict[str, Any] | None) -> LossError | None:
    """The :class:`~sashil.errors.LossError` of a run that missed more of its scheduled deadlines than
    the ``loop``'s ``max_missed_fraction`` (``loop.max_missed_fraction``) or lost more of its samples
    than its ``max_lost_fraction`` (``driver.max_lost_fraction``) allows, naming what was lost and the key; None when it stayed within both."""
    problems = []
    scheduled = timing.cycles + timing.missed_deadlines
    allowed = loop.max_missed_fraction
    if scheduled and timing.missed_deadlines > allowed * scheduled:
        problems.append(
            f"missed {timing.missed_deadlines} of {scheduled} deadlines ({100 * timing.missed_deadlines / scheduled:.2g} %; "
            f"loop.max_missed_fraction allows {100 * allowed:g} %)"
        )
    if link:
        lost = int(link.get("samples_missed", 0))
        expected = int(link.get("samples", 0)) + lost
        allowed = loop.max_lost_fraction
        if expected and lost > allowed * expected:
            problems.append(
                f"lost {lost} of {expected} samples ({100 * lost / expected:.2g} %; driver.max_lost_fraction allows {100 * allowed:g} %)"
            )
    return LossError("the run " + " and ".join(problems) + "; its data are kept") if problems else None


def loop_summary(
    *,
    exit_status: str,
    timing: dict[str, Any],
    trips: list[dict[str, Any]],
    error: BaseException | None,
    stop_reason: str | None,
    controller_stats: dict[str, Any] | None,
    safety: dict[str, Any] | None,
    realtime: dict[str, Any],
    recording: dict[str, Any] | None,
    link: dict[str, Any] | None,
    shutdown_errors: list[str],
    error_text: str | None = None,
    safe_state: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The keys of summary.json every loop run has, in one place: the run in this process
    (:meth:`RunOutcome.summary`), in a loop process (:meth:`~sashil.runtime.loop_process.LoopProcess.run`)
    and a loop whose session died (:mod:`~sashil.runtime.orphan`). ``exit_code`` follows from the
    status and the error; ``error`` is ``error_text`` (default: the error's line) when there is one.
    ``safe_state``: after a stop, the coil's measured current at 0 A and how soon it got there."""
    return {
        "exit_status": exit_status,
        "timing": timing,
        "trips": trips,
        "exit_code": exit_code_of(exit_status, error),
        "error": (error_text or str(error)) if error is not None else None,
        "stop_reason": stop_reason,
        "controller_stats": controller_stats,
        "safety": safety,
        "realtime": realtime,
        "recording": recording,
        "link": link,
        "shutdown_errors": shutdown_errors,
        "safe_state": safe_state,
    }


def end_summary(
    end: dict[str, Any],
    *,
    exit_status: str,
    timing: dict[str, Any],
    error: BaseException | None,
    realtime: dict[str, Any],
    recording: dict[str, Any] | None,
) -> dict[str, Any]:
    """:func:`loop_summary` of a loop that ran in a loop process, from its ``end`` message: the one
    reading of that message, for the session (:class:`~sashil.runtime.loop_process.LoopEnd`) and for
    a loop whose session died (:mod:`~sashil.runtime.orphan`)."""
    return loop_summary(
        exit_status=exit_status,
        timing=timing,
        trips=list(end.get("trips", [])),
        error=error,
        stop_reason=end.get("stop_reason"),
        controller_stats=end.get("controller_stats"),
        safety=end.get("safety"),
        realtime=realtime,
        recording=recording,
        link=end.get("link"),
        shutdown_errors=list(end.get("shutdown_errors", [])),
        error_text=end.get("error_text"),
        safe_state=end.get("safe_state"),
    )


@dataclass
class RunOutcome:
    """What a loop run leaves, whether it ran in this process (:func:`run_plan`) or in its own
    (``run_plan_process``, :meth:`~sashil.runtime.loop_process.LoopProcess.run`): the error that
    ended the run (None: it ended normally or by a signal), its timing and start, and its
    summary.json keys, from which the properties read how it ended (one record of it, wherever the
    loop ran)."""

    error: BaseException | None
    stop: StopFlag
    timing: Any
    #: the loop's start on CLOCK_MONOTONIC [ns] (the stream's ``time_s`` counts from it)
    start_ns: int
    #: summary.json: the keys every loop run has (:func:`loop_summary`), and the session's own when
    #: a session wrote the run's folder (:func:`~sashil.runtime.session.run_session`)
    summary: dict[str, Any]
    realtime: dict[str, Any] = field(default_factory=dict)
    recording: dict[str, Any] | None = None
    link: dict[str, Any] | None = None
    #: the stream's columns (``run_plan(read_stream=True)``): time from the loop's start, one row per
    #: cycle and the shutdown's safe-state row; empty when the run recorded nothing
    stream: dict[str, Any] = field(default_factory=dict)
    #: the CAN trace's statistics when the run was traced
    can_trace: dict[str, Any] | None = None
    #: the loop process that ran the loop (pid, threads, start-up; ``died`` when it did), None: this one
    loop_process: dict[str, Any] | None = None
    #: the live tuning's summary.json keys (None: the run was not tuned), its ``events.csv`` rows and
    #: its notes on a view's time axis (``(time_s, text)``)
    tuning: dict[str, Any] | None = None
    tuning_rows: list[list[Any]] = field(default_factory=list)
    tuning_notes: list[tuple[float, str]] = field(default_factory=list)

    @property
    def exit_status(self) -> str:
        """``ok``, ``stopped``, ``safety_trip``, ``lossy``, ``error`` (summary.json's ``exit_status``)."""
        return str(self.summary["exit_status"])

    @property
    def trips(self) -> list[dict[str, Any]]:
        """The safety supervisor's trips, in order."""
        return list(self.summary["trips"])

    @property
    def stop_reason(self) -> str | None:
        """What stopped the run (a signal's name, ``stop requested``), None when nothing did."""
        return self.summary.get("stop_reason")

    @property
    def safe_state(self) -> dict[str, Any] | None:
        """After a stop, how the coil's measured current settled at 0 A."""
        return self.summary.get("safe_state")

    @property
    def exit_code(self) -> int:
        return exit_code_of(self.exit_status, self.error)

    def stop_error(self) -> Stopped | None:
        """:class:`~sashil.errors.Stopped` if a signal stopped the run cleanly (exit 130), else None."""
        if self.exit_status == "stopped" and self.stop.requested:
            return stopped_error(self.stop)
        return None

    def raise_stop(self) -> None:
        """Raise :meth:`stop_error` if a signal stopped the run."""
        stopped = self.stop_error()
        if stopped is not None:
            raise stopped


@dataclass(frozen=True)
class LoopHooks:
    """What a session hands its loop for a run: where the loop's lines go (``say``), the readers of
    its stream (``live``: ``start(stream, timing)``), whether to serve live tuning on the folder's
    socket, the caller's stop flag and the verb that runs it."""

    say: Callable[[str], None]
    live: Any = None
    tune: bool = False
    stop: StopFlag | None = None
    verb: str = "run"


def control_loop(
    spec: RunSpec,
    rig: Any,
    stage: Any,
    clock: Clock,
    duration_s: float | None,
    *,
    warn: Callable[[str], None],
    rate_hz: float | None = None,
    recorder: Any = None,
    tuning: Any = None,
    stop: Any = None,
    timing: Any = None,
) -> ControlLoop:
    """The run's :class:`~sashil.runtime.loop.ControlLoop`, wherever it runs (this process, or a
    loop process: :mod:`sashil.runtime.worker`): ``stage`` on ``rig`` at the spec's rate (or
    ``rate_hz``) on ``clock``, under the spec's safety limits and overrun policy, its rows to
    ``recorder``, its warnings to ``warn``. On the real clock a preview law's re-planning moves to a
    planner process beside the loop (:func:`sashil.runtime.planner.plan_beside_loop`)."""
    from sashil.runtime.planner import plan_beside_loop  # the session's process loads no planner

    loop = spec.loop
    plan_beside_loop(stage, bool(getattr(clock, "virtual", False)))
    return ControlLoop(
        rig,
        stage,
        clock,
        float(rate_hz if rate_hz is not None else loop.rate_hz),
        duration_s,
        safety=SafetySupervisor.from_parts(spec.safety),
        recorder=recorder,
        overrun_policy=loop.overrun_policy,
        warn_interval_s=loop.warn_interval_s,
        warn=warn,
        tuning=tuning,
        stop=stop,
        timing=timing,
    )


def loop_end(
    loop: ControlLoop,
    error: BaseException | None,
    stage: Any,
    rt: RealtimeSetup | None,
    rig: Any,
    tuning: Any = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """How a loop run ended, wherever it ran (a loop process sends it as its ``end`` message): how
    the loop ended, its timing counters, the stage's, the safety supervisor's, the real-time
    set-up's and the rig's facts, the tuning's events."""
    from sashil.runtime.planner import end_beside_loop

    end_beside_loop(stage)
    result = loop.result
    controller = stage if hasattr(stage, "clip_warning") else getattr(stage, "controller", None)
    clipped = getattr(controller, "clip_warning", None)
    return {
        "exit_status": result.exit_status,
        "error": error_fields(error) if error is not None else None,
        "error_text": result.error,
        "stop_reason": result.stop_reason,
        "trips": result.trips,
        "shutdown_errors": result.shutdown_errors,
        "safe_state": result.safe_state,
        "timing": loop.timing.counters(),
        "controller_stats": stage.stats() if hasattr(stage, "stats") else None,
        "safety": loop.safety.summary() if loop.safety is not None else None,
        "realtime": rt.report() if rt is not None else {},
        "link": rig.link_stats() if capabilities_of(rig).link else None,
        "clip_warning": clipped() if callable(clipped) else None,
        "tuning": tuning.summary() if tuning is not None else None,
        "tuning_notes": tuning.notes() if tuning is not None else [],
        "threads": threads,
        "start_ns": loop.start_ns,
        "plan": stage.facts() if hasattr(stage, "facts") else None,
    }


def outcome_of(
    end: dict[str, Any],
    *,
    error: BaseException | None,
    exit_status: str,
    stop: StopFlag,
    timing: Any,
    realtime: dict[str, Any],
    recording: dict[str, Any] | None,
    stream: dict[str, Any] | None = None,
    can_trace: dict[str, Any] | None = None,
    loop_process: dict[str, Any] | None = None,
) -> RunOutcome:
    """The :class:`RunOutcome` of a loop run from its end (:func:`loop_end`), wherever it ran: the
    one place one is made. ``timing``: the loop's statistics; ``recording`` None for a run that
    wrote no data file of its own."""
    events = (end.get("tuning") or {}).get("events") or []
    return RunOutcome(
        error,
        stop,
        timing,
        int(end.get("start_ns") or 0),
        end_summary(
            end, exit_status=exit_status, timing=timing.summary(), error=error, realtime=realtime, recording=recording
        ),
        realtime=realtime,
        recording=recording,
        link=end.get("link"),
        stream=stream if stream is not None else {},
        can_trace=can_trace,
        loop_process=loop_process,
        tuning=end.get("tuning"),
        tuning_rows=[[event[name] for name in EVENT_COLUMNS] for event in events],
        tuning_notes=[(float(time_s), str(text)) for time_s, text in end.get("tuning_notes") or []],
    )


def run_realtime(loop: ControlLoop, rt: RealtimeSetup | None, note: Callable[[str], None]) -> BaseException | None:
    """Run ``loop`` under the real-time set-up ``rt`` (its steps reported through ``note``, undone
    afterwards); the error that ended the loop, if any (the rig is then already at 0 A, deactivated
    and closed)."""
    try:
        if rt is not None:
            rt.apply()
            for line in rt.lines():
                note(line)
        try:
            loop.run()
        except BaseException as err:
            return err
        return None
    finally:
        if rt is not None:
            rt.restore()


def run_plan(
    spec: RunSpec,
    rig: Any,
    plan: Any,
    clock: Clock,
    duration_s: float | None = None,
    *,
    data_path: str | Path | None = None,
    rate_hz: float | None = None,
    say: Callable[[str], None] = _stderr,
    note: Callable[[str], None] | None = None,
    realtime: bool = True,
    live: Any = None,
    stop: StopFlag | None = None,
    read_stream: bool = False,
    tuning: Any = None,
) -> RunOutcome:
    """Run ``plan`` on ``rig`` (see the module docstring); never raises for what ends the loop.

    ``spec``: the assembled run (its loop's rate and set-up, its safety limits). ``data_path``:
    stream every cycle there (None: no stream). ``rate_hz``: the loop's rate (default ``spec.loop.rate_hz``). ``say``: the loop's warnings (overruns); ``note``: the real-time set-up's
    report, one line per step (default ``say``). ``realtime``: apply ``loop.rt`` on the real clock. ``live``: the rerun live
    view. ``stop``: a stop flag of the caller's (a calibration plan shares one across its runs); the
    signals are routed to it for the run. A disk too full for the run raises DiskSpaceError before
    the rig is touched. ``read_stream``: read the stream back into :attr:`RunOutcome.stream` (a
    temporary file holds it when there is no ``data_path``). ``tuning``: live parameter changes
    for the plan's law (:class:`~sashil.runtime.tuning.LiveTuning`), applied between cycles.
    """
    loop_parts = spec.loop
    rate = float(rate_hz if rate_hz is not None else loop_parts.rate_hz)
    columns = record_columns(plan)
    real_clock = not getattr(clock, "virtual", False)
    keep = read_stream and not real_clock  # the stream in memory (module docstring)
    scratch = None
    if data_path is None and read_stream and not keep:
        scratch = tempfile.TemporaryDirectory(prefix="sashil-stream-")
        data_path = Path(scratch.name) / CYCLES_FILE
    recorder = None
    if data_path is not None:
        data_path = Path(data_path)
        check_disk(data_path.parent, len(columns), rate, duration_s)
    if data_path is not None or keep:
        recorder = Recorder(data_path, columns, lossless=not real_clock, keep=keep)
    rt = RealtimeSetup.from_parts(loop_parts.rt) if realtime and real_clock else None
    if rt is not None and live is not None:
        rt.current_only = True  # the live view allocates beside the loop (see RealtimeSetup._mlockall)
    loop = control_loop(spec, rig, plan, clock, duration_s, warn=say, rate_hz=rate, recorder=recorder, tuning=tuning)
    # loaded here, not with the module: a session whose loop runs in a loop process imports this
    # module for its summary and never loads numba's kernels itself
    from sashil.runtime.warmup import warm_up

    warm_up(plan, say)  # before the rig is touched: the first cycle is on time (overrun_policy: fail usable)
    error, flag = _run_recorded(loop, recorder, live, rt, stop, note or say)
    stream = _read_back(recorder if keep else None, data_path if read_stream else None)
    if scratch is not None:
        scratch.cleanup()
    end = loop_end(loop, error, plan, rt, rig)
    if end["clip_warning"] is not None:
        say(end["clip_warning"])
    lost = losses(loop_parts, loop.timing, end["link"]) if error is None and end["exit_status"] == "ok" else None
    if lost is not None:  # a run that lost what the config does not allow does not end ok
        error = lost
        end.update(exit_status="lossy", error_text=str(lost))
        say(str(lost))
    recording = recorder.summary() if recorder is not None and data_path is not None else None
    return outcome_of(
        end,
        error=error,
        exit_status=end["exit_status"],
        stop=flag,
        timing=loop.timing,
        realtime=end["realtime"],
        recording=recording,
        stream=stream,
    )


def _run_recorded(
    loop: ControlLoop,
    recorder: Recorder | None,
    live: Any,
    rt: RealtimeSetup | None,
    stop: StopFlag | None,
    note: Callable[[str], None],
) -> tuple[BaseException | None, StopFlag]:
    """Run ``loop`` with the stop signals routed to ``stop`` (or a flag of its own), the recorder
    and the live view started first and the recorder closed after; the error that ended the run
    (a recorder that cannot close ends it in error) and the stop flag."""
    error: BaseException | None = None
    with catch_stop_signals(stop) as flag:
        loop.stop = flag
        if recorder is not None:
            recorder.start()
        if live is not None:  # the rerun live view (sashil.recording.rerun_log.LiveTap)
            live.start(recorder, loop.timing)
        try:
            error = run_realtime(loop, rt, note)
        finally:
            if recorder is not None:
                try:
                    recorder.close()
                except OSError as err:
                    if error is None:
                        error = err
                        loop.result.exit_status = "error"
                        loop.result.error = str(err)
    return error, flag


def _read_back(kept: Recorder | None, data_path: Path | None) -> dict[str, Any]:
    """The run's stream: the columns the recorder ``kept`` in memory, else those read back from
    ``data_path``, else none."""
    if kept is not None:
        return kept.stream()
    if data_path is not None:
        try:
            return read_data_csv(data_path, required=(), min_rows=0)
        except DataFileError:  # a stream the disk lost: what ended the run says why
            return {}
    return {}

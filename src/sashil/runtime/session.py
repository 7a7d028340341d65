"""One closed-loop session into a run folder: RT set-up, signals, safety, recorder, loop, summary.

``run_session`` is what ``sashil run`` (and ``tools/bench_loop.py``) call: it writes
``config.yaml`` first, records ``data.csv`` through the threaded recorder while the loop runs, and
always writes ``summary.json`` at the end, whatever ended the loop (a signal, a trip, an error).
The rig is already in the safe state (0 A, deactivated, closed) when the summary is written.

summary.json (docs/architecture.md fixed keys first): ``exit_status`` (ok | stopped | safety_trip |
deadline_missed | error), ``timing`` ({rate_hz, cycles, missed_deadlines, lateness_us,
compute_us} each with p50/p99/p99_9/max, plus overruns, read_us, write_us, cycle_us), ``trips``,
then ``exit_code``, ``error``, ``stop_reason``, ``safety``, ``realtime`` (each set-up step's
outcome), ``recording`` (rows written/dropped) and ``controller``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sashil import errors
from sashil.recording.run_folder import RunFolder
from sashil.runtime.clock import Clock
from sashil.runtime.loop import LoopResult
from sashil.runtime.runner import run_plan
from sashil.runtime.signals import StopFlag
from sashil.runtime.tune_socket import TuneServer
from sashil.runtime.tuning import EVENT_COLUMNS, RAMP_KEY, LiveTuning

if TYPE_CHECKING:
    from sashil.runtime.loop_process import LoopProcess

#: the run folder's record of live parameter changes (sashil tune)
EVENTS_FILE = "events.csv"


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def open_tuning(
    config: dict[str, Any], stage: Any, folder: RunFolder, say: Callable[[str], None]
) -> tuple[LiveTuning | None, TuneServer | None]:
    """The live tuning of ``stage``'s law on ``folder``'s socket, started; (None, None) when the
    stage has no law or the socket cannot be made (said in one line: the run goes on untuned)."""
    law = getattr(stage, "law", None)
    if law is None or not hasattr(law, "check_parameters"):
        return None, None
    tuning = LiveTuning(law, float(config["loop"]["rate_hz"]), float(config["controller"].get(RAMP_KEY, 0.0)))
    try:
        server = TuneServer(folder.path, tuning).start()
    except OSError as err:
        say(f"live tuning: off ({folder.path}: cannot listen on a Unix socket: {err.strerror or err})")
        return None, None
    say(f"live tuning: sashil tune {folder.path} controller.<param>=VALUE")
    return tuning, server


@dataclass
class SessionOutcome:
    result: LoopResult
    summary: dict[str, Any]
    error: BaseException | None
    exit_code: int


def run_session(
    config: dict[str, Any],
    rig: Any,
    stage: Any,
    folder: RunFolder,
    clock: Clock,
    duration_s: float | None,
    *,
    controller: str = "passive",
    verb: str = "run",
    say: Callable[[str], None] = _stderr,
    realtime: bool = True,
    live: Any = None,
    tune: bool = False,
    finish: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
    stop: StopFlag | None = None,
) -> SessionOutcome:
    """Run ``stage`` on ``rig`` in closed loop through the one runner
    (:func:`~sashil.runtime.runner.run_plan`), streaming ``data.csv`` into ``folder``; then the
    timing file and ``summary.json`` (see module doc). ``tune``: serve live changes of the stage's
    law on the folder's tuning socket while the loop runs (:mod:`sashil.runtime.tune_socket`),
    recorded in ``events.csv`` and ``summary.json``'s ``tuning``. ``finish``: the verb's one hook,
    called with the session's summary once the data and timing are on disk; the keys it returns are
    added before ``summary.json`` is written, once. ``stop``: a flag another thread may set to stop
    the run cleanly (signals are routed to it as well when the session runs on the main thread)."""
    folder.write_config(config)
    tuning, server = open_tuning(config, stage, folder, say) if tune else (None, None)
    try:
        outcome = run_plan(
            config,
            rig,
            stage,
            clock,
            duration_s,
            data_path=folder.file("data.csv"),
            say=say,
            realtime=realtime,
            live=live,
            tuning=tuning,
            stop=stop,
        )
    finally:
        if tuning is not None and server is not None:
            tuning.close()
            server.stop()
    result = outcome.result
    notes = tuning.notes() if tuning is not None else ()
    live_stats = live.close(result.trips, notes) if live is not None else None
    if tuning is not None and tuning.events:
        folder.write_rows(EVENTS_FILE, EVENT_COLUMNS, tuning.rows())
    folder.write_timing(outcome.loop.timing)
    summary: dict[str, Any] = {
        "verb": verb,
        **outcome.summary(),
        "controller": controller,
        "duration_s": duration_s,
        "driver": config["driver"]["name"],
        "live_view": live_stats,
        "tuning": tuning.summary() if tuning is not None else None,
    }
    if finish is not None:
        summary.update(finish(summary))
    folder.write_summary(summary)
    return SessionOutcome(result, summary, outcome.error, outcome.exit_code)


def run_loop_process(
    process: LoopProcess,
    config: dict[str, Any],
    folder: RunFolder,
    duration_s: float | None,
    *,
    controller: str,
    verb: str = "run",
    say: Callable[[str], None] = _stderr,
    live: Any = None,
    tune: bool = False,
    finish: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
    stop: StopFlag | None = None,
) -> SessionOutcome:
    """:func:`run_session` with the loop in its own process (:mod:`sashil.runtime.loop_process`):
    ``process`` is ready (its rig open, its kernels warm, its stream made). The session writes
    ``config.yaml``, checks the disk, records the stream into ``data.csv``, serves the views and the
    tuning socket, tells the loop to go, and writes the timing file and ``summary.json`` once,
    whatever ended the loop: a signal, a trip, an error, or the loop process's death."""
    from sashil.runtime.loop_process import LiveTiming, SessionSignals, confirm_safe, error_of
    from sashil.runtime.mailbox import CALLER_STOP
    from sashil.runtime.runner import check_disk, loop_summary, losses
    from sashil.runtime.stream_recorder import StreamRecorder

    stream = process.stream
    assert stream is not None
    rate = process.rate_hz
    recorder: StreamRecorder | None = None
    server = None
    try:  # until the loop is told to go, a failure ends the loop process with nothing energised
        folder.write_config(config)
        check_disk(folder.path, len(stream.columns), rate, duration_s)
        recorder = StreamRecorder(stream, folder.file("data.csv")).start()
        if tune and process.ready.get("tunable"):
            try:
                server = TuneServer(folder.path, handler=process.request).start()
                say(f"live tuning: sashil tune {folder.path} controller.<param>=VALUE")
            except OSError as err:
                say(f"live tuning: off ({folder.path}: cannot listen on a Unix socket: {err.strerror or err})")
        if live is not None:
            live.start(stream, LiveTiming(stream, rate))
    except BaseException:
        if server is not None:
            server.stop()
        if recorder is not None:
            recorder.close()
        process.abort()
        raise
    flag = stop if stop is not None else StopFlag()

    def forward(kind: str, text: str) -> None:
        say(text)

    flag.on_request = process.pass_stop(flag)  # a stop reaches the loop's next cycle, not the next poll
    try:
        with SessionSignals(flag, process):
            process.go(folder.path)
            end = process.wait_end(flag, forward)
    finally:
        flag.on_request = None
        if server is not None:
            server.stop()
    error: BaseException | None = None
    try:
        recorder.close()
    except OSError as err:
        error = err
    timing = stream.timing(rate)
    if end is not None:
        timing.restore(end["timing"])
        if end.get("clip_warning"):
            say(end["clip_warning"])
        if end.get("error") is not None:
            error = error_of(end["error"])
        status = end["exit_status"]
    else:  # the loop process died: its rows are kept, the rig is reopened and checked
        timing.cycles = stream.rows_committed
        code = process.process.returncode if process.process is not None else None
        end = {"exit_status": "error", "stop_reason": None, "trips": [], "shutdown_errors": []}
        found = confirm_safe(config, lambda kind, text: say(text))
        died = f"the loop process died (exit status {code}); the data up to its last committed row are kept"
        error = errors.SashilError(died)
        end.update(loop_died={"exit_status": code, "rig": found})
        status = "error"
    if error is not None and status == "ok":
        status = "error"
    lost = losses(config, timing, end.get("link")) if error is None and status == "ok" else None
    if lost is not None:
        error, status = lost, "lossy"
        say(str(lost))
    notes = end.get("tuning_notes") or []
    live_stats = live.close(end.get("trips", []), [tuple(note) for note in notes]) if live is not None else None
    events = (end.get("tuning") or {}).get("events") or []
    if events:
        folder.write_rows(EVENTS_FILE, EVENT_COLUMNS, [[event[name] for name in EVENT_COLUMNS] for event in events])
    folder.write_timing(timing)
    session_affinity = {"session": process.session_affinity} if process.session_affinity else {}
    summary: dict[str, Any] = {
        "verb": verb,
        **loop_summary(
            exit_status=status,
            timing=timing.summary(),
            trips=end.get("trips", []),
            error=error,
            stop_reason=flag.signal_name
            if end.get("stop_reason") == CALLER_STOP and flag.signal_name
            else end.get("stop_reason"),
            controller_stats=end.get("controller_stats"),
            safety=end.get("safety"),
            realtime={**end.get("realtime", {}), **session_affinity},
            recording=recorder.summary(),
            link=end.get("link"),
            shutdown_errors=end.get("shutdown_errors", []),
        ),
        "controller": controller,
        "duration_s": duration_s,
        "driver": config["driver"]["name"],
        "live_view": live_stats,
        "tuning": end.get("tuning"),
        "loop_process": {
            "pid": process.process.pid if process.process else None,
            "threads": end.get("threads"),
            "startup_s": None if process.startup_s is None else round(process.startup_s, 3),
            "since_spawn_s": None if process.since_spawn_s is None else round(process.since_spawn_s, 3),
        },
    }
    if "loop_died" in end:
        summary["loop_process"]["died"] = end["loop_died"]
    if finish is not None:
        summary.update(finish(summary))
    folder.write_summary(summary)
    process.close()
    result = LoopResult(
        cycles=timing.cycles,
        missed_deadlines=timing.missed_deadlines,
        exit_status=status,
        error=summary["error"],
        trips=list(summary["trips"]),
        timing=timing,
        stop_reason=summary["stop_reason"],
    )
    return SessionOutcome(result, summary, error, summary["exit_code"])

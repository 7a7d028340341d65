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
from typing import TYPE_CHECKING, Any

from sashil.recording.run_folder import RunFolder
from sashil.runtime.clock import Clock
from sashil.runtime.runner import RunOutcome, run_plan
from sashil.runtime.signals import StopFlag
from sashil.runtime.tune_socket import TuneServer
from sashil.runtime.tuning import EVENT_COLUMNS, RAMP_KEY, LiveTuning

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig
    from sashil.runtime.loop_process import LoopProcess

#: the run folder's record of live parameter changes (sashil tune)
EVENTS_FILE = "events.csv"


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def open_tuning(
    config: RunConfig, stage: Any, folder: RunFolder, say: Callable[[str], None]
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


def run_session(
    config: RunConfig,
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
) -> RunOutcome:
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
    notes = tuning.notes() if tuning is not None else ()
    live_stats = live.close(outcome.trips, notes) if live is not None else None
    outcome.summary = _close_folder(
        folder,
        config,
        outcome.timing,
        tuning.rows() if tuning is not None else [],
        {
            "verb": verb,
            **outcome.summary,
            "controller": controller,
            "duration_s": duration_s,
            "live_view": live_stats,
            "tuning": tuning.summary() if tuning is not None else None,
        },
        finish,
    )
    return outcome


def _close_folder(
    folder: RunFolder,
    config: RunConfig,
    timing: Any,
    event_rows: list[list[Any]],
    summary: dict[str, Any],
    finish: Callable[[dict[str, Any]], Mapping[str, Any]] | None,
) -> dict[str, Any]:
    """A session's last writes into ``folder``, wherever its loop ran: the live changes
    (``events.csv``, when there were any), the timing file, and ``summary.json`` once: ``summary``
    with the config's driver and the keys the verb's ``finish`` hook adds, given the summary so far."""
    if event_rows:
        folder.write_rows(EVENTS_FILE, EVENT_COLUMNS, event_rows)
    folder.write_timing(timing)
    summary = {**summary, "driver": config["driver"]["name"]}
    if finish is not None:
        summary.update(finish(summary))
    folder.write_summary(summary)
    return summary


def run_loop_process(
    process: LoopProcess,
    config: RunConfig,
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
) -> RunOutcome:
    """:func:`run_session` with the loop in its own process (:mod:`sashil.runtime.loop_process`):
    ``process`` is ready (its rig open, its kernels warm, its stream made). The session writes
    ``config.yaml``, checks the disk, records the stream into ``data.csv``, serves the views and the
    tuning socket, tells the loop to go, and writes the timing file and ``summary.json`` once,
    whatever ended the loop: a signal, a trip, an error, or the loop process's death."""
    from sashil.runtime.loop_process import drive
    from sashil.runtime.runner import loop_summary

    try:
        folder.write_config(config)
    except BaseException:
        process.abort()
        raise
    ended = drive(
        process,
        config,
        folder.file("data.csv"),
        duration_s,
        say=lambda kind, text: say(text),
        live=live,
        tune_folder=folder.path if tune else None,
        stop=stop,
        verb=verb,
    )
    end, timing, error, status = ended.end, ended.timing, ended.error, ended.exit_status
    notes = end.get("tuning_notes") or []
    live_stats = live.close(end.get("trips", []), [tuple(note) for note in notes]) if live is not None else None
    events = (end.get("tuning") or {}).get("events") or []
    session_affinity = {"session": process.session_affinity} if process.session_affinity else {}
    loop_process = {
        "pid": process.process.pid if process.process else None,
        "threads": end.get("threads"),
        "startup_s": None if process.startup_s is None else round(process.startup_s, 3),
        "since_spawn_s": None if process.since_spawn_s is None else round(process.since_spawn_s, 3),
        **({"died": end["loop_died"]} if "loop_died" in end else {}),
    }
    head: dict[str, Any] = {
        "verb": verb,
        **loop_summary(
            exit_status=status,
            timing=timing.summary(),
            trips=end.get("trips", []),
            error=error,
            stop_reason=end.get("stop_reason"),
            controller_stats=end.get("controller_stats"),
            safety=end.get("safety"),
            realtime={**end.get("realtime", {}), **session_affinity},
            recording=ended.recording,
            link=end.get("link"),
            shutdown_errors=end.get("shutdown_errors", []),
            safe_state=end.get("safe_state"),
        ),
        "controller": controller,
        "duration_s": duration_s,
        "live_view": live_stats,
        "tuning": end.get("tuning"),
        "loop_process": loop_process,
    }
    rows = [[event[name] for name in EVENT_COLUMNS] for event in events]
    summary = _close_folder(folder, config, timing, rows, head, finish)
    timing = timing.copy()  # the stream's shared rings end with the process
    process.close()
    return RunOutcome(error, ended.stop, timing, int(end.get("start_ns") or 0), summary)

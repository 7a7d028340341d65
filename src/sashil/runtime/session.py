"""One closed-loop session into a run folder, wherever its loop runs: config, stream, summary.

``run_session`` is what ``sashil run`` (and ``tools/bench_loop.py``) call. Its loop runs in this
process (:class:`InProcessLoop`: the one runner, RT set-up, signals, safety and the threaded
recorder) or in a process of its own (:class:`~sashil.runtime.loop_process.LoopProcess`: the
session records the loop's stream); the session's own part is the same either way. Its folder's
writer (:class:`~sashil.writer.folder_writer.FolderWriter`) writes ``config.yaml`` first and
always ``summary.json`` at the end, once, whatever ended the loop (a signal, a trip, an error, the
loop process's death). The rig is already in the safe state (0 A,
deactivated, closed) when the summary is written.

summary.json (docs/architecture.md fixed keys first): ``exit_status`` (ok | stopped | safety_trip |
deadline_missed | error), ``timing`` ({rate_hz, cycles, missed_deadlines, lateness_us,
compute_us} each with p50/p99/p99_9/max, plus overruns, read_us, write_us, cycle_us), ``trips``,
then ``exit_code``, ``error``, ``stop_reason``, ``safety``, ``realtime`` (each set-up step's
outcome), ``recording`` (rows written/dropped) and ``controller``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from sashil.runtime.clock import Clock
from sashil.runtime.runner import LoopHooks, RunOutcome, run_plan
from sashil.runtime.signals import StopFlag
from sashil.runtime.tune_socket import TuneServer
from sashil.runtime.tuning import EVENT_COLUMNS, LiveTuning
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

#: the run folder's record of live parameter changes (sashil tune)
EVENTS_FILE = "events.csv"


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def open_tuning(
    spec: RunSpec, stage: Any, folder: RunFolder, say: Callable[[str], None]
) -> tuple[LiveTuning | None, TuneServer | None]:
    """The live tuning of ``stage``'s law on ``folder``'s socket, started; (None, None) when the
    stage has no law or the socket cannot be made (said in one line: the run goes on untuned)."""
    law = getattr(stage, "law", None)
    if law is None or not hasattr(law, "check_parameters"):
        return None, None
    tuning = LiveTuning(law, spec.loop.rate_hz, spec.stage.controller.tune_ramp_s)
    try:
        server = TuneServer(folder.path, tuning).start()
    except OSError as err:
        say(f"live tuning: off ({folder.path}: cannot listen on a Unix socket: {err.strerror or err})")
        return None, None
    say(f"live tuning: sashil tune {folder.path} controller.<param>=VALUE")
    return tuning, server


class SessionLoop(Protocol):
    """The loop a session runs: in this process (:class:`InProcessLoop`) or in a process of its
    own (:class:`~sashil.runtime.loop_process.LoopProcess`, ready), and the run it was assembled for."""

    spec: RunSpec

    def run(self, folder: RunFolder, duration_s: float | None, hooks: LoopHooks) -> RunOutcome:
        """Run the loop, streaming ``data.csv`` into ``folder``; never raises for what ends the loop."""
        ...

    def abort(self) -> None:
        """Give up a loop that never ran (nothing was energised)."""
        ...

    def close(self) -> None:
        """Let go of what the run held once its folder is complete."""
        ...


class InProcessLoop:
    """A session's loop in this process: :func:`~sashil.runtime.runner.run_plan` of ``stage`` on
    ``rig`` (built, its port open) on ``clock``, its live tuning served on the folder's socket.
    ``realtime``: apply ``loop.rt`` on the real clock."""

    def __init__(self, spec: RunSpec, rig: Any, stage: Any, clock: Clock, *, realtime: bool = True):
        self.spec = spec
        self.rig = rig
        self.stage = stage
        self.clock = clock
        self.realtime = realtime

    def run(self, folder: RunFolder, duration_s: float | None, hooks: LoopHooks) -> RunOutcome:
        tuning, server = open_tuning(self.spec, self.stage, folder, hooks.say) if hooks.tune else (None, None)
        try:
            outcome = run_plan(
                self.spec,
                self.rig,
                self.stage,
                self.clock,
                duration_s,
                data_path=folder.file("data.csv"),
                say=hooks.say,
                realtime=self.realtime,
                live=hooks.live,
                tuning=tuning,
                stop=hooks.stop,
            )
        except BaseException:
            self.rig.close()  # run_plan raises before the loop touches the rig (a disk too full)
            raise
        finally:
            if tuning is not None and server is not None:
                tuning.close()
                server.stop()
        if tuning is not None:
            outcome.tuning, outcome.tuning_rows, outcome.tuning_notes = tuning.summary(), tuning.rows(), tuning.notes()
        return outcome

    def abort(self) -> None:
        self.rig.close()

    def close(self) -> None:
        """Nothing to let go: the run's end closed the rig."""


def run_session(
    loop: SessionLoop,
    config: Mapping[str, Any] | None,
    folder: RunFolder,
    duration_s: float | None,
    *,
    controller: str = "passive",
    verb: str = "run",
    say: Callable[[str], None] = _stderr,
    live: Any = None,
    tune: bool = False,
    finish: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
    stop: StopFlag | None = None,
) -> RunOutcome:
    """Run ``loop`` (in this process or its own) streaming ``data.csv`` into ``folder``, with
    ``config.yaml`` (the resolved ``config`` the loop's spec was assembled from) written first and the timing file and ``summary.json`` last (see module doc).
    ``tune``: serve live changes of the law on the folder's tuning socket while the loop runs
    (:mod:`sashil.runtime.tune_socket`), recorded in ``events.csv`` and ``summary.json``'s
    ``tuning``. ``finish``: the verb's one hook, called with the session's summary once the data
    and timing are on disk; the keys it returns are added before ``summary.json`` is written, once.
    ``stop``: a flag another thread may set to stop the run cleanly (signals are routed to it as
    well when the session runs on the main thread)."""
    documents = Documents([FolderWriter(folder, verb, {}, several=False)])  # its config.yaml and summary.json
    try:
        documents.start(None, config, loop.spec)
    except BaseException:
        loop.abort()
        raise
    try:
        outcome = loop.run(folder, duration_s, LoopHooks(say, live, tune, stop, verb))
        live_stats = live.close(outcome.trips, outcome.tuning_notes) if live is not None else None
        head = {
            "verb": verb,
            **outcome.summary,
            "controller": controller,
            "duration_s": duration_s,
            "live_view": live_stats,
            "tuning": outcome.tuning,
        }
        if outcome.loop_process is not None:
            head["loop_process"] = outcome.loop_process
        if outcome.tuning_rows:  # the live changes
            folder.write_rows(EVENTS_FILE, EVENT_COLUMNS, outcome.tuning_rows)
        folder.write_timing(outcome.timing)
        summary = {**head, "driver": loop.spec.rig.backend}
        if finish is not None:  # the verb's keys, given the summary so far
            summary.update(finish(summary))
        documents.summary(None, summary)
        outcome.summary = summary
    finally:
        loop.close()
    return outcome

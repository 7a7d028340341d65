"""The engine: the one place a verb's plan is run, wherever its loop runs.

A verb assembles its run (:func:`~sashil.engine.assemble.assemble`) and hands the engine the plan;
the engine decides where the loop runs (:func:`~sashil.engine.where.loop_in_process`) and runs it
there: in a loop process of its own, which builds the same plan from its values
(:func:`~sashil.runtime.plan_process.run_plan_process`), or in this process through the one
runner (:func:`~sashil.runtime.runner.run_plan`), the plan given its rig first (``plan.attach_rig``).
Either way the verb gets one :class:`~sashil.runtime.runner.RunOutcome`, its stream read back.
A session's loop (``sashil run``, a script's, the panel's: its folder made once the loop is ready,
its law tuned live) is launched by the same function, under the same rule (``run(..., session=)``).

Given the verb's :class:`~sashil.writer.documents.Documents`, the engine emits the run's ``start``
document before the loop (the resolved config, the assembled run, the versions), its ``progress``
as the loop starts and once it has ended, and its ``stop`` after it: the run's record, which the
experiment's ``analyse`` makes of the outcome (a :class:`~sashil.writer.documents.RunRecord`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.config.parts import RunSpec
from sashil.drivers import RigInterface, open_rig
from sashil.engine.where import loop_in_process
from sashil.runtime.clock import Clock, RealClock, default_clock
from sashil.runtime.plan_process import run_plan_process
from sashil.runtime.runner import RunOutcome, run_plan
from sashil.runtime.session import InProcessLoop, SessionLoop, run_session
from sashil.writer.documents import Documents, RunRecord
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.runtime.loop_process import LoopProcess

__all__ = ["Session", "SessionFolder", "StartedLoop", "run"]

log = logging.getLogger("sashil")


def run(
    spec: RunSpec,
    plan: Any,
    duration_s: float | None = None,
    *,
    clock: Clock | None = None,
    rig: Callable[[], RigInterface] | None = None,
    data_path: str | Path | None = None,
    live: Any = None,
    stop: Any = None,
    trace: Any = None,
    realtime: bool = True,
    say: Callable[[str], None] = log.warning,
    documents: Documents | None = None,
    name: str | None = None,
    config: Mapping[str, Any] | None = None,
    analyse: Callable[[RunOutcome], RunRecord] | None = None,
    session: Session | None = None,
) -> RunOutcome:
    """Run ``plan`` of the assembled ``spec`` for ``duration_s`` (None: until the plan ends) and
    return its outcome, the stream read back (:attr:`RunOutcome.stream`).

    ``session``: the run is a session's (``sashil run``, a script's, the panel's: ``plan`` None, the
    run's own plan ``spec.plan``, built where its loop runs): its loop made ready first, then its
    folder, views and finish hook by ``session.ready``, then the session run into that folder
    (:func:`~sashil.runtime.session.run_session`: ``config.yaml`` from ``config``, ``summary.json``
    once), until ``stop`` or ``duration_s``.

    ``clock``: the run's clock (default: the spec's, :func:`~sashil.runtime.clock.default_clock`).
    ``rig``: makes the rig for a loop in this process (default: the spec's backend). ``data_path``:
    every cycle streamed there as it runs. ``live``: views of the stream; ``stop``: a
    :class:`~sashil.runtime.signals.StopFlag` another thread may set; ``trace``: a
    :class:`~sashil.recording.can_trace.CanTrace` (not started) fed the run's CAN frames, closed
    after the run (its statistics in :attr:`RunOutcome.can_trace`). ``realtime``: apply ``loop.rt``
    to a loop in this process on the real clock. ``say``: the loop's warnings. Bad input found before the loop
    starts raises with nothing energised; what ends the loop does not raise.

    ``documents``: where the run's documents go, as run ``name`` (None: the verb's folder itself):
    ``start`` with ``config`` (the config its folder records; None: none), ``progress`` as the loop
    starts and once it has ended (:func:`running_text`, :func:`ran_text`), ``stop`` with the run's
    record: ``analyse(outcome)``, the experiment's (what ended the run as the experiment judges it,
    its entry, data and format labels beside the loop's summary keys), which is called with or
    without documents; without ``analyse``, the outcome's summary keys and error alone."""
    if session is not None:
        return _run_session(spec, duration_s, session, config, stop)
    clock = clock if clock is not None else default_clock(spec)
    alone = loop_in_process(spec, clock, plan)
    if documents is not None:
        documents.start(name, config, spec)
        documents.progress(name, running_text(spec, duration_s, alone))
    outcome = _run_loop(spec, plan, duration_s, clock, alone, rig, data_path, live, stop, trace, realtime, say)
    record = analyse(outcome) if analyse is not None else RunRecord(summary=outcome.summary, error=outcome.error)
    if documents is not None:
        documents.progress(name, ran_text(spec, outcome.summary))
        documents.stop(str(name), record)
    return outcome


def running_text(spec: RunSpec, duration_s: float | None, alone: bool) -> str:
    """A run's progress as its loop starts: where the loop runs, on which clock, how long and how fast."""
    where = "a loop process" if alone else "this process"
    clock = "simulated time" if spec.virtual else "the real clock"
    length = "until its plan ends" if duration_s is None else f"{duration_s:g} s"
    return f"running: {spec.rig.backend} backend, the loop in {where} on {clock}, {length} at {spec.loop.rate_hz:g} Hz"


def ran_text(spec: RunSpec, summary: Mapping[str, Any]) -> str:
    """A run's progress once its loop has ended: the run time its cycles make and how it ended."""
    cycles = int((summary.get("timing") or {}).get("cycles", 0))
    return f"ran: {cycles} cycles ({cycles / spec.loop.rate_hz:g} s of run time), {summary.get('exit_status', 'ok')}"


def _run_loop(
    spec: RunSpec,
    plan: Any,
    duration_s: float | None,
    clock: Clock,
    alone: bool,
    rig: Callable[[], RigInterface] | None,
    data_path: str | Path | None,
    live: Any,
    stop: Any,
    trace: Any,
    realtime: bool,
    say: Callable[[str], None],
) -> RunOutcome:
    """The loop of ``plan`` where the one rule says it runs (``alone``: in a loop process; see :func:`run`)."""
    if alone:
        return run_plan_process(spec, plan, duration_s, data_path=data_path, say=say, live=live, stop=stop, trace=trace)
    board = rig() if rig is not None else open_rig(spec.rig)
    attach = getattr(plan, "attach_rig", None)
    try:
        if attach is not None:
            attach(board)
    except BaseException:
        board.close()
        raise
    if trace is not None:
        trace.attach(board)
        trace.start()
    try:
        outcome = run_plan(
            spec,
            board,
            plan,
            clock,
            duration_s,
            data_path=data_path,
            say=say,
            note=log.debug,
            realtime=realtime,
            read_stream=True,
            live=live,
            stop=stop,
        )
    finally:
        trace_stats = trace.close() if trace is not None else None
    outcome.can_trace = trace_stats
    return outcome


@dataclass(frozen=True)
class StartedLoop:
    """A session's loop, ready to go (what :attr:`Session.ready` is given): the loop (a
    :class:`~sashil.runtime.session.SessionLoop`), its loop process (None: it runs in this process)
    and its rig (None: the rig is the loop process's), the stage's label, the road's text and the
    stage's columns."""

    loop: SessionLoop
    process: LoopProcess | None
    rig: RigInterface | None
    label: str
    road_text: str
    columns: tuple[str, ...]


@dataclass(frozen=True)
class SessionFolder:
    """What a session's verb readies once its loop is (:attr:`Session.ready`): the run folder, the
    views of the stream (``start(stream, timing)``, ``close(trips, notes)``; None: none), the verb's
    finish hook (:func:`~sashil.runtime.session.run_session`'s ``finish``) and where the loop's
    lines go."""

    folder: RunFolder
    live: Any = None
    finish: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None
    say: Callable[[str], None] = log.warning


@dataclass(frozen=True)
class Session:
    """A session's run (:func:`run` with ``session``): ``ready(started)`` makes the verb's folder and
    views once the loop is ready (a failure there gives the loop up, nothing energised);
    ``tune``: the loop serves live changes of its law; ``can_trace``: a loop process puts every CAN
    frame into the stream; ``say(kind, text)``: the warm-up's progress and warnings."""

    ready: Callable[[StartedLoop], SessionFolder]
    tune: bool = True
    can_trace: bool = False
    say: Callable[[str, str], None] = lambda kind, text: log.warning("%s", text)


def _run_session(
    spec: RunSpec, duration_s: float | None, session: Session, config: Mapping[str, Any] | None, stop: Any
) -> RunOutcome:
    """A session's loop made ready (:func:`_ready_loop`), its folder by the verb, then run into it."""
    started = _ready_loop(spec, duration_s, session)
    try:
        opened = session.ready(started)
    except BaseException:
        started.loop.abort()
        raise
    return run_session(
        started.loop,
        config,
        opened.folder,
        duration_s,
        controller=started.label,
        live=opened.live,
        say=opened.say,
        tune=session.tune,
        finish=opened.finish,
        stop=stop,
    )


def _ready_loop(spec: RunSpec, duration_s: float | None, session: Session) -> StartedLoop:
    """The loop of a session on the real clock, of the assembled run ``spec`` (its ``plan``: the kind
    and values a loop builds its stage from), made ready where the one rule says it runs
    (:func:`~sashil.engine.where.loop_in_process`): in a loop process of its own, or in this one (the
    rig built, its port open, the board greeted). Its stage is built by the same function either
    way (:func:`~sashil.runtime.worker.build`), once, where the loop runs. Bad input (a port that
    cannot be opened) raises before anything is energised."""
    clock = RealClock.for_rate(spec.loop.spin_margin_us, spec.loop.rate_hz)
    if loop_in_process(spec, clock):
        # the session's side of a loop process loads here: a run on simulated time never needs it
        from sashil.runtime.loop_process import LoopProcess

        process = LoopProcess(spec, duration_s, tune=session.tune, can_trace=session.can_trace).start()
        try:
            ready = process.wait_ready(session.say)
        except BaseException:
            process.close()
            raise
        return StartedLoop(process, process, None, ready["label"], ready["road"], tuple(ready["columns"]))
    # the law, the estimator and numba's kernels load here: a session whose loop runs in a loop
    # process never loads them
    from sashil.runtime.loop import record_columns
    from sashil.runtime.worker import build

    rig, stage, label, road_text = build(spec, _Said(session.say))
    return StartedLoop(InProcessLoop(spec, rig, stage, clock), None, rig, label, road_text, record_columns(stage))


class _Said:
    """A loop built in this process tells its progress as a loop process's messages do."""

    def __init__(self, say: Callable[[str, str], None]):
        self.say = say

    def send(self, kind: str, **fields: Any) -> None:
        self.say(kind, str(fields.get("text", "")))

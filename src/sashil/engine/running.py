"""The engine: the one place a verb's plan is run, wherever its loop runs.

A verb assembles its run (:func:`~sashil.engine.assemble.assemble`) and hands the engine the plan;
the engine decides where the loop runs (:func:`~sashil.engine.where.loop_in_process`) and runs it
there: in a loop process of its own, which builds the same plan from its values
(:func:`~sashil.runtime.plan_process.run_plan_process`), or in this process through the one
runner (:func:`~sashil.runtime.runner.run_plan`), the plan given its rig first (``plan.attach_rig``).
Either way the verb gets one :class:`~sashil.runtime.runner.RunOutcome`, its stream read back.

Given the verb's :class:`~sashil.engine.documents.Documents`, the engine emits the run's ``start``
document before the loop (the resolved config, the assembled run, the versions) and its ``stop``
after it: the outcome's summary keys, to which the experiment's ``analyse`` adds its analysis.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from sashil.config.parts import RunSpec
from sashil.drivers import RigInterface, open_rig
from sashil.engine.documents import Documents
from sashil.engine.where import loop_in_process
from sashil.runtime.clock import Clock, default_clock
from sashil.runtime.plan_process import run_plan_process
from sashil.runtime.runner import RunOutcome, run_plan

__all__ = ["run"]

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
    analyse: Callable[[RunOutcome], Mapping[str, Any]] | None = None,
) -> RunOutcome:
    """Run ``plan`` of the assembled ``spec`` for ``duration_s`` (None: until the plan ends) and
    return its outcome, the stream read back (:attr:`RunOutcome.stream`).

    ``clock``: the run's clock (default: the spec's, :func:`~sashil.runtime.clock.default_clock`).
    ``rig``: makes the rig for a loop in this process (default: the spec's backend). ``data_path``:
    every cycle streamed there as it runs. ``live``: views of the stream; ``stop``: a
    :class:`~sashil.runtime.signals.StopFlag` another thread may set; ``trace``: a
    :class:`~sashil.recording.can_trace.CanTrace` (not started) fed the run's CAN frames, closed
    after the run (its statistics in :attr:`RunOutcome.can_trace`). ``realtime``: apply ``loop.rt``
    to a loop in this process on the real clock. ``say``: the loop's warnings. Bad input found before the loop
    starts raises with nothing energised; what ends the loop does not raise.

    ``documents``: where the run's documents go, as run ``name`` (None: the verb's folder itself):
    ``start`` with ``config`` (the config its folder records; None: none), ``stop`` with the
    outcome and ``analyse(outcome)`` (the experiment's analysis: ``error``, what ended the run as
    the experiment judges it, ``entry``, ``data``, ``formats``), which is called with or without
    documents."""
    clock = clock if clock is not None else default_clock(spec)
    if documents is not None:
        documents.start(name, config, spec)
    outcome = _run_loop(spec, plan, duration_s, clock, rig, data_path, live, stop, trace, realtime, say)
    analysis = dict(analyse(outcome)) if analyse is not None else {}
    if documents is not None:
        documents.stop(str(name), outcome.summary, analysis.pop("error", outcome.error), **analysis)
    return outcome


def _run_loop(
    spec: RunSpec,
    plan: Any,
    duration_s: float | None,
    clock: Clock,
    rig: Callable[[], RigInterface] | None,
    data_path: str | Path | None,
    live: Any,
    stop: Any,
    trace: Any,
    realtime: bool,
    say: Callable[[str], None],
) -> RunOutcome:
    """The loop of ``plan`` where the one rule says it runs (see :func:`run`)."""
    if loop_in_process(spec, clock, plan):
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

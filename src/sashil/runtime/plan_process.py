"""A verb's plan run in a loop process of its own: the same :class:`~sashil.runtime.runner.RunOutcome`
as :func:`~sashil.runtime.runner.run_plan` gives in this process.

On the real clock, with ``loop.process`` (the default), a plan that says how to build it
(``plan.spec()``: its ``kind`` and arguments, :func:`sashil.runtime.worker.plan_builder`) runs in a loop
process (:mod:`sashil.runtime.loop_process`): the rig, the safety supervisor and the plan live
there, and nothing else. This process keeps the plan's twin, which takes what the loop process's
plan saw (``plan.absorb(facts)``) after the run, records the stream into the data file, feeds the
views and the CAN trace, passes stop requests on, and reads the stream back for the verb's record.
Which plans run here is decided by the engine (:func:`sashil.engine.run`), from the assembled run.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import DataFileError
from sashil.recording.data_file import read_data_csv
from sashil.runtime.runner import CYCLES_FILE, RunOutcome
from sashil.runtime.signals import StopFlag

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

log = logging.getLogger("sashil")


def run_plan_process(
    spec: RunSpec,
    plan: Any,
    duration_s: float | None,
    *,
    data_path: str | Path | None = None,
    say: Callable[[str], None] = log.warning,
    live: Any = None,
    stop: StopFlag | None = None,
    trace: Any = None,
) -> RunOutcome:
    """Run ``plan`` of the assembled run ``spec`` (the plan's :meth:`spec` built again in the loop process) for ``duration_s`` (None:
    until the plan ends) and return what :func:`~sashil.runtime.runner.run_plan` would, with the
    stream read back from ``data_path`` (a temporary file when None). The plan's prompts to the
    operator reach its ``notify`` as they come; warnings reach ``say``. ``live``: views of the
    stream; ``stop``: a flag another thread may set; ``trace``: a
    :class:`~sashil.recording.can_trace.CanTrace`, not started, fed the loop's CAN frames. Bad
    input found in the loop process before the run (a port that cannot be opened) raises, with
    nothing energised; what ends the run does not raise."""
    # the session's side of a loop process loads here: a run on simulated time never needs it
    from sashil.runtime.loop_process import LoopProcess, drive

    values = plan.spec()
    if values is None:
        raise ValueError(f"{type(plan).__name__}: this plan cannot be built in a loop process (no spec)")
    forward = _forwarder(getattr(plan, "notify", None), say)
    process = LoopProcess(spec.with_plan(values), duration_s, tune=False, can_trace=trace is not None).start()
    try:
        process.wait_ready(forward)
    except BaseException:
        process.close()
        raise
    scratch = tempfile.TemporaryDirectory(prefix="sashil-stream-") if data_path is None else None
    path = Path(scratch.name) / CYCLES_FILE if scratch is not None else Path(data_path)  # type: ignore[arg-type]
    trace_stats = None
    try:
        if trace is not None:
            trace.follow(process.can_frames).start()
        try:
            ended = drive(process, path, duration_s, say=forward, live=live, stop=stop, verb=str(values["kind"]))
        finally:
            if trace is not None:
                trace_stats = trace.close()
                trace_stats["frames_dropped"] += process.frames_dropped()
        timing = ended.timing.copy()  # the stream's shared rings end with the process
    finally:
        pid = process.process.pid if process.process is not None else None
        startup_s = process.startup_s
        process.close()
    end = ended.end
    if end.get("plan") is not None and hasattr(plan, "absorb"):
        plan.absorb(end["plan"])
    try:
        stream = read_data_csv(path, required=(), min_rows=0)
    except DataFileError:  # a stream the disk lost: what ended the run says why
        stream = {}
    if scratch is not None:
        scratch.cleanup()
    return ended.outcome(
        timing,
        recording=ended.recording if data_path is not None else None,  # a temporary stream file is no recording
        realtime=ended.end.get("realtime", {}),
        facts=ended.facts(pid, startup_s),
        stream=stream,
        can_trace=trace_stats,
    )


def _forwarder(notify: Callable[[str], None] | None, say: Callable[[str], None]) -> Callable[[str, str], None]:
    """Where the loop process's messages go: the operator's prompts to the plan's ``notify``, the
    real-time set-up's report to the debug log, the rest to ``say``."""

    def forward(kind: str, text: str) -> None:
        if kind == "prompt" and notify is not None:
            notify(text)
        elif kind == "progress" and text.startswith("realtime:"):
            log.debug("%s", text)
        else:
            say(text)

    return forward

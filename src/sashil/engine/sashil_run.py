"""``sashil run`` as a library function: the rig in closed loop on the real clock, at a fixed
rate, under a law and a road, into a run folder (data.csv, timing, run.png, summary.json)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from sashil import engine
from sashil.api import Run, load_run
from sashil.engine import assemble
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import ConfigError, SashilError
from sashil.plans import run as run_plan
from sashil.recording.formats import can_formats
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_run, plot_timing
from sashil.recording.rest import rest_phrase
from sashil.recording.run_progress import RunProgress, SessionHooks
from sashil.roads.option import RoadParts
from sashil.runtime.signals import StopFlag
from sashil.runtime.timing import format_timing
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig
    from sashil.runtime.loop_process import LoopProcess

__all__ = ["PLAN", "READS", "closed_loop"]

#: ``sashil run``'s own values (``{name: config key}``), read once by the engine into its run's
#: ``options``: how long, the road and what it is made with, the port a CAN trace names
READS = {"duration_s": "run.duration_s", "road": "run.road", "port": "driver.port", **RoadParts.READS}
#: ``sashil run``'s plan (:mod:`sashil.plans.run`): its values are the run's ``options`` (the road,
#: what it is made with, how long the run commands it), which a loop process receives with the run
PLAN = {"kind": run_plan.KIND}


def closed_loop(
    config: RunConfig,
    outputs: Outputs | None = None,
    on_event: Listener = ignore,
    *,
    progress: bool = False,
    tune: bool = True,
    views: Sequence[Any] = (),
    stop: StopFlag | None = None,
) -> Run:
    """Run the rig of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``run``) in closed loop for ``run.duration_s`` (None: until stopped by a signal) and return its
    folder as a :class:`~sashil.api.Run`.

    ``progress``: a progress bar on the terminal. ``tune``: serve live changes of the law on the
    folder's socket (``sashil tune``). ``views``: more readers of the run's stream, each with
    ``start(stream, timing)`` and ``close(trips, notes)`` (the live view's shape): ``stream.columns``,
    ``stream.rows_committed`` and ``stream.copy_rows(start, stop, step)`` give the rows, and
    ``timing.cycles`` and ``timing.missed_deadlines`` the loop's counts. ``stop``: a flag another
    thread may set (:meth:`~sashil.runtime.signals.StopFlag.request`) to stop the run cleanly. Bad input (a port that cannot be opened) raises ConfigError
    with no folder left; an error during the run ends at 0 A and is raised after the folder is complete."""

    outputs = outputs if outputs is not None else Outputs()
    spec = assemble(config, PLAN, READS)
    outputs.check(spec.rig.backend)
    opener = _Opener(outputs, on_event, progress, views)
    session = engine.Session(
        opener,
        tune=tune,
        can_trace=bool(can_formats(tuple(outputs.formats))),
        say=lambda kind, text: on_event(Event("warning" if kind == "warning" else "progress", text)),
    )
    try:
        outcome = engine.run(spec, None, spec.options["duration_s"], config=config, stop=stop, session=session)
    finally:
        opener.close_trace()
    return _ended(outcome, opener.opened.folder, on_event)


class _Opener:
    """What ``sashil run`` readies once its loop is (the run it was assembled for: ``started.loop.spec``):
    the run folder, the live view (and a progress bar, and the caller's views), the CAN trace, the
    run's first line, the finish hook."""

    def __init__(self, outputs: Outputs, on_event: Listener, progress: bool, views: Sequence[Any]):
        self.outputs, self.on_event, self.progress, self.views = outputs, on_event, progress, views
        self.finish: _Finish | None = None
        self.opened: engine.SessionFolder

    def __call__(self, started: engine.StartedLoop) -> engine.SessionFolder:
        spec, outputs, on_event = started.loop.spec, self.outputs, self.on_event
        duration, rate, process = spec.options["duration_s"], spec.loop.rate_hz, started.process
        folder = RunFolder.create(outputs.out, "run")
        live = outputs.open_live_tap(
            spec.stage.model, spec.stage.current_max_a, started.columns, "sashil run", folder.path
        )
        if self.progress:  # a bar on a terminal, a line every 10 s otherwise
            live = SessionHooks(live, RunProgress(duration, rate))
        if self.views:
            live = SessionHooks(live, *self.views)
        on_event(
            Event(
                "progress",
                f"sashil run: {spec.rig.backend} backend, {started.label}, road {started.road_text}, {rate:g} Hz, "
                f"{'until stopped' if duration is None else f'{duration:g} s'} -> {folder.path}",
                {"folder": str(folder.path)},  # known before the loop starts: its tuning socket is there
            )
        )
        if process is None:
            trace = outputs.start_can_trace(started.rig, folder.path)
        else:
            trace = outputs.follow_can_trace(folder.path, spec.options["port"], process.can_frames)
        self.finish = _Finish(outputs, folder, started.road_text, trace, process)

        def say(line: str) -> None:
            on_event(Event("progress" if line.startswith(("realtime:", "live tuning:")) else "warning", line))

        self.opened = engine.SessionFolder(folder, live, self.finish, say)
        return self.opened

    def close_trace(self) -> None:
        """The CAN trace closed, when the run's finish did not close it."""
        finish = self.finish
        if finish is not None and finish.trace is not None and finish.trace_stats is None:
            finish.trace.close()


class _Finish:
    """What a run writes of its own before the one summary.json: the CAN trace's figures, its
    --format files and plots; the run's own summary keys."""

    def __init__(self, outputs: Outputs, folder: RunFolder, road_text: str, trace: Any, process: LoopProcess | None):
        self.outputs, self.folder, self.road_text, self.trace, self.process = outputs, folder, road_text, trace, process
        self.trace_stats: dict[str, Any] | None = None  # the trace's figures, once the finish closed it

    def __call__(self, summary: dict[str, Any]) -> dict[str, Any]:
        folder = self.folder
        trace_stats = self.trace_stats = self.trace.close() if self.trace is not None else None
        if trace_stats is not None and self.process is not None:
            trace_stats["frames_dropped"] += self.process.frames_dropped()
        extra: dict[str, Any] = {"road": self.road_text}
        if trace_stats is not None:
            extra["can_trace"] = trace_stats
        if (folder.path / "data.csv").exists():
            self.outputs.write_formats(
                folder.path,
                "run",
                exit_status=summary.get("exit_status", "ok"),
                controller=summary.get("controller"),
            )
            plot_run(folder.path / "run.png", folder.path, {**summary, **extra})
        timing = load_run(folder.path).timing
        if timing is not None and len(timing.get("lateness_ns", ())):
            plot_timing(folder.path / "timing.png", [(str(summary.get("controller") or "run"), timing)])
        return extra


def _ended(outcome: Any, folder: RunFolder, on_event: Listener) -> Run:
    """The run's folder, its figures and trips told as events; bad input (nothing ran) leaves no
    folder, and an error during the run is raised after the folder is complete."""
    if isinstance(outcome.error, SashilError) and outcome.error.exit_code == ConfigError.exit_code:
        folder.discard()
        raise outcome.error  # bad input (a port that cannot be opened): nothing ran, no folder
    summary = outcome.summary
    on_event(Event("result", format_timing(summary["timing"]), {"timing": summary["timing"]}))
    for trip in summary["trips"]:
        on_event(Event("warning", f"safety trip at {trip['time_s']:.3f} s: {trip['reason']}", trip))
    on_event(Event("folder", f"run folder: {folder.path}", {"folder": str(folder.path)}))
    if outcome.exit_status == "stopped":
        on_event(Event("warning", f"sashil run: stopped by {outcome.stop_reason}; {rest_phrase(summary)}"))
    error = outcome.error
    if error is not None and not isinstance(error, KeyboardInterrupt):
        if isinstance(error, SashilError):
            raise error
        raise SashilError(f"{type(error).__name__}: {error} (the damper was set to 0 A first)") from error
    return load_run(folder.path)

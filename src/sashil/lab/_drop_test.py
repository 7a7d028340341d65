"""The drop test of seed 001 section 8, as a library function: hold the arm at θ0 (−5°), release,
record the free oscillation at each constant current, one sub-run per current.

Each drop is a plan in the loop (:class:`~sashil.plans.drop.DropTestPlan`: constant current,
hold, release, run on), built where the loop runs; this module makes the plans, runs them through
the engine and derives each drop's record from the runner's stream (:func:`drop_record`: the
release dated by the backend, or from the departure samples by :func:`estimate_release_ns`) and its
metrics. The record is the drop's stop document (a :class:`~sashil.writer.documents.RunRecord`):
the folder's writer reads its row, its data and its format labels from it.

Release time. When the backend plays the operator it knows the instant it lets go. Otherwise the
release is estimated from the departure (:func:`estimate_release_ns`): just after release the arm
leaves the hold angle with constant acceleration, ``|theta - theta_hold| = a/2 * (t - t_r)^2``, so
``sqrt|dtheta|`` is linear in t and its zero is t_r (a least-squares line through the departure
samples between two encoder counts and the release threshold).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil import engine
from sashil.api import Run, load_run
from sashil.config.overrides import set_values
from sashil.config.parts import RunSpec
from sashil.control.law_registry import law_label
from sashil.control.registry import stage_signals
from sashil.drivers.interface import RigInterface
from sashil.engine import assemble, assembled
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import SashilError
from sashil.lab.compare_metrics import sample_times
from sashil.lab.metrics import DropMetrics, damping_text, drop_metrics, settling_text
from sashil.plans.drop import (
    CONFIG_LAW,
    DROP_COLUMNS,
    DropTestPlan,
    plan_drop,
)
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_drop_test
from sashil.recording.run_progress import SessionHooks
from sashil.runtime.clock import Clock
from sashil.runtime.runner import CYCLES_FILE, RunOutcome
from sashil.runtime.signals import StopFlag
from sashil.writer.documents import Documents, RunRecord
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["READS", "DropRecord", "drop_test", "result_line", "run_drop_test"]

#: the drop test's own values (``{name: config key}``), read once by the engine into its run's
#: ``options`` (:func:`sashil.engine.assemble`)
READS = {
    "theta0_deg": "drop_test.theta0_deg",
    "currents_a": "drop_test.currents_a",
    "duration_s": "drop_test.duration_s",
    "settle_band_deg": "drop_test.settle_band_deg",
    "hold_tolerance_deg": "drop_test.hold_tolerance_deg",
    "hold_time_s": "drop_test.hold_time_s",
    "release_threshold_deg": "drop_test.release_threshold_deg",
    "hold_timeout_s": "drop_test.hold_timeout_s",
    "port": "driver.port",
}


def _label(current: float) -> str:
    return f"i{current:.3f}A"


def result_line(metrics: DropMetrics, duration_s: float) -> str:
    """One drop's period, first peaks, damping ratio and settling, as reported after it."""
    period = "-" if metrics.period_s is None else f"{metrics.period_s:.3f} s"
    peaks = ", ".join(f"{p:.2f}" for p in metrics.peaks_deg[:4])
    return f"period {period}, peaks [{peaks}] deg, {damping_text(metrics)}, {settling_text(metrics, duration_s)}"


def result_warnings(metrics: DropMetrics) -> list[str]:
    """What the operator should know about a drop's figures: no peaks, or a damping ratio the record cut short."""
    if metrics.peaks_note is not None:
        return [f"no peaks: {metrics.peaks_note}"]
    if metrics.damping_note is not None and (metrics.damping_ratio is None or metrics.damping_record_short):
        return [metrics.damping_note]
    return []


def drop_test(
    config: RunConfig,
    outputs: Outputs | None = None,
    on_event: Listener = ignore,
    *,
    views: Sequence[Any] = (),
    stop: StopFlag | None = None,
) -> Run:
    """Run the drop tests of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``drop-test``: ``drop_test.theta0_deg``, ``currents_a``, ``duration_s``) into a new run folder.

    Each current is a sub-run (``i0.000A/``, ...) when there are several. The law in
    ``controller.law`` takes over at the release (``passive``: the constant current throughout).
    On the real clock each drop runs in a loop process of its own (``loop.process``). ``views``:
    readers of each drop's stream, as :func:`sashil.engine.sashil_run.closed_loop` takes them (each gets
    ``start(stream, timing)`` and ``close(trips, notes)`` once per drop, with that drop's stream).
    ``stop``: a flag another thread may set to end the current drop at 0 A and the test.
    Returns the folder as a :class:`~sashil.api.Run`. Bad input raises ConfigError before any folder
    exists; a run that fails after it started raises the error that ended it, after the folder is
    complete (its data up to the failure, its plot and summary)."""
    outputs = outputs if outputs is not None else Outputs()
    run = assemble(config, reads=READS)
    drop = run.options
    theta0_deg, duration = float(drop["theta0_deg"]), float(drop["duration_s"])
    currents = [float(value) for value in drop["currents_a"]]
    # each drop of several records the config that reruns it alone: the resolved one at its current
    own = {c: set_values(config, [(["drop_test", "currents_a"], [c])], "--current")[0] for c in currents}
    outputs.check(run.rig.backend)
    # the law and its parameters were checked in the resolution; its controller is built where each drop's loop runs
    signals = stage_signals(run.stage)
    closed = bool(signals)
    folder = RunFolder.create(outputs.out, "drop-test")
    law, origin = law_label(run.stage.law)
    live = outputs.open_rerun(DROP_COLUMNS + signals, "sashil drop-test", folder.path)
    live_offset_s = 0.0
    several = len(currents) > 1
    writer = _writer(run, folder, law if closed else f"{law} (constant current per run)", origin, several, outputs)
    documents = Documents([writer])
    documents.start(None, config, run)
    overlay = []
    prompt = lambda line: on_event(Event("prompt", line))  # noqa: E731
    for current in currents:
        label = f"{law} (from {current:g} A until the release)" if closed else f"{law} {current:g} A"
        on_event(Event("progress", f"drop test from {theta0_deg:g} deg, {label} ...", {"current_a": current}))
        target = writer.folder_for(_label(current))
        record = run_drop(
            run,
            plan_drop(run, theta0_deg, current, duration, prompt, CONFIG_LAW if closed else None),
            data_path=target.file(CYCLES_FILE),  # every cycle streamed as it runs (the hold too)
            live=SessionHooks(*views) if views else None,
            stop=stop,
            trace=outputs.can_trace(target.path, drop["port"]),
            documents=documents,
            name=_label(current),
            recorded_config=own[current] if several else None,
            describe=functools.partial(_described, current, label, theta0_deg),
        )
        assert record.metrics is not None and record.summary  # run_drop sets both
        if live is not None:
            live.note(
                live_offset_s,
                f"drop test from {theta0_deg:g} deg at {current:g} A (release at t = {live_offset_s:g} s)",
            )
            live.log_columns(record.data, live_offset_s)
            live_offset_s += duration + 1.0
        entry = writer.entries[-1]
        if writer.failed:
            overlay.append({**entry, **record.data, "label": f"{label} (stopped)"})
            break
        overlay.append({**entry, **record.data, "label": label})
        on_event(Event("result", result_line(record.metrics, duration), {"current_a": current}))
        for note in result_warnings(record.metrics):
            on_event(Event("warning", f"drop test at {current:g} A: {note}", {"current_a": current}))
    under = f", under {law}" if closed else ""
    title = f"Drop test from {theta0_deg:g}°{under} ({run.rig.backend} rig)"
    return _finish(folder, writer, documents, overlay, title, drop["settle_band_deg"], live, on_event)


def _finish(
    folder: RunFolder,
    writer: FolderWriter,
    documents: Documents,
    overlay: list[dict[str, Any]],
    title: str,
    band_deg: float,
    live: Any,
    on_event: Listener,
) -> Run:
    """The drop test's plot and summary; the folder discarded when bad input stopped the first drop
    before it began, and the error that ended a drop raised after the folder is complete."""
    plot = plot_drop_test(folder.file("drop_test.png"), overlay, title, band_deg=band_deg)
    if live is not None:
        live.close()
    if writer.error is not None and getattr(writer.error, "exit_code", 1) == 2:
        # bad input found on opening the rig (a port that cannot be opened) or before the drop began
        # (an emulated rig whose operator holds nothing): the drop never started, no folder
        folder.discard()
        raise writer.error
    documents.end()
    on_event(Event("folder", f"run folder: {folder.path} (plot {plot.name})", {"folder": str(folder.path)}))
    if writer.error is not None:
        raise writer.error  # the data up to it is on disk
    return load_run(Path(folder.path))


def _writer(
    run: RunSpec, folder: RunFolder, controller: str, origin: str, several: bool, outputs: Outputs
) -> FolderWriter:
    """The writer of the drop test's folder, with the keys its summaries share."""
    common = {
        "driver": run.rig.backend,
        "controller": controller,
        "controller_origin": origin,
        "clock": "virtual" if run.virtual else "real",  # timing is simulated on the virtual clock
    }
    return FolderWriter(folder, "drop-test", common, several=several, outputs=outputs)


def _described(current: float, label: str, theta0_deg: float, record: DropRecord) -> None:
    """One drop's record as its stop document tells it: its row of the summary and what its
    --format files are labelled with."""
    record.entry = _drop_row(record, current, label, theta0_deg)
    record.formats = {"current_a": current, "controller": label}


def _drop_row(record: DropRecord, current: float, label: str, theta0_deg: float) -> dict[str, Any]:
    """One drop's row of the folder's summary: what ran, its figures, its timing and facts."""
    assert record.metrics is not None  # every record run_drop makes has its metrics
    return {
        "current_a": current,
        "controller": label,
        "theta0_deg": theta0_deg,
        "hold_angle_deg": math.degrees(record.hold_angle_rad),
        "release_estimated": record.release_estimated,
        **record.metrics.as_dict(),
        "timing": record.summary["timing"],
        "trips": record.summary["trips"],
        "safe_state": record.summary.get("safe_state"),
        "link": record.extra.get("link"),
        "realtime": record.extra.get("realtime"),
        "can_trace": record.extra.get("can_trace"),
        "loop_process": record.extra.get("loop_process"),
    }


@dataclass(kw_only=True)
class DropRecord(RunRecord):
    """The recorded free oscillation, time zero at the release: the drop's record, and so its stop
    document (``data``: the columns from the release on; ``summary``: the loop run's summary.json
    keys, :func:`~sashil.runtime.runner.loop_summary`: how it ended, its timing, trips and safe
    state; ``error``: what ended the test early, the data up to it kept)."""

    data: dict[str, np.ndarray]
    release_time_ns: int
    release_estimated: bool
    hold_angle_rad: float
    error: SashilError | None = None
    metrics: DropMetrics | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: every stream column of the record's rows (time zero at the release)
    stream: dict[str, np.ndarray] = field(default_factory=dict)
    #: the device's clock at the release [s] (between the samples around it)
    device_release_s: float | None = None


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


#: how far before its detection the release is looked for in the stream (the departure samples)
RELEASE_WINDOW_S = 1.0


def drop_record(stream: dict[str, np.ndarray], plan: DropTestPlan, loop_start_ns: int) -> DropRecord:
    """The record from the release on, derived from the runner's stream of every cycle.

    The release is the backend's known instant, else the zero of the departure (see the module
    docstring) in the stream's rows of the last :data:`RELEASE_WINDOW_S` before the detection.
    Columns: :data:`DROP_COLUMNS` (+ the plan's ``signal_names`` under a controller) and ``seq``,
    time zero at the release; rows up to ``duration_s`` after it (the shutdown's 0 A row included
    when the run ended earlier). ``stream`` keeps every stream column of those rows (device time,
    road speed commanded) for a caller that needs them."""
    names = DROP_COLUMNS + tuple(plan.signal_names) + ("seq",)
    empty = {name: np.zeros(0, dtype=np.int64 if name == "seq" else float) for name in names}
    if plan.detected_ns is None or not stream or stream["time_s"].size == 0:
        return DropRecord(data=empty, release_time_ns=0, release_estimated=False, hold_angle_rad=plan.hold_angle)
    t_ns = loop_start_ns + np.round(stream["time_s"] * 1e9).astype(np.int64)
    release_ns = plan.known_release_ns
    estimated = release_ns is None
    if release_ns is None:
        window = (t_ns >= plan.detected_ns - round(RELEASE_WINDOW_S * 1e9)) & (t_ns < plan.detected_ns)
        release_ns = (
            estimate_release_ns(
                t_ns[window].tolist(), stream["theta_rad"][window].tolist(), plan.hold_angle, plan.resolution
            )
            if window.any()
            else plan.detected_ns
        )
    rows = (t_ns >= release_ns) & (t_ns - release_ns <= round(plan.duration_s * 1e9))
    columns = {name: stream[name][rows] for name in names}
    columns["time_s"] = (t_ns[rows] - release_ns) * 1e-9
    columns["seq"] = columns["seq"].astype(np.int64)
    record = DropRecord(
        data=columns, release_time_ns=release_ns, release_estimated=estimated, hold_angle_rad=plan.hold_angle
    )
    record.stream = {name: values[rows] for name, values in stream.items()}
    record.stream["time_s"] = columns["time_s"]
    if "device_time_us" in stream:  # the device's clock at the release (between two samples)
        record.device_release_s = float(np.interp(release_ns, t_ns, stream["device_time_us"] * 1e-6))
    return record


def run_drop_test(
    config: RunConfig | RunSpec,
    theta0_deg: float = -5.0,
    current_a: float = 0.0,
    duration_s: float = 10.0,
    rig: RigInterface | None = None,
    clock: Clock | None = None,
    controller: Any = None,
    notify: Callable[[str], None] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    trace: Any = None,
    documents: Documents | None = None,
    name: str | None = None,
    recorded_config: Mapping[str, Any] | None = None,
    describe: Callable[[DropRecord], None] | None = None,
) -> DropRecord:
    """One drop test of a resolved ``config`` or of the drop test's assembled run (its ``options``:
    :data:`READS`) at a constant current (or, after the release, under ``controller``: a stage, or :data:`CONFIG_LAW`
    for the config's law).

    On the real clock with ``loop.process`` (the default) the drop runs in a loop process of its
    own (:mod:`sashil.runtime.loop_process`), which opens the rig, plays or waits for the operator
    and runs the plan; its prompts reach ``notify`` as they come. A controller crosses to it as the
    config's law or as its own ``spec()`` (a calibration step's stage); any other runs its drop in
    this process. ``rig``: the rig for a run in
    this process (default: the config's). ``data_path``: where every cycle of the loop is streamed
    as it runs (the hold included, time from the loop's start); the record returned is the part
    from the release. ``live``: views of the stream (``start(stream, timing)``, ``close(trips,
    notes)``); ``stop``: a :class:`~sashil.runtime.signals.StopFlag` another thread may set;
    ``trace``: a :class:`~sashil.recording.can_trace.CanTrace` (not started) fed the run's CAN
    frames, closed after the run (its statistics in ``record.extra["can_trace"]``). ``documents``:
    the verb's documents, this drop as run ``name`` recording ``recorded_config`` (None: none of its own),
    its stop document the record, with the row and format labels ``describe(record)`` gives it.

    Returns the record from the release on. An error that ends the test early (a driver error, a
    safety trip, no hold) does not raise: the rig is already safe, and the record carries the data
    up to it and the error in ``record.error``.
    """
    run = assembled(config, READS)
    plan = plan_drop(run, theta0_deg, current_a, duration_s, notify, controller)
    return run_drop(
        run,
        plan,
        rig=rig,
        clock=clock,
        data_path=data_path,
        live=live,
        stop=stop,
        trace=trace,
        documents=documents,
        name=name,
        recorded_config=recorded_config,
        describe=describe,
    )


def run_drop(
    run: RunSpec,
    plan: DropTestPlan,
    *,
    rig: RigInterface | None = None,
    clock: Clock | None = None,
    data_path: str | Path | None = None,
    live: Any = None,
    stop: Any = None,
    trace: Any = None,
    documents: Documents | None = None,
    name: str | None = None,
    recorded_config: Mapping[str, Any] | None = None,
    describe: Callable[[DropRecord], None] | None = None,
) -> DropRecord:
    """The drop ``plan`` of the drop test's assembled ``run`` through the engine, and its record
    (the arguments as :func:`run_drop_test` takes them)."""
    records: list[DropRecord] = []

    def analyse(outcome: RunOutcome) -> DropRecord:
        if live is not None:
            live.close(outcome.trips, ())
        # whatever ended the test early, the rig is at 0 A, deactivated and closed
        error = outcome.error if outcome.error is not None else outcome.stop_error()
        if error is not None and not isinstance(error, SashilError):
            raise error
        record = _record(run, outcome, plan, error)
        if describe is not None:
            describe(record)
        records.append(record)
        return record

    engine.run(
        run,
        plan,
        clock=clock,
        rig=(lambda: rig) if rig is not None else None,
        data_path=data_path,
        live=live,
        stop=stop,
        trace=trace,
        documents=documents,
        name=name,
        config=recorded_config,
        analyse=analyse,
    )
    return records[0]


def _record(run: RunSpec, outcome: RunOutcome, plan: DropTestPlan, error: SashilError | None) -> DropRecord:
    """The drop's record from the release on, from the run's stream: its columns, the run's summary
    keys and facts, its metrics."""
    record = drop_record(outcome.stream, plan, outcome.start_ns)
    record.summary = outcome.summary
    record.error = error
    if outcome.can_trace is not None:
        record.extra["can_trace"] = outcome.can_trace
    if outcome.loop_process is not None:
        record.extra["loop_process"] = outcome.loop_process
    if outcome.link is not None:
        record.extra["link"] = outcome.link
    if outcome.realtime:
        record.extra["realtime"] = outcome.realtime
    if outcome.recording is not None:
        record.extra["recording"] = outcome.recording
    time_s, theta = sampled_angle(record)
    record.metrics = drop_metrics(
        time_s, theta, settle_band_deg=run.options["settle_band_deg"], resolution_rad=plan.resolution
    )
    return record


def sampled_angle(record: DropRecord) -> tuple[np.ndarray, np.ndarray]:
    """The drop's angle against the clock that sampled it, time zero at the release: the device's
    (each distinct sample once, at its own device time) when the rig's samples carry one, else the
    loop's. Over a link the loop reads a sample a round trip after the device took it, and on a
    busy host a late cycle later still: peaks and the period on the loop's clock would carry that
    lateness, which is the host's, not the arm's. A device clock that only restates the loop's (a
    simulated rig's: the loop's time in whole µs, :data:`SAME_CLOCK_S`) gives way to the loop's,
    which is finer."""
    loop_time, theta = record.data["time_s"], record.data["theta_rad"]
    sampled = sample_times(record.stream) if record.device_release_s is not None else None
    if sampled is None:
        return loop_time, theta
    times, rows = sampled
    device_time = times - record.device_release_s
    if rows.size == loop_time.size and np.all(np.abs(device_time - loop_time) <= SAME_CLOCK_S):
        return loop_time, theta
    return device_time, theta[rows]


#: the largest difference between a device's sample times and the loop's at which the device's clock
#: is the loop's restated (whole µs, and the release's instant read between two samples) [s]
SAME_CLOCK_S = 2e-6

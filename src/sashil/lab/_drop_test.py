"""The drop test as a library function: hold the arm at θ0, release, record the free oscillation
at each constant current (seed 001 section 8), one sub-run per current."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.api import Run, load_run
from sashil.config.frozen import thaw
from sashil.config.parts import StageParts
from sashil.control.law_registry import law_label
from sashil.engine import assemble
from sashil.experiments.drop_test import CONFIG_LAW, DROP_COLUMNS, controller_columns, run_drop_test, stage_controller
from sashil.experiments.metrics import DropMetrics, damping_text, settling_text
from sashil.lab.events import Event, Listener, ignore
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_drop_test
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_progress import SessionHooks
from sashil.recording.run_set import RunSet, ending
from sashil.runtime.runner import CYCLES_FILE
from sashil.runtime.signals import StopFlag

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["drop_test", "result_line"]


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
    """Run the drop tests of a resolved ``config`` (:func:`sashil.config.resolve.resolve` with verb
    ``drop-test``: ``drop_test.theta0_deg``, ``currents_a``, ``duration_s``) into a new run folder.

    Each current is a sub-run (``i0.000A/``, ...) when there are several. The law in
    ``controller.law`` takes over at the release (``passive``: the constant current throughout).
    On the real clock each drop runs in a loop process of its own (``loop.process``). ``views``:
    readers of each drop's stream, as :func:`sashil.lab.closed_loop` takes them (each gets
    ``start(stream, timing)`` and ``close(trips, notes)`` once per drop, with that drop's stream).
    ``stop``: a flag another thread may set to end the current drop at 0 A and the test.
    Returns the folder as a :class:`~sashil.api.Run`. Bad input raises ConfigError before any folder
    exists; a run that fails after it started raises the error that ended it, after the folder is
    complete (its data up to the failure, its plot and summary)."""
    outputs = outputs if outputs is not None else Outputs()
    section = config["drop_test"]
    theta0_deg, duration = float(section["theta0_deg"]), float(section["duration_s"])
    currents = [float(value) for value in section["currents_a"]]
    outputs.check(config["driver"]["name"])
    checked = stage_controller(StageParts.read(config))  # bad controller parameters fail here, before a folder exists
    closed = checked is not None
    folder = RunFolder.create(outputs.out, "drop-test")
    law, origin = law_label(config["controller"]["law"])
    columns = DROP_COLUMNS + controller_columns(checked)
    live = outputs.open_rerun(columns, "sashil drop-test", folder.path)
    live_offset_s = 0.0
    folder.write_config(config)
    runs = _run_set(config, folder, law if closed else f"{law} (constant current per run)", origin, len(currents) > 1)
    overlay = []
    prompt = lambda line: on_event(Event("prompt", line))  # noqa: E731
    for current in currents:
        label = f"{law} (from {current:g} A until the release)" if closed else f"{law} {current:g} A"
        on_event(Event("progress", f"drop test from {theta0_deg:g} deg, {label} ...", {"current_a": current}))
        target = runs.folder_for(_label(current))
        record = run_drop_test(
            config,
            theta0_deg,
            current,
            duration,
            controller=CONFIG_LAW if closed else None,
            notify=prompt,
            data_path=target.file(CYCLES_FILE),  # every cycle streamed as it runs (the hold too)
            live=SessionHooks(*views) if views else None,
            stop=stop,
            trace=outputs.can_trace(target.path, config["driver"]["port"]),
        )
        _write_drop(config, outputs, target, record, current, label, sub_config=runs.several)
        assert record.metrics is not None and record.run  # run_drop_test sets both
        if live is not None:
            live.note(
                live_offset_s,
                f"drop test from {theta0_deg:g} deg at {current:g} A (release at t = {live_offset_s:g} s)",
            )
            live.log_columns(record.columns, live_offset_s)
            live_offset_s += duration + 1.0
        entry = runs.add(_label(current), _drop_row(record, current, label, theta0_deg), record.error)
        if runs.failed:
            overlay.append({**entry, **record.columns, "label": f"{label} (stopped)"})
            break
        overlay.append({**entry, **record.columns, "label": label})
        on_event(Event("result", result_line(record.metrics, duration), {"current_a": current}))
        for note in result_warnings(record.metrics):
            on_event(Event("warning", f"drop test at {current:g} A: {note}", {"current_a": current}))
    under = f", under {law}" if closed else ""
    title = f"Drop test from {theta0_deg:g}°{under} ({config['driver']['name']} rig)"
    return _finish(folder, runs, overlay, title, section["settle_band_deg"], live, on_event)


def _finish(
    folder: RunFolder,
    runs: RunSet,
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
    if runs.error is not None and getattr(runs.error, "exit_code", 1) == 2:
        # bad input found on opening the rig (a port that cannot be opened) or before the drop began
        # (an emulated rig whose operator holds nothing): the drop never started, no folder
        folder.discard()
        raise runs.error
    runs.finish()
    on_event(Event("folder", f"run folder: {folder.path} (plot {plot.name})", {"folder": str(folder.path)}))
    if runs.error is not None:
        raise runs.error  # the data up to it is on disk
    return load_run(Path(folder.path))


def _run_set(config: RunConfig, folder: RunFolder, controller: str, origin: str, several: bool) -> RunSet:
    """The drop test's set of runs, one per current, with the keys its folder's summary shares."""
    return RunSet(
        folder,
        "drop-test",
        {
            "driver": config["driver"]["name"],
            "controller": controller,
            "controller_origin": origin,
            "clock": "virtual" if assemble(config).virtual else "real",  # timing is simulated on the virtual clock
        },
        several=several,
    )


def _write_drop(
    config: RunConfig,
    outputs: Outputs,
    target: RunFolder,
    record: Any,
    current: float,
    label: str,
    sub_config: bool,
) -> None:
    """One drop's files in ``target``: its config when it is a sub-run, its data and the --format files."""
    if sub_config:  # the sub-folder's config reruns its one drop
        own = thaw(config)
        own["drop_test"]["currents_a"] = [current]
        target.write_config(own)
    target.write_data(record.columns)
    outputs.write_formats(
        target.path,
        "drop-test",
        record.columns,
        exit_status=ending(record.error)["exit_status"],
        current_a=current,
        controller=label,
    )


def _drop_row(record: Any, current: float, label: str, theta0_deg: float) -> dict[str, Any]:
    """One drop's row of the folder's summary: what ran, its figures, its timing and facts."""
    return {
        "current_a": current,
        "controller": label,
        "theta0_deg": theta0_deg,
        "hold_angle_deg": math.degrees(record.hold_angle_rad),
        "release_estimated": record.release_estimated,
        **record.metrics.as_dict(),
        "timing": record.run["timing"],
        "trips": record.run["trips"],
        "safe_state": record.run.get("safe_state"),
        "link": record.extra.get("link"),
        "realtime": record.extra.get("realtime"),
        "can_trace": record.extra.get("can_trace"),
        "loop_process": record.extra.get("loop_process"),
    }

"""``sashil sweep`` as a library function: road-side excitation through the resonance, a chirp or
a stepped sine with its transmissibility per frequency, into a run folder.

The excitation and its measurement are :mod:`sashil.experiments.sweep`; this module runs them on the
config's rig, writes the folder (``data.csv`` and ``chirp.png`` of a chirp; a sub-folder per
frequency, ``transmissibility.csv`` and ``transmissibility.png`` of a stepped sine) and reports
through events.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.api import Run, load_run
from sashil.config.parts import StageParts
from sashil.control.registry import law_run_label, make_controller
from sashil.errors import ConfigError, SashilError
from sashil.experiments.sweep import (
    SWEEP_COLUMNS,
    ac_rms,
    chirp_profile,
    default_rig,
    frequencies,
    run_sweep,
    stepped_sine,
)
from sashil.identify.progress import Progress
from sashil.lab.events import Event, Listener, ignore
from sashil.recording.formats import can_formats
from sashil.recording.labels import controller_label
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_chirp, plot_transmissibility
from sashil.recording.rerun_log import feasible_band
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_progress import SessionHooks
from sashil.recording.run_set import RunSet
from sashil.runtime.runner import CYCLES_FILE
from sashil.runtime.signals import StopFlag
from sashil.stats import nrmse

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["TRANSMISSIBILITY_COLUMNS", "sweep"]

#: the columns of a stepped sine's ``transmissibility.csv``, one row per frequency
TRANSMISSIBILITY_COLUMNS = (
    "frequency_hz",
    "body_rms_rad",
    "road_rms_rad",
    "transmissibility",
    "observer_nrmse",
    "clipped_cycles",
)


def _label(config: RunConfig) -> str:
    """What commanded the damper: the law's label (``skyhook``; ``passive 1 A``)."""
    return law_run_label(StageParts.read(config))


def _freq_label(f_hz: float) -> str:
    """Sub-folder of one stepped-sine frequency, e.g. ``f1.650Hz``."""
    return f"f{f_hz:.3f}Hz"


def sweep(
    config: RunConfig,
    outputs: Outputs | None = None,
    on_event: Listener = ignore,
    *,
    progress: bool = False,
    views: Sequence[Any] = (),
    stop: StopFlag | None = None,
) -> Run:
    """Run the sweep of a resolved ``config`` (:func:`sashil.config.resolve.resolve` with verb
    ``sweep``: the ``sweep`` section; the law ``controller.law``, ``passive`` for a constant
    ``controller.current_a``) into a new run folder, and return it as a :class:`~sashil.api.Run`.

    A chirp (``sweep.stepped`` false) is one run: ``data.csv`` (:data:`~sashil.experiments.sweep.SWEEP_COLUMNS`
    and ``seq``), ``chirp.png``, and the body's RMS and peak in ``summary.json``. A stepped sine runs
    each of ``sweep.steps`` frequencies in a sub-folder of its own and writes the transmissibility
    table (``transmissibility.csv``, ``.png``; the points in ``summary.json``). The tables and the
    folder line are ``output`` events. ``progress``: a bar on stderr over the stepped sine's
    frequencies, instead of a ``progress`` event per frequency. ``views``: readers of each run's
    stream, as :func:`sashil.lab.closed_loop` takes them (a stepped sine's view gets
    ``start(stream, timing)`` and ``close(trips, notes)`` once per frequency); ``stop``: a flag
    another thread may set to end the running frequency at 0 A and the sweep (exit 130).

    Bad input (exit code 2: ConfigError; DriverError for a port that cannot be opened) is raised with
    no folder left; a run that fails after it started raises the error that ended it, after the
    folder is complete (the data up to the failure, the summary)."""

    outputs = outputs if outputs is not None else Outputs()
    outputs.check(config["driver"]["name"])
    make_controller(
        config["controller"]["law"], StageParts.read(config)
    )  # bad law parameters fail here, before a folder exists
    stepped = bool(config["sweep"]["stepped"])

    # the config's law runs each frequency, so on the real clock a loop process runs it (unless the
    # CAN frames are traced: a sweep's one trace follows the rigs in this process)
    in_process_only = bool(can_formats(tuple(outputs.formats)))
    watch = {"live": SessionHooks(*views) if views else None, "stop": stop, "law_of_config": not in_process_only}
    folder = RunFolder.create(outputs.out, "sweep")
    live = (
        None
        if stepped
        else outputs.open_rerun((*SWEEP_COLUMNS, "band_lo_nm", "band_hi_nm"), "sashil sweep", folder.path)
    )
    folder.write_config(config)
    label = _label(config)
    traces: list[Any] = []  # the CAN frame trace (formats blf|asc|log|mf4), started with the first rig
    rig_factory = _traced_rigs(outputs, folder, traces)
    runs = RunSet(
        folder,
        "sweep",
        {"driver": config["driver"]["name"], "controller": label, "mode": "stepped" if stepped else "chirp"},
        several=stepped,
    )
    extra: dict[str, Any] = {}
    failure: SashilError | None = None
    try:
        if stepped:
            _stepped(config, label, folder, rig_factory, runs, extra, outputs, on_event, progress, watch)
        else:
            _chirp(config, label, folder, live, rig_factory, runs, extra, outputs, on_event, watch)
    except SashilError as err:
        failure = err
    finally:
        trace_stats = traces[0].close() if traces else None
    if traces:
        extra["can_trace"] = trace_stats
    return _ended(folder, runs, extra, failure, on_event)


def _traced_rigs(outputs: Outputs, folder: RunFolder, traces: list[Any]) -> Callable[[Any, Any], Any]:
    """The sweep's rig factory: every rig of the sweep feeds the one CAN trace (in ``traces``, once
    the first rig started it)."""

    def rig_factory(cfg: Any, road: Any) -> Any:
        rig = default_rig(cfg, road)
        if traces:
            traces[0].attach(rig)
        else:
            trace = outputs.start_can_trace(rig, folder.path)
            if trace is not None:
                traces.append(trace)
        return rig

    return rig_factory


def _ended(
    folder: RunFolder, runs: RunSet, extra: dict[str, Any], failure: SashilError | None, on_event: Listener
) -> Run:
    """The sweep's summary, and its folder told as an event; bad input found on opening the rig
    leaves no folder, and an error that ended the sweep early is raised after the folder is complete."""
    if failure is not None and failure.exit_code == ConfigError.exit_code and not folder.recorded():
        folder.discard()  # bad input found on opening the rig (a port that cannot be opened): no folder
        raise failure
    runs.finish(**extra)
    if failure is not None:
        kept = "what was recorded is kept" if folder.recorded() else "nothing was recorded"
        on_event(
            Event("folder", f"run folder: {folder.path} (the sweep ended early; {kept})", {"folder": str(folder.path)})
        )
        raise failure
    on_event(Event("output", f"run folder: {folder.path}", {"folder": str(folder.path)}))
    return load_run(folder.path)


def _stepped(
    config: RunConfig,
    label: str,
    folder: Any,
    rig_factory: Any,
    runs: Any,
    extra: dict[str, Any],
    outputs: Outputs,
    on_event: Listener,
    progress: bool,
    watch: dict[str, Any],
) -> None:
    """The stepped sine: each frequency's run into ``runs`` and its sub-folder, the table and plot
    into ``folder``, the sweep's own summary keys into ``extra`` (as far as it got when a run fails)."""

    section = config["sweep"]
    name, stage = config["controller"]["law"], StageParts.read(config)
    f_start, f_stop = section["f_start_hz"], section["f_stop_hz"]
    freqs = frequencies(f_start, f_stop, section["steps"], section["spacing"])
    bar = Progress(len(freqs), "stepped sine", enabled=progress)
    points = []
    extra["points"] = []

    def stream_to(f: float) -> Path:
        """Each frequency in its own sub-folder (a run folder of its own), its cycles streamed there."""
        sub = runs.folder_for(_freq_label(f))
        sub.write_config(config)
        return sub.file(CYCLES_FILE)

    def keep(f: float, cols: dict[str, Any]) -> None:
        sub = runs.folder_for(_freq_label(f))
        sub.write_data(cols)
        outputs.write_formats(sub.path, "sweep", cols, exit_status="ok", controller=label, frequency_hz=f)

    try:
        for k, f in enumerate(freqs):  # one frequency at a time, for the progress bar
            if not progress:
                on_event(Event("progress", f"stepped sine: {f:.3g} Hz ({k + 1} of {len(freqs)})", {"frequency_hz": f}))
            try:
                point = stepped_sine(
                    config, lambda: make_controller(name, stage), [f], rig_factory, keep, stream_to, **watch
                )[0]
            except SashilError as err:  # the frequencies done so far are kept
                if err.exit_code != ConfigError.exit_code:
                    runs.add(_freq_label(f), {"frequency_hz": f, "safe_state": getattr(err, "safe_state", None)}, err)
                raise
            points.append(point)
            extra["points"].append(point.__dict__)
            runs.add(_freq_label(f), dict(point.__dict__))
            bar.advance(1, f"{f:.3g} Hz")
    finally:
        bar.close()
    rows = [[getattr(p, column) for column in TRANSMISSIBILITY_COLUMNS] for p in points]
    folder.write_rows("transmissibility.csv", TRANSMISSIBILITY_COLUMNS, rows)
    on_event(Event("output", f"{'f [Hz]':>8} {'body RMS [deg]':>15} {'transmissibility':>17} {'observer NRMSE':>15}"))
    for p in points:
        on_event(
            Event(
                "output",
                f"{p.frequency_hz:8.3f} {math.degrees(p.body_rms_rad):15.4f} {p.transmissibility:17.4f} "
                f"{100 * p.observer_nrmse:14.1f}%",
                dict(p.__dict__),
            )
        )
    _plot(folder, points, label, config)
    integrated = math.sqrt(sum(p.body_rms_rad**2 for p in points) / len(points))
    on_event(
        Event(
            "output",
            f"integrated body RMS over the frequencies: {math.degrees(integrated):.4f} deg ({label})",
            {"integrated_body_rms_rad": integrated},
        )
    )
    extra.update(
        road=f"stepped sine {f_start:g}-{f_stop:g} Hz, {len(freqs)} steps, {section['amplitude_deg']:g} deg",
        integrated_body_rms_rad=integrated,
    )


def _plot(folder: Any, points: list[Any], label: str, config: RunConfig) -> None:
    """``transmissibility.png``, the curve named by the law, its parameters and current."""

    freq = [p.frequency_hz for p in points]
    curve = (controller_label({"controller": label}, config), freq, [p.transmissibility for p in points])
    plot_transmissibility(folder.file("transmissibility.png"), [curve])


def _chirp(
    config: RunConfig,
    label: str,
    folder: Any,
    live: Any,
    rig_factory: Any,
    runs: Any,
    extra: dict[str, Any],
    outputs: Outputs,
    on_event: Listener,
    watch: dict[str, Any],
) -> None:
    """The chirp: one run into ``folder`` (data.csv however it ends, chirp.png, the live view), the
    body's RMS and peak into ``extra``."""

    section = config["sweep"]
    f_start, f_stop, duration = section["f_start_hz"], section["f_stop_hz"], section["duration_s"]
    amplitude = math.radians(section["amplitude_deg"])
    controller = make_controller(config["controller"]["law"], StageParts.read(config))
    on_event(
        Event(
            "progress", f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s ({label}) ...", {"duration_s": duration}
        )
    )
    try:  # data.csv is written however the run ends
        cols, stage = run_sweep(
            config,
            controller,
            chirp_profile(amplitude, f_start, f_stop, duration, section["ramp_s"]),
            duration + section["ramp_s"],
            rig_factory,
            keep=folder.write_data,
            data_path=folder.file(CYCLES_FILE),  # every cycle streamed as it runs
            **watch,
        )
    except SashilError as err:
        if err.exit_code != ConfigError.exit_code:
            runs.add("chirp", {"safe_state": getattr(err, "safe_state", None)}, err)
        raise
    outputs.write_formats(folder.path, "sweep", cols, exit_status="ok", controller=label)
    plot_chirp(
        folder.file("chirp.png"),
        cols,
        f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {section['amplitude_deg']:g} deg road "
        f"({controller_label({'controller': label}, config)})",
        chirp=(f_start, f_stop, duration),
    )
    if live is not None:
        shown = dict(cols)
        if config["model"]["name"] == "bouc-wen":
            feasible_band(shown, config["model"]["params"], config["rig"]["current_max_a"])
        live.log_columns(shown)
        live.close()
    body = cols["theta_rad"] + cols["theta_road_rad"]
    body_rms, body_peak = ac_rms(body), float(max(abs(body.max()), abs(body.min())))
    summary = {
        "road": f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {section['amplitude_deg']:g} deg",
        "body_rms_rad": body_rms,
        "road_rms_rad": ac_rms(cols["theta_road_rad"]),
        "body_peak_rad": body_peak,
        "observer_nrmse": nrmse(cols["torque_hat_nm"], cols["torque_true_nm"]),
        "clipped_cycles": stage.clip_count,
        "controller_stats": stage.stats(),
    }
    on_event(
        Event(
            "output",
            f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s ({label}): body RMS "
            f"{math.degrees(body_rms):.4f} deg, peak {math.degrees(body_peak):.3f} deg",
            {"body_rms_rad": body_rms, "body_peak_rad": body_peak},
        )
    )
    runs.add("chirp", {})
    extra.update(summary)

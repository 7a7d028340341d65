"""``sashil sweep`` as a library function: road-side excitation through the resonance, a linear
chirp or a stepped sine with its transmissibility table, into a run folder (``data.csv`` and
``chirp.png`` of a chirp; a sub-folder per frequency, ``transmissibility.csv`` and
``transmissibility.png`` of a stepped sine).

The road/wheel-side angle follows theta1(t) = A(t)*sin(phi(t)) (like the seed's wheel speed-up
through the ~1.6 Hz resonance), A(t) rising over ``ramp_s`` with a raised cosine:

* chirp: phi(t) = 2*pi*(f0*t + (f1 - f0)*t^2/(2*T)), instantaneous frequency f0 -> f1 over T;
* stepped sine: phi(t) = 2*pi*f*t per frequency, ``settle_s`` to reach the steady state, then
  ``measure_s`` (rounded up to whole periods) over which the body (arm) angle theta2 = theta +
  theta1 and the road angle are measured; transmissibility = RMS(theta2) / RMS(theta1) (RMS about
  the mean). Then the amplitude ramps back to 0 over ``ramp_s``, so that a rig that stays up
  between frequencies starts the next one at rest.

Every cycle's command carries ``road_speed_rad_s = theta1_dot(t)``, which every backend's road
motor obeys (a real rig's, the emulator's and the simulated rig's road wheel). The simulated rig runs on the virtual clock unless the config asks
for the real one; a link (serial, CAN: the emulator or the bench) runs on the real clock with the
loop's real-time set-up, as a drop test does. Each row records the sample's sequence number
(``seq``, as on the wire), so a link run joins with the emulator's ``--truth`` file.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil import engine
from sashil.api import Run, load_run
from sashil.config.parts import RunSpec
from sashil.control.registry import law_run_label, make_controller
from sashil.drivers import open_rig
from sashil.drivers.interface import RigInterface
from sashil.engine import assemble, assembled
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import ConfigError, SashilError
from sashil.identify.progress import Progress
from sashil.models.plant import RoadProfile
from sashil.plans.sweep import SweepStage
from sashil.recording.formats import can_formats
from sashil.recording.labels import controller_label
from sashil.recording.outputs import Outputs
from sashil.recording.plots import plot_chirp, plot_transmissibility
from sashil.recording.rerun_log import feasible_band
from sashil.recording.run_progress import SessionHooks
from sashil.roads.profiles import chirp_profile, sine_profile
from sashil.runtime.clock import Clock
from sashil.runtime.runner import CYCLES_FILE
from sashil.runtime.signals import StopFlag
from sashil.stats import nrmse
from sashil.writer.documents import Documents, RunRecord
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["READS", "TRANSMISSIBILITY_COLUMNS", "run_profile", "run_sweep", "stepped_sine", "sweep"]

#: the sweep's own values (``{name: config key}``), read once by the engine into its run's ``options``
READS = {
    key: f"sweep.{key}"
    for key in (
        "stepped",
        "f_start_hz",
        "f_stop_hz",
        "steps",
        "spacing",
        "amplitude_deg",
        "duration_s",
        "ramp_s",
        "measure_s",
        "settle_s",
    )
}


#: the columns of a stepped sine's ``transmissibility.csv``, one row per frequency
TRANSMISSIBILITY_COLUMNS = (
    "frequency_hz",
    "body_rms_rad",
    "road_rms_rad",
    "transmissibility",
    "observer_nrmse",
    "clipped_cycles",
)


def _shown(run: RunSpec) -> dict[str, Any]:
    """The run's law section as a plot's label reads it (:func:`~sashil.recording.labels.controller_label`)."""
    return {"controller": run.stage.controller.section()}


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
    """Run the sweep of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``sweep``: the ``sweep`` section; the law ``controller.law``, ``passive`` for a constant
    ``controller.current_a``) into a new run folder, and return it as a :class:`~sashil.api.Run`.

    A chirp (``sweep.stepped`` false) is one run: ``data.csv`` (:data:`~sashil.lab._sweep.SWEEP_COLUMNS`
    and ``seq``), ``chirp.png``, and the body's RMS and peak in ``summary.json``. A stepped sine runs
    each of ``sweep.steps`` frequencies in a sub-folder of its own and writes the transmissibility
    table (``transmissibility.csv``, ``.png``; the points in ``summary.json``). The tables and the
    folder line are ``output`` events. ``progress``: a bar on stderr over the stepped sine's
    frequencies, instead of a ``progress`` event per frequency. ``views``: readers of each run's
    stream, as :func:`sashil.engine.sashil_run.closed_loop` takes them (a stepped sine's view gets
    ``start(stream, timing)`` and ``close(trips, notes)`` once per frequency); ``stop``: a flag
    another thread may set to end the running frequency at 0 A and the sweep (exit 130).

    Bad input (exit code 2: ConfigError; DriverError for a port that cannot be opened) is raised with
    no folder left; a run that fails after it started raises the error that ended it, after the
    folder is complete (the data up to the failure, the summary)."""

    outputs = outputs if outputs is not None else Outputs()
    run = assemble(config, reads=READS)
    outputs.check(run.rig.backend)
    make_controller(run.stage.law, run.stage)  # bad law parameters fail here, before a folder exists
    stepped = bool(run.options["stepped"])

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
    label = law_run_label(run.stage)
    traces: list[Any] = []  # the CAN frame trace (formats blf|asc|log|mf4), started with the first rig
    rig_factory = _traced_rigs(outputs, folder, traces)
    common = {"driver": run.rig.backend, "controller": label, "mode": "stepped" if stepped else "chirp"}
    runs = FolderWriter(folder, "sweep", common, several=stepped)
    documents = Documents([runs])
    documents.start(None, config, run)
    extra: dict[str, Any] = {}
    failure: SashilError | None = None
    try:
        if stepped:
            _stepped(
                run, config, label, folder, rig_factory, documents, runs, extra, outputs, on_event, progress, watch
            )
        else:
            _chirp(run, label, folder, live, rig_factory, documents, extra, outputs, on_event, watch)
    except SashilError as err:
        failure = err
    finally:
        trace_stats = traces[0].close() if traces else None
    if traces:
        extra["can_trace"] = trace_stats
    return _ended(folder, documents, extra, failure, on_event)


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
    folder: RunFolder, documents: Documents, extra: dict[str, Any], failure: SashilError | None, on_event: Listener
) -> Run:
    """The sweep's summary, and its folder told as an event; bad input found on opening the rig
    leaves no folder, and an error that ended the sweep early is raised after the folder is complete."""
    if failure is not None and failure.exit_code == ConfigError.exit_code and not folder.recorded():
        folder.discard()  # bad input found on opening the rig (a port that cannot be opened): no folder
        raise failure
    documents.end(**extra)
    if failure is not None:
        kept = "what was recorded is kept" if folder.recorded() else "nothing was recorded"
        on_event(
            Event("folder", f"run folder: {folder.path} (the sweep ended early; {kept})", {"folder": str(folder.path)})
        )
        raise failure
    on_event(Event("output", f"run folder: {folder.path}", {"folder": str(folder.path)}))
    return load_run(folder.path)


def _stepped(
    run: RunSpec,
    config: RunConfig,
    label: str,
    folder: Any,
    rig_factory: Any,
    documents: Documents,
    runs: FolderWriter,
    extra: dict[str, Any],
    outputs: Outputs,
    on_event: Listener,
    progress: bool,
    watch: dict[str, Any],
) -> None:
    """The stepped sine: each frequency's run into ``runs`` and its sub-folder, the table and plot
    into ``folder``, the sweep's own summary keys into ``extra`` (as far as it got when a run fails);
    ``config``: the resolved config, which each frequency's folder records."""

    section = run.options
    name, stage = run.stage.law, run.stage
    f_start, f_stop = section["f_start_hz"], section["f_stop_hz"]
    freqs = frequencies(f_start, f_stop, section["steps"], section["spacing"])
    bar = Progress(len(freqs), "stepped sine", enabled=progress)
    points = []
    extra["points"] = []

    def stream_to(f: float) -> Path:
        """Each frequency in its own sub-folder (a run folder of its own), its cycles streamed there."""
        documents.start(_freq_label(f), config, run)
        return runs.folder_for(_freq_label(f)).file(CYCLES_FILE)

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
                    run, lambda: make_controller(name, stage), [f], rig_factory, keep, stream_to, **watch
                )[0]
            except SashilError as err:  # the frequencies done so far are kept
                if err.exit_code != ConfigError.exit_code:
                    entry = {"frequency_hz": f, "safe_state": getattr(err, "safe_state", None)}
                    documents.stop(_freq_label(f), RunRecord(error=err, entry=entry))
                raise
            points.append(point)
            extra["points"].append(point.__dict__)
            documents.stop(_freq_label(f), RunRecord(entry=dict(point.__dict__)))
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
    _plot(folder, points, label, run)
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


def _plot(folder: Any, points: list[Any], label: str, run: RunSpec) -> None:
    """``transmissibility.png``, the curve named by the law, its parameters and current."""

    freq = [p.frequency_hz for p in points]
    curve = (controller_label({"controller": label}, _shown(run)), freq, [p.transmissibility for p in points])
    plot_transmissibility(folder.file("transmissibility.png"), [curve])


def _chirp(
    run: RunSpec,
    label: str,
    folder: Any,
    live: Any,
    rig_factory: Any,
    documents: Documents,
    extra: dict[str, Any],
    outputs: Outputs,
    on_event: Listener,
    watch: dict[str, Any],
) -> None:
    """The chirp: one run into ``folder`` (data.csv however it ends, chirp.png, the live view), the
    body's RMS and peak into ``extra``."""

    section = run.options
    f_start, f_stop, duration = section["f_start_hz"], section["f_stop_hz"], section["duration_s"]
    amplitude = math.radians(section["amplitude_deg"])
    controller = make_controller(run.stage.law, run.stage)
    on_event(
        Event(
            "progress", f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s ({label}) ...", {"duration_s": duration}
        )
    )
    try:  # data.csv is written however the run ends
        cols, stage = run_sweep(
            run,
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
            documents.stop("chirp", RunRecord(error=err, entry={"safe_state": getattr(err, "safe_state", None)}))
        raise
    outputs.write_formats(folder.path, "sweep", cols, exit_status="ok", controller=label)
    plot_chirp(
        folder.file("chirp.png"),
        cols,
        f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {section['amplitude_deg']:g} deg road "
        f"({controller_label({'controller': label}, _shown(run))})",
        chirp=(f_start, f_stop, duration),
    )
    if live is not None:
        shown = dict(cols)
        if run.stage.model.name == "bouc-wen":
            feasible_band(shown, run.stage.model.params, run.stage.current_max_a)
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
    documents.stop("chirp", RunRecord())
    extra.update(summary)


#: data.csv columns of a sweep (docs/architecture.md names; torque_true_nm only on the simulated rig), then ``seq``
SWEEP_COLUMNS = (
    "time_s",
    "theta_rad",
    "theta_road_rad",
    "current_a",
    "current_cmd_a",
    "theta_dot_rad_s",
    "z_hat",
    "torque_hat_nm",
    "torque_cmd_nm",
    "torque_true_nm",
)


def frequencies(f_start_hz: float, f_stop_hz: float, steps: int, spacing: str = "linear") -> list[float]:
    if spacing == "log":
        return [float(f) for f in np.geomspace(f_start_hz, f_stop_hz, steps)]
    return [float(f) for f in np.linspace(f_start_hz, f_stop_hz, steps)]


#: the controller's per-cycle values a sweep records (the controller's attributes, docs/architecture.md names)
def sweep_columns(stream: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """:data:`SWEEP_COLUMNS`, a current law's own output (``current_law_a``) when the stream has it,
    and ``seq`` (int64) of a sweep's stream."""
    if not stream:
        return {name: np.zeros(0) for name in SWEEP_COLUMNS} | {"seq": np.zeros(0, dtype=np.int64)}
    names = (*SWEEP_COLUMNS, "current_law_a") if "current_law_a" in stream else SWEEP_COLUMNS
    return {name: stream[name] for name in names} | {"seq": stream["seq"].astype(np.int64)}


RigFactory = Callable[["RunSpec", RoadProfile], RigInterface]


def default_rig(run: RunSpec, road: RoadProfile) -> RigInterface:
    """The rig a sweep runs on: the run's backend, whose road motor gets the profile's speed
    from the sweep's commands (the simulated rig's road wheel as a board's)."""
    return open_rig(run.rig)


def run_profile(
    config: RunConfig | RunSpec,
    controller: Any,
    road: RoadProfile,
    duration_s: float,
    rig_factory: RigFactory | None = None,
    clock: Clock | None = None,
    keep: Callable[[dict[str, np.ndarray]], object] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
) -> dict[str, np.ndarray]:
    """One run of ``controller`` under the road profile (:func:`run_sweep`); the recorded columns."""
    columns, _ = run_sweep(
        config, controller, road, duration_s, rig_factory, clock, keep, data_path, live=live, stop=stop
    )
    return columns


def run_sweep(
    config: RunConfig | RunSpec,
    controller: Any,
    road: RoadProfile,
    duration_s: float,
    rig_factory: RigFactory | None = None,
    clock: Clock | None = None,
    keep: Callable[[dict[str, np.ndarray]], object] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    law_of_config: bool = False,
) -> tuple[dict[str, np.ndarray], SweepStage]:
    """One run of ``controller`` under the road profile, in the run of ``config`` (a resolved config,
    or the sweep's assembled run), through the one runner
    (:func:`~sashil.runtime.runner.run_plan`: safety, signals, real-time set-up on the real clock,
    the road at rest and 0 A at the end); returns the recorded columns and the run's stage (its
    :attr:`~SweepStage.clip_count` and :meth:`~SweepStage.stats`).

    ``law_of_config``: ``controller`` is the config's law, so on the real clock with
    ``loop.process`` a loop process can run the same stage of its own (:func:`sashil.plans.sweep.stage`; the
    road a :class:`~sashil.roads.profiles.SweepRoad`); ``rig_factory`` then goes unused. Clock: ``clock``, else the
    config's (:func:`~sashil.runtime.clock.default_clock`: the virtual one for the simulated
    rig, the real one for a link). ``keep`` gets the columns recorded so far however the run ends
    (a link fault, a safety trip, a stop), before the error propagates. ``data_path``: the runner
    streams every cycle there as it runs. ``live``: views of the stream (``start(stream, timing)``,
    ``close(trips, notes)``); ``stop``: a :class:`~sashil.runtime.signals.StopFlag` another thread
    may set. A signal or a stop ends the run cleanly and raises :class:`~sashil.errors.Stopped`
    (exit 130) after ``keep``; the error that ended a run carries its ``safe_state`` (how the coil
    settled at 0 A after a stop).
    """
    run = assembled(config, READS)
    stage = SweepStage(controller, road, duration_s)
    stage.from_config = law_of_config
    outcome = engine.run(
        run,
        stage,
        duration_s,
        clock=clock,
        rig=lambda: (rig_factory or default_rig)(run, road),
        data_path=data_path,
        live=live,
        stop=stop,
    )
    if live is not None:
        live.close(outcome.trips, ())
    columns = sweep_columns(outcome.stream)
    if keep is not None:
        keep(columns)
    ended = outcome.error if outcome.error is not None else outcome.stop_error()
    if ended is not None:
        ended.safe_state = outcome.safe_state  # type: ignore[attr-defined]  # the run's summary row shows it
        raise ended
    return columns, stage


def ac_rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean((x - x.mean()) ** 2))) if x.size else math.nan


@dataclass
class SteppedPoint:
    frequency_hz: float
    body_rms_rad: float
    road_rms_rad: float
    transmissibility: float
    observer_nrmse: float  # T-hat against the true plant torque (sim only, else NaN)
    clipped_cycles: int


def stepped_sine(
    config: RunConfig | RunSpec,
    make_controller: Callable[[], Any],
    freqs: list[float],
    rig_factory: RigFactory | None = None,
    keep: Callable[[float, dict[str, np.ndarray]], None] | None = None,
    stream_to: Callable[[float], Path] | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    law_of_config: bool = False,
) -> list[SteppedPoint]:
    """Transmissibility per frequency: a fresh controller and rig per frequency (``sweep`` section).
    ``keep(frequency_hz, columns)`` gets each frequency's time series once it has run;
    ``stream_to(frequency_hz)``: the file the runner streams that frequency's cycles to; ``live``
    and ``stop``: each frequency's run's views and stop flag; ``law_of_config``: ``make_controller``
    makes the config's law (:func:`run_sweep`)."""
    run = assembled(config, READS)
    sweep = run.options
    amplitude = math.radians(sweep["amplitude_deg"])
    points = []
    for f in freqs:
        measure = math.ceil(sweep["measure_s"] * f) / f
        start = sweep["ramp_s"] + sweep["settle_s"]
        controller = make_controller()
        # the road ramps down after the measurement: a rig that stays up between frequencies (a link)
        # starts the next one at rest instead of with a step of the road speed
        stop_s = start + measure
        cols, stage = run_sweep(
            run,
            controller,
            sine_profile(amplitude, f, sweep["ramp_s"], stop_s),
            stop_s + sweep["ramp_s"],
            rig_factory,
            data_path=stream_to(f) if stream_to is not None else None,
            live=live,
            stop=stop,
            law_of_config=law_of_config,
        )
        if keep is not None:
            keep(f, cols)
        window = (cols["time_s"] >= start - 1e-9) & (cols["time_s"] < stop_s - 1e-9)
        body = cols["theta_rad"][window] + cols["theta_road_rad"][window]
        road = cols["theta_road_rad"][window]
        body_rms, road_rms = ac_rms(body), ac_rms(road)
        points.append(
            SteppedPoint(
                f,
                body_rms,
                road_rms,
                body_rms / road_rms if road_rms > 0 else math.nan,
                nrmse(cols["torque_hat_nm"][window], cols["torque_true_nm"][window]),
                stage.clip_count,
            )
        )
    return points

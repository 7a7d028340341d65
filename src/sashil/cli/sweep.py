"""``sashil sweep``: road-side excitation through the resonance, chirp or stepped sine."""

from __future__ import annotations

import argparse
import copy
import math
import sys
from pathlib import Path
from typing import Any

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    current_in_range,
    law_help,
    open_rerun,
    option_or_config,
    positive_seconds,
    resolve_config,
    select_law,
    setup_logging,
    start_can_trace,
    write_formats,
)
from sashil.control.registry import make_controller
from sashil.errors import ConfigError, SashilError
from sashil.experiments.sweep import (
    SWEEP_COLUMNS,
    ac_rms,
    chirp_profile,
    default_rig,
    frequencies,
    run_profile,
    stepped_sine,
)
from sashil.identify.progress import Progress
from sashil.recording.rerun_log import feasible_band
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_set import RunSet
from sashil.runtime.runner import CYCLES_FILE
from sashil.stats import nrmse

EXAMPLE = "sashil sweep --f-start 0.5 --f-stop 5 --duration 30 --controller skyhook-onoff"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--f-start", type=float, metavar="HZ", help="start frequency [Hz] (default sweep.f_start_hz, 0.5)"
    )
    parser.add_argument(
        "--f-stop",
        type=float,
        metavar="HZ",
        help="stop frequency [Hz] (default sweep.f_stop_hz, 5; equal to --f-start: a sine at that frequency)",
    )
    parser.add_argument("--duration", type=float, metavar="S", help="chirp length [s] (default sweep.duration_s, 30)")
    parser.add_argument(
        "--amplitude-deg", type=float, metavar="DEG", help="road amplitude (override sweep.amplitude_deg)"
    )
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--controller", metavar="LAW", help=f"semi-active law ({law_help()}); default controller.law")
    group.add_argument(
        "--current", type=float, metavar="A", help="passive constant current instead of a law (controller.current_a)"
    )
    parser.add_argument(
        "--stepped",
        action=argparse.BooleanOptionalAction,
        help="stepped sine: transmissibility per frequency (sweep.steps); default sweep.stepped, false",
    )
    parser.add_argument(
        "--steps", type=int, metavar="N", help="stepped sine: number of frequencies (override sweep.steps)"
    )
    add_output_options(parser)
    add_recording_options(parser)  # live view / data.mat of the chirp's data.csv
    add_verbosity_options(parser)


def _frequencies(args: argparse.Namespace, config: dict) -> None:
    """``--f-start``/``--f-stop``/``--stepped`` (else the config's ``sweep`` section), checked and
    written to the config."""
    sweep = config["sweep"]
    f_start, start_name = option_or_config(args.f_start, "--f-start", config, "sweep.f_start_hz")
    f_stop, stop_name = option_or_config(args.f_stop, "--f-stop", config, "sweep.f_stop_hz")
    stepped, _ = option_or_config(args.stepped, "--stepped", config, "sweep.stepped")
    top = config["loop"]["rate_hz"] / 10
    for option, value in ((start_name, f_start), (stop_name, f_stop)):
        if not (math.isfinite(value) and 0.0 < value <= top):
            raise ConfigError(f"{option}: expected a frequency in (0, {top:g}] Hz, got {value:g}")
    if f_stop < f_start:
        raise ConfigError(
            f"{stop_name}: expected a frequency at or above {start_name} ({f_start:g} Hz), got {f_stop:g}"
        )
    if stepped and f_stop == f_start:
        raise ConfigError(
            f"{stop_name}: a stepped sine needs a frequency above {start_name} ({f_start:g} Hz), got {f_stop:g}"
        )
    sweep.update(f_start_hz=float(f_start), f_stop_hz=float(f_stop), stepped=bool(stepped))


def _check(args: argparse.Namespace, config: dict) -> tuple[str, dict]:
    """The law and the config the sweep runs with: every option in it (config.yaml says what ran)."""
    config = copy.deepcopy(config)
    duration, duration_name = option_or_config(args.duration, "--duration", config, "sweep.duration_s")
    config["sweep"]["duration_s"] = positive_seconds(duration_name, duration)
    _frequencies(args, config)
    if args.amplitude_deg is not None:
        if not (math.isfinite(args.amplitude_deg) and 0.0 < args.amplitude_deg <= 20.0):
            raise ConfigError(f"--amplitude-deg: expected an angle in (0, 20] deg, got {args.amplitude_deg:g}")
        config["sweep"]["amplitude_deg"] = args.amplitude_deg
    if args.steps is not None:
        if not 2 <= args.steps <= 1000:
            raise ConfigError(f"--steps: expected an integer in [2, 1000], got {args.steps}")
        config["sweep"]["steps"] = args.steps
    if args.current is not None:
        select_law(config, "passive")
        config["controller"]["current_a"] = current_in_range("--current", args.current, config)
        return "passive", config
    return select_law(config, args.controller), config


def _label(name: str, config: dict) -> str:
    """What commanded the damper: the law, or the passive current."""
    return f"passive {config['controller']['current_a']:g} A" if name == "passive" else name


def _plot(folder: RunFolder, points, label: str, config: dict) -> None:
    """``transmissibility.png``, the curve named by the law, its parameters and current."""
    from sashil.recording.labels import controller_label
    from sashil.recording.plots import plot_transmissibility

    freq = [p.frequency_hz for p in points]
    curve = (controller_label({"controller": label}, config), freq, [p.transmissibility for p in points])
    plot_transmissibility(folder.file("transmissibility.png"), [curve])


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    config = resolve_config(args)
    name, config = _check(args, config)
    folder = RunFolder.create(args.out, "sweep")
    live = (
        None
        if config["sweep"]["stepped"]
        else open_rerun(args, (*SWEEP_COLUMNS, "band_lo_nm", "band_hi_nm"), "sashil sweep", folder.path)
    )
    folder.write_config(config)
    label = _label(name, config)
    trace_box: list = []  # the CAN frame trace (--format blf|asc|log|mf4), started with the first rig

    def rig_factory(cfg: dict, road):  # every rig of the sweep feeds the one trace
        rig = default_rig(cfg, road)
        if trace_box:
            trace_box[0].attach(rig)
        else:
            trace = start_can_trace(args, rig, folder.path)
            if trace is not None:
                trace_box.append(trace)
        return rig

    stepped = config["sweep"]["stepped"]
    runs = RunSet(
        folder,
        "sweep",
        {"driver": config["driver"]["name"], "controller": label, "mode": "stepped" if stepped else "chirp"},
        several=stepped,
    )
    extra: dict[str, Any] = {}
    failure: SashilError | None = None
    try:
        _sweep(args, config, name, label, folder, live, rig_factory, runs, extra)
    except SashilError as err:
        if err.exit_code == ConfigError.exit_code:
            raise  # bad input (a port that cannot be opened): nothing is written, the folder goes
        failure = err
    finally:
        if trace_box:
            extra["can_trace"] = trace_box[0].close()
    runs.finish(**extra)
    if failure is not None:
        kept = "what was recorded is kept" if folder.recorded() else "nothing was recorded"
        print(f"run folder: {folder.path} (the sweep ended early; {kept})", file=sys.stderr)
        raise failure
    print(f"run folder: {folder.path}")
    return 0


def _freq_label(f_hz: float) -> str:
    """Sub-folder of one stepped-sine frequency, e.g. ``f1.650Hz``."""
    return f"f{f_hz:.3f}Hz"


def _sweep(args, config, name, label, folder, live, rig_factory, runs: RunSet, extra: dict[str, Any]) -> None:
    """Run the stepped sine or the chirp of ``config['sweep']``: each run's entry into ``runs``, the
    sweep's own summary keys into ``extra`` (as far as it got when a run fails)."""
    sweep = config["sweep"]
    f_start, f_stop, duration = sweep["f_start_hz"], sweep["f_stop_hz"], sweep["duration_s"]
    if sweep["stepped"]:
        freqs = frequencies(f_start, f_stop, sweep["steps"], sweep["spacing"])
        bar = Progress(len(freqs), "stepped sine", enabled=not args.quiet)
        points = []

        extra["points"] = []

        def stream_to(f: float) -> Path:
            """Each frequency in its own sub-folder (a run folder of its own), its cycles streamed there."""
            sub = runs.folder_for(_freq_label(f))
            sub.write_config(config)
            return sub.file(CYCLES_FILE)

        def keep(f: float, cols: dict) -> None:
            sub = runs.folder_for(_freq_label(f))
            sub.write_data(cols)
            write_formats(args, sub.path, config, "sweep", cols, exit_status="ok", controller=label, frequency_hz=f)

        try:
            for f in freqs:  # one frequency at a time, for the progress bar
                try:
                    point = stepped_sine(
                        config, lambda: make_controller(name, config), [f], rig_factory, keep, stream_to=stream_to
                    )[0]
                except SashilError as err:  # the frequencies done so far are kept
                    if err.exit_code != ConfigError.exit_code:
                        runs.add(_freq_label(f), {"frequency_hz": f}, err)
                    raise
                points.append(point)
                extra["points"].append(point.__dict__)
                runs.add(_freq_label(f), dict(point.__dict__))
                bar.advance(1, f"{f:.3g} Hz")
        finally:
            bar.close()
        lines = ["frequency_hz,body_rms_rad,road_rms_rad,transmissibility,observer_nrmse,clipped_cycles"]
        print(f"{'f [Hz]':>8} {'body RMS [deg]':>15} {'transmissibility':>17} {'observer NRMSE':>15}")
        for p in points:
            lines.append(
                f"{p.frequency_hz!r},{p.body_rms_rad!r},{p.road_rms_rad!r},{p.transmissibility!r},{p.observer_nrmse!r},{p.clipped_cycles}"
            )
            print(
                f"{p.frequency_hz:8.3f} {math.degrees(p.body_rms_rad):15.4f} {p.transmissibility:17.4f} {100 * p.observer_nrmse:14.1f}%"
            )
        folder._write_text("transmissibility.csv", "\n".join(lines) + "\n")
        _plot(folder, points, label, config)
        integrated = math.sqrt(sum(p.body_rms_rad**2 for p in points) / len(points))
        print(f"integrated body RMS over the frequencies: {math.degrees(integrated):.4f} deg ({label})")
        extra.update(
            road=f"stepped sine {f_start:g}-{f_stop:g} Hz, {len(freqs)} steps, {sweep['amplitude_deg']:g} deg",
            integrated_body_rms_rad=integrated,
        )
    else:
        amplitude = math.radians(sweep["amplitude_deg"])
        controller = make_controller(name, config)
        total = duration + sweep["ramp_s"]
        try:  # data.csv is written however the run ends
            cols = run_profile(
                config,
                controller,
                chirp_profile(amplitude, f_start, f_stop, duration, sweep["ramp_s"]),
                total,
                rig_factory,
                keep=folder.write_data,
                data_path=folder.file(CYCLES_FILE),  # every cycle streamed as it runs
            )
        except SashilError as err:
            if err.exit_code != ConfigError.exit_code:
                runs.add("chirp", {}, err)
            raise
        write_formats(args, folder.path, config, "sweep", cols, exit_status="ok", controller=label)
        from sashil.recording.labels import controller_label
        from sashil.recording.plots import plot_chirp

        plot_chirp(
            folder.file("chirp.png"),
            cols,
            f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {sweep['amplitude_deg']:g} deg road "
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
            "road": f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {sweep['amplitude_deg']:g} deg",
            "body_rms_rad": body_rms,
            "road_rms_rad": ac_rms(cols["theta_road_rad"]),
            "body_peak_rad": body_peak,
            "observer_nrmse": nrmse(cols["torque_hat_nm"], cols["torque_true_nm"]),
            "clipped_cycles": int(getattr(controller, "clip_count", 0)),
            "controller_stats": controller.stats() if hasattr(controller, "stats") else None,
        }
        print(
            f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s ({label}): body RMS "
            f"{math.degrees(body_rms):.4f} deg, peak {math.degrees(body_peak):.3f} deg"
        )
        runs.add("chirp", {})
        extra.update(summary)

"""``sashil sweep``: road-side excitation through the resonance, chirp or stepped sine (issue 5)."""

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
    open_rerun,
    positive_seconds,
    resolve_config,
    setup_logging,
)
from sashil.cli.outputs import start_can_trace, write_formats
from sashil.control.registry import LAWS, make_controller
from sashil.errors import ConfigError, SashilError, status_of
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
from sashil.runtime.runner import CYCLES_FILE
from sashil.stats import nrmse

HELP = "sweep: road excitation theta1 = A sin(phi(t)), a linear chirp or stepped sine (transmissibility table)"
EXAMPLE = "sashil sweep --f-start 0.5 --f-stop 5 --duration 30 --controller skyhook-onoff"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument("--f-start", type=float, default=0.5, metavar="HZ", help="start frequency [Hz] (default 0.5)")
    parser.add_argument(
        "--f-stop",
        type=float,
        default=5.0,
        metavar="HZ",
        help="stop frequency [Hz] (default 5; equal to --f-start: a sine at that frequency)",
    )
    parser.add_argument("--duration", type=float, default=30.0, metavar="S", help="chirp length [s] (default 30)")
    parser.add_argument(
        "--amplitude-deg", type=float, metavar="DEG", help="road amplitude (override sweep.amplitude_deg)"
    )
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--controller", metavar="LAW", help=f"semi-active law ({', '.join(LAWS)}); default controller.law"
    )
    group.add_argument("--current", type=float, metavar="A", help="passive constant current instead of a law")
    parser.add_argument(
        "--stepped", action="store_true", help="stepped sine: transmissibility per frequency (sweep.steps)"
    )
    parser.add_argument(
        "--steps", type=int, metavar="N", help="stepped sine: number of frequencies (override sweep.steps)"
    )
    add_output_options(parser)
    add_recording_options(parser)  # live view / data.mat of the chirp's data.csv
    add_verbosity_options(parser)


def _check(args: argparse.Namespace, config: dict) -> tuple[str, dict]:
    for option, value in (("--f-start", args.f_start), ("--f-stop", args.f_stop)):
        if not (math.isfinite(value) and 0.0 < value <= config["loop"]["rate_hz"] / 10):
            raise ConfigError(
                f"{option}: expected a frequency in (0, {config['loop']['rate_hz'] / 10:g}] Hz, got {value:g}"
            )
    if args.f_stop < args.f_start:
        raise ConfigError(
            f"--f-stop: expected a frequency at or above --f-start ({args.f_start:g} Hz), got {args.f_stop:g}"
        )
    if args.stepped and args.f_stop == args.f_start:
        raise ConfigError(
            f"--f-stop: a stepped sine needs a frequency above --f-start ({args.f_start:g} Hz), got {args.f_stop:g}"
        )
    config = copy.deepcopy(config)
    if args.amplitude_deg is not None:
        if not (math.isfinite(args.amplitude_deg) and 0.0 < args.amplitude_deg <= 20.0):
            raise ConfigError(f"--amplitude-deg: expected an angle in (0, 20] deg, got {args.amplitude_deg:g}")
        config["sweep"]["amplitude_deg"] = args.amplitude_deg
    if args.steps is not None:
        if not 2 <= args.steps <= 1000:
            raise ConfigError(f"--steps: expected an integer in [2, 1000], got {args.steps}")
        config["sweep"]["steps"] = args.steps
    if args.current is not None:
        config["controller"]["current_a"] = current_in_range("--current", args.current, config)
        return "passive", config
    name = args.controller or config["controller"]["law"]
    if name not in LAWS:
        raise ConfigError(f"--controller: unknown law {name!r} (known: {', '.join(LAWS)})")
    make_controller(name, config)  # bad law parameters fail here, before a folder exists
    return name, config


def _plot(folder: RunFolder, points, label: str) -> None:
    from sashil.recording.plots import plot_transmissibility

    freq = [p.frequency_hz for p in points]
    plot_transmissibility(folder.file("transmissibility.png"), [(label, freq, [p.transmissibility for p in points])])


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    config = resolve_config(args)
    duration = positive_seconds("--duration", args.duration)
    name, config = _check(args, config)
    folder = RunFolder.create(args.out, "sweep")
    live = (
        None
        if args.stepped
        else open_rerun(args, (*SWEEP_COLUMNS, "band_lo_nm", "band_hi_nm"), "sashil sweep", folder.path)
    )
    folder.write_config(config)
    label = name if args.current is None else f"passive {args.current:g} A"
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

    try:
        summary = _sweep(args, config, name, label, duration, folder, live, rig_factory)
    finally:
        if trace_box:
            trace_stats = trace_box[0].close()
    if trace_box:
        summary["can_trace"] = trace_stats
    _write_summary(folder, summary)
    print(f"run folder: {folder.path}")
    return 0


def _freq_label(f_hz: float) -> str:
    """Sub-folder of one stepped-sine frequency, e.g. ``f1.650Hz``."""
    return f"f{f_hz:.3f}Hz"


def _sweep(args, config, name, label, duration, folder, live, rig_factory) -> dict:
    """Run the stepped sine or the chirp; returns the summary."""
    sweep = config["sweep"]
    if args.stepped:
        freqs = frequencies(args.f_start, args.f_stop, sweep["steps"], sweep["spacing"])
        bar = Progress(len(freqs), "stepped sine", enabled=not args.quiet)
        points = []
        kept: list[dict] = []

        subs: dict[float, RunFolder] = {}

        def stream_to(f: float) -> Path:
            """Each frequency in its own sub-folder (a run folder of its own), its cycles streamed there."""
            subs[f] = RunFolder.create(folder.path / _freq_label(f), "sweep")
            subs[f].write_config(config)
            return subs[f].file(CYCLES_FILE)

        def keep(f: float, cols: dict) -> None:
            sub = subs[f]
            sub.write_data(cols)
            write_formats(args, sub.path, config, "sweep", cols, controller=label, frequency_hz=f)
            kept.append({"folder": _freq_label(f), "frequency_hz": f})
            sub.write_summary(
                {"exit_status": "ok", "driver": config["driver"]["name"], "controller": label, "mode": "stepped",
                 "runs": [{"folder": ".", "frequency_hz": f}]}
            )  # fmt: skip

        try:
            for f in freqs:  # one frequency at a time, for the progress bar
                points += stepped_sine(
                    config, lambda: make_controller(name, config), [f], rig_factory, keep, stream_to=stream_to
                )
                bar.advance(1, f"{f:.3g} Hz")
        except SashilError as err:  # the frequencies done so far are kept
            _write_failed(folder, err, {"mode": "stepped", "controller": label, "points": [p.__dict__ for p in points]})
            raise
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
        _plot(folder, points, label)
        integrated = math.sqrt(sum(p.body_rms_rad**2 for p in points) / len(points))
        print(f"integrated body RMS over the frequencies: {math.degrees(integrated):.4f} deg ({label})")
        summary: dict[str, Any] = {
            "exit_status": "ok",
            "driver": config["driver"]["name"],
            "mode": "stepped",
            "controller": label,
            "integrated_body_rms_rad": integrated,
            "points": [p.__dict__ for p in points],
            "runs": [{**entry, **p.__dict__} for entry, p in zip(kept, points, strict=True)],
        }
    else:
        amplitude = math.radians(sweep["amplitude_deg"])
        controller = make_controller(name, config)
        total = duration + sweep["ramp_s"]
        try:  # data.csv is written however the run ends
            cols = run_profile(
                config,
                controller,
                chirp_profile(amplitude, args.f_start, args.f_stop, duration, sweep["ramp_s"]),
                total,
                rig_factory,
                keep=folder.write_data,
                data_path=folder.file(CYCLES_FILE),  # every cycle streamed as it runs
            )
        except SashilError as err:
            _write_failed(folder, err, {"mode": "chirp", "controller": label})
            raise
        write_formats(args, folder.path, config, "sweep", cols, controller=label)
        from sashil.recording.plots import plot_chirp

        plot_chirp(
            folder.file("chirp.png"),
            cols,
            f"chirp {args.f_start:g}-{args.f_stop:g} Hz over {duration:g} s, {sweep['amplitude_deg']:g} deg road ({label})",
        )
        if live is not None:
            shown = dict(cols)
            if config["model"]["name"] == "bouc-wen":
                feasible_band(shown, config["model"]["params"], config["rig"]["current_max_a"])
            live.log_columns(shown)
            live.close()
        body = cols["theta_rad"] + cols["theta_road_rad"]
        summary = {
            "exit_status": "ok",
            "driver": config["driver"]["name"],
            "mode": "chirp",
            "controller": label,
            "body_rms_rad": ac_rms(body),
            "road_rms_rad": ac_rms(cols["theta_road_rad"]),
            "body_peak_rad": float(max(abs(body.max()), abs(body.min()))),
            "observer_nrmse": nrmse(cols["torque_hat_nm"], cols["torque_true_nm"]),
            "clipped_cycles": int(getattr(controller, "clip_count", 0)),
            "controller_stats": controller.stats() if hasattr(controller, "stats") else None,
        }
        print(
            f"chirp {args.f_start:g}-{args.f_stop:g} Hz over {duration:g} s ({label}): body RMS "
            f"{math.degrees(summary['body_rms_rad']):.4f} deg, peak {math.degrees(summary['body_peak_rad']):.3f} deg"
        )
    return summary


def _write_summary(folder: RunFolder, summary: dict) -> None:
    """summary.json with NaN as null (JSON has no NaN)."""

    def finite(items: dict) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in items.items()}

    summary = finite(summary)
    if "points" in summary:
        summary["points"] = [finite(p) for p in summary["points"]]
    folder.write_summary(summary)


def _write_failed(folder: RunFolder, err: SashilError, summary: dict) -> None:
    """The summary of a sweep that ended early (a link fault, a safety trip); the error is raised on.
    Bad input (a port that cannot be opened) writes nothing: the folder is removed as the error is reported."""
    if err.exit_code == ConfigError.exit_code:
        return
    _write_summary(folder, {"exit_status": status_of(err), "error": str(err), **summary})
    kept = "what was recorded is kept" if folder.recorded() else "nothing was recorded"
    print(f"run folder: {folder.path} (the sweep ended early; {kept})", file=sys.stderr)

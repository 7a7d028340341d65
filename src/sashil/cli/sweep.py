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
)
from sashil.cli.outputs import start_can_trace, write_formats
from sashil.control.registry import make_controller
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

    try:
        summary = _sweep(args, config, name, label, folder, live, rig_factory)
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


def _sweep(args, config, name, label, folder, live, rig_factory) -> dict:
    """Run the stepped sine or the chirp of ``config['sweep']``; returns the summary."""
    sweep = config["sweep"]
    f_start, f_stop, duration = sweep["f_start_hz"], sweep["f_stop_hz"], sweep["duration_s"]
    if sweep["stepped"]:
        freqs = frequencies(f_start, f_stop, sweep["steps"], sweep["spacing"])
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
            write_formats(args, sub.path, config, "sweep", cols, exit_status="ok", controller=label, frequency_hz=f)
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
        _plot(folder, points, label, config)
        integrated = math.sqrt(sum(p.body_rms_rad**2 for p in points) / len(points))
        print(f"integrated body RMS over the frequencies: {math.degrees(integrated):.4f} deg ({label})")
        summary: dict[str, Any] = {
            "exit_status": "ok",
            "driver": config["driver"]["name"],
            "mode": "stepped",
            "controller": label,
            "road": f"stepped sine {f_start:g}-{f_stop:g} Hz, {len(freqs)} steps, {sweep['amplitude_deg']:g} deg",
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
                chirp_profile(amplitude, f_start, f_stop, duration, sweep["ramp_s"]),
                total,
                rig_factory,
                keep=folder.write_data,
                data_path=folder.file(CYCLES_FILE),  # every cycle streamed as it runs
            )
        except SashilError as err:
            _write_failed(folder, err, {"mode": "chirp", "controller": label})
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
        summary = {
            "exit_status": "ok",
            "driver": config["driver"]["name"],
            "mode": "chirp",
            "controller": label,
            "road": f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s, {sweep['amplitude_deg']:g} deg",
            "body_rms_rad": ac_rms(body),
            "road_rms_rad": ac_rms(cols["theta_road_rad"]),
            "body_peak_rad": float(max(abs(body.max()), abs(body.min()))),
            "observer_nrmse": nrmse(cols["torque_hat_nm"], cols["torque_true_nm"]),
            "clipped_cycles": int(getattr(controller, "clip_count", 0)),
            "controller_stats": controller.stats() if hasattr(controller, "stats") else None,
        }
        print(
            f"chirp {f_start:g}-{f_stop:g} Hz over {duration:g} s ({label}): body RMS "
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

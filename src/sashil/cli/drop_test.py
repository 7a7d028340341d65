"""``sashil drop-test``: press the arm to theta0, release, record the free oscillation (seed 001 section 8)."""

from __future__ import annotations

import argparse
import logging
import math
import sys

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    current_in_range,
    open_rerun,
    option_or_config,
    positive_seconds,
    resolve_config,
    say,
    setup_logging,
)
from sashil.cli.outputs import start_can_trace, write_formats
from sashil.drivers import on_virtual_clock, open_rig
from sashil.errors import ConfigError
from sashil.experiments.drop_test import CONTROLLER_COLUMNS, DROP_COLUMNS, check_theta0, run_drop_test
from sashil.experiments.metrics import DropMetrics, damping_text, settling_text
from sashil.recording.plots import plot_drop_test
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_set import RunSet, ending
from sashil.runtime.runner import CYCLES_FILE

HELP = "drop test: hold the arm at theta0, release, record the free oscillation at constant current(s)"
EXAMPLE = "sashil drop-test --current 0 --current 1 --duration 10 --out runs/drop"

THETA0_LIMIT_DEG = 30.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--theta0-deg",
        type=float,
        metavar="DEG",
        help="hold angle before release [deg] (default drop_test.theta0_deg, -5)",
    )
    parser.add_argument(
        "--current",
        type=float,
        action="append",
        metavar="A",
        help="constant coil current [A], flowing before release; repeat for one sub-run each "
        "(default drop_test.currents_a, [0])",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="record length after release [s] (default drop_test.duration_s, 10)",
    )
    add_output_options(parser)
    add_recording_options(parser)
    add_verbosity_options(parser)


def _controller(config: dict) -> object | None:
    """The config's controller, which takes over at the release (None: the constant current)."""
    law = config["controller"]["law"]
    if law == "passive":
        return None
    from sashil.control.registry import make_controller

    return make_controller(law, config)


def _prompt(line: str) -> None:
    """Operator prompts and detections: shown even with --quiet (someone at the bench needs them)."""
    print(f"  {line}", file=sys.stderr, flush=True)


def _label(current: float) -> str:
    return f"i{current:.3f}A"


def resolve_drops(args: argparse.Namespace, config: dict) -> tuple[float, list[float], float]:
    """``(theta0_deg, currents, duration_s)`` from the options, else the config's ``drop_test``
    section; checked, and written back to it so that config.yaml says what ran."""
    section = config["drop_test"]
    duration, duration_name = option_or_config(args.duration, "--duration", config, "drop_test.duration_s")
    duration = positive_seconds(duration_name, duration)
    theta0, theta0_name = option_or_config(args.theta0_deg, "--theta0-deg", config, "drop_test.theta0_deg")
    if not (math.isfinite(theta0) and abs(theta0) <= THETA0_LIMIT_DEG):
        raise ConfigError(f"{theta0_name}: expected an angle within ±{THETA0_LIMIT_DEG:g} deg, got {theta0:g}")
    values, currents_name = option_or_config(args.current, "--current", config, "drop_test.currents_a")
    if not values:
        raise ConfigError(f"{currents_name}: expected at least one current, got []")
    currents = [current_in_range(currents_name, value, config) for value in values]
    if len(set(currents)) != len(currents):
        raise ConfigError(f"{currents_name}: each current once, got {currents}")
    section.update(theta0_deg=float(theta0), currents_a=currents, duration_s=duration)
    return float(theta0), currents, duration


def result_line(metrics: DropMetrics, duration_s: float) -> str:
    """One drop's period, first peaks, damping ratio and settling, as printed after it."""
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


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    config = resolve_config(args)
    theta0_deg, currents, duration = resolve_drops(args, config)
    check_theta0(config, theta0_deg)

    _controller(config)  # bad controller parameters fail here, before a folder exists
    folder = RunFolder.create(args.out, "drop-test")
    columns = DROP_COLUMNS + (CONTROLLER_COLUMNS if config["controller"]["law"] != "passive" else ())
    live = open_rerun(args, columns, "sashil drop-test", folder.path)
    live_offset_s = 0.0
    folder.write_config(config)
    law = config["controller"]["law"]
    runs = RunSet(
        folder,
        "drop-test",
        {
            "driver": config["driver"]["name"],
            "controller": law if law != "passive" else "passive (constant current per run)",
            "clock": "virtual" if on_virtual_clock(config) else "real",  # timing is simulated on the virtual clock
        },
        several=len(currents) > 1,
    )
    overlay = []
    for current in currents:
        label = f"{law} (from {current:g} A until the release)" if law != "passive" else f"passive {current:g} A"
        say(args, f"drop test from {theta0_deg:g} deg, {label} ...")
        target = runs.folder_for(_label(current))
        rig = open_rig(config)
        trace = start_can_trace(args, rig, target.path)
        try:
            record = run_drop_test(
                config,
                theta0_deg,
                current,
                duration,
                rig=rig,
                controller=_controller(config),
                notify=_prompt,
                data_path=target.file(CYCLES_FILE),  # every cycle streamed as it runs (the hold too)
            )
        finally:
            trace_stats = trace.close() if trace is not None else None
        if runs.several:  # the sub-folder's config reruns its one drop
            target.write_config({**config, "drop_test": {**config["drop_test"], "currents_a": [current]}})
        target.write_data(record.columns)
        assert record.metrics is not None and record.loop is not None  # run_drop_test sets both
        write_formats(
            args,
            target.path,
            config,
            "drop-test",
            record.columns,
            exit_status=ending(record.error)["exit_status"],
            current_a=current,
            controller=label,
        )
        if live is not None:
            live.note(
                live_offset_s,
                f"drop test from {theta0_deg:g} deg at {current:g} A (release at t = {live_offset_s:g} s)",
            )
            live.log_columns(record.columns, live_offset_s)
            live_offset_s += duration + 1.0
        entry = runs.add(
            _label(current),
            {
                "current_a": current,
                "controller": label,
                "theta0_deg": theta0_deg,
                "hold_angle_deg": math.degrees(record.hold_angle_rad),
                "release_estimated": record.release_estimated,
                **record.metrics.as_dict(),
                "timing": record.loop.timing.summary() if record.loop.timing is not None else None,
                "trips": record.loop.trips,
                "link": record.extra.get("link"),
                "realtime": record.extra.get("realtime"),
                "can_trace": trace_stats,
            },
            record.error,
        )
        if runs.failed:
            overlay.append({**entry, **record.columns, "label": f"{label} (stopped)"})
            break
        overlay.append({**entry, **record.columns, "label": label})
        say(args, "  " + result_line(record.metrics, duration))
        for note in result_warnings(record.metrics):
            logging.getLogger("sashil").warning("drop test at %g A: %s", current, note)
    under = f", under {law}" if law != "passive" else ""
    plot = plot_drop_test(
        folder.file("drop_test.png"),
        overlay,
        f"Drop test from {theta0_deg:g}°{under} ({config['driver']['name']} rig)",
        band_deg=config["drop_test"]["settle_band_deg"],
    )
    if live is not None:
        live.close()
    runs.finish()
    print(f"run folder: {folder.path} (plot {plot.name})", file=sys.stderr)
    if runs.error is not None:
        raise runs.error  # one line and its exit code from the CLI; the data up to it is on disk
    return 0

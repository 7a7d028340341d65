"""``sashil run``: closed loop with the configured backend on the real clock, into a run folder."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    current_in_range,
    open_live_tap,
    positive_seconds,
    resolve_config,
    say,
    setup_logging,
)
from sashil.cli.outputs import finish_loop_run, start_can_trace
from sashil.config.sections import LOOP
from sashil.drivers import open_rig
from sashil.drivers.interface import capabilities_of
from sashil.errors import ConfigError, SashilError
from sashil.experiments.road_option import DEFAULT_SIM_ROAD, RoadStage, parse_road
from sashil.experiments.road_option import SYNTAX as ROAD_SYNTAX
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_progress import RunProgress, SessionHooks
from sashil.runtime.clock import RealClock
from sashil.runtime.loop import record_columns
from sashil.runtime.session import run_session
from sashil.runtime.stages import ConstantCurrent
from sashil.runtime.timing import format_timing

HELP = "run the rig in closed loop at a fixed rate (real clock), recording data.csv and timing"
EXAMPLE = "sashil run --duration 10 --controller passive --current 0.5 --out runs/passive-0.5A"

#: highest loop rate each backend supports when the backend does not say (``max_rate_hz``)
DEFAULT_MAX_RATE_HZ = {"sim": 10_000.0}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument("--duration", type=float, metavar="S", help="seconds to run (default: until Ctrl-C / SIGTERM)")
    parser.add_argument("--rate", type=float, metavar="HZ", help="loop rate (default: loop.rate_hz, 1000)")
    parser.add_argument(
        "--controller",
        metavar="NAME",
        help="controller (default: the config's controller section, else passive)",
    )
    parser.add_argument("--current", type=float, metavar="A", help="coil current of the passive controller (default 0)")
    parser.add_argument(
        "--road",
        metavar="SPEC",
        help=f"road excitation theta1(t): {ROAD_SYNTAX} (default on the sim backend: {DEFAULT_SIM_ROAD}, else none)",
    )
    add_output_options(parser)
    add_recording_options(parser)
    add_verbosity_options(parser)


def backend_max_rate_hz(rig: Any, backend: str) -> float | None:
    """What the backend declares (``capabilities.max_rate_hz``), else DEFAULT_MAX_RATE_HZ (before it is opened)."""
    value = capabilities_of(rig).max_rate_hz if rig is not None else None
    if value is None:
        value = DEFAULT_MAX_RATE_HZ.get(backend)
    return None if value is None else float(value)


def check_rate(rate: float, rig: Any, backend: str) -> float:
    """``rate`` if the loop and the backend (``rig``'s ``max_rate_hz``, or the backend's default;
    ``rig`` None: before it is opened) can run at it; ConfigError naming --rate otherwise."""
    if not (math.isfinite(rate) and rate > 0):
        raise ConfigError(f"--rate: expected a loop rate in Hz > 0, got {rate:g}")
    limit = backend_max_rate_hz(rig, backend)
    if limit is not None and rate > limit:
        raise ConfigError(f"--rate: {rate:g} Hz is above what the {backend} backend can do ({limit:g} Hz)")
    top = LOOP.fields["rate_hz"].high
    if rate > top:
        raise ConfigError(f"--rate: {rate:g} Hz is above the loop's limit ({top:g} Hz, loop.rate_hz)")
    return float(rate)


def _registry_make_controller() -> Any:
    try:
        from sashil.control.registry import make_controller
    except ModuleNotFoundError as err:
        if err.name not in ("sashil.control", "sashil.control.registry"):
            raise
        return None
    return make_controller


def build_stage(name: str | None, config: dict[str, Any], current: float | None) -> tuple[str, Any]:
    """The loop stage for ``--controller``/``--current`` (passive: a constant current)."""
    section = config.get("controller")
    if name is None:
        name = section.get("law", "passive") if isinstance(section, dict) and current is None else "passive"
    if current is not None and name != "passive":
        raise ConfigError(f"--current: only for --controller passive (got --controller {name})")
    if name == "passive":
        configured = section.get("current_a", 0.0) if isinstance(section, dict) else 0.0
        value = current_in_range(
            "--current" if current is not None else "controller.current_a",
            configured if current is None else current,
            config,
        )
        return f"passive {value:g} A", ConstantCurrent(value)
    make_controller = _registry_make_controller()
    if make_controller is None:
        raise ConfigError(f"--controller: unknown controller {name!r} (known: passive)")
    return name, make_controller(name, config)


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    config = resolve_config(args)
    duration = None if args.duration is None else positive_seconds("--duration", args.duration)
    backend = config["driver"]["name"]
    # the rate first: the controller's estimator gains and the device's Configure both use it
    config["loop"]["rate_hz"] = check_rate(config["loop"]["rate_hz"] if args.rate is None else args.rate, None, backend)
    label, stage = build_stage(args.controller, config, args.current)
    road, road_text = parse_road(args.road or (DEFAULT_SIM_ROAD if backend == "sim" else None), config)
    if backend == "sim" and road is not None:
        from sashil.models.mismatch import open_sim_rig

        rig = open_sim_rig(config, road)  # the plant's road angle follows the profile
    else:
        rig = open_rig(config)
        if road is not None:
            stage = RoadStage(stage, road)  # the rig's road motor gets the profile's speed
    try:  # the device's own limit, now that it is open (nothing configured or energised yet)
        rate = check_rate(config["loop"]["rate_hz"], rig, backend)
    except ConfigError:
        rig.close()
        raise
    config["driver"]["clock"] = "real"  # `sashil run` always runs on the real clock
    folder = RunFolder.create(args.out, "run")
    live = open_live_tap(args, config, record_columns(stage), "sashil run", folder.path)
    if not args.quiet:  # progress of the run on stderr (a bar on a terminal, a line every 10 s otherwise)
        live = SessionHooks(live, RunProgress(duration, rate))
    clock = RealClock.for_rate(config["loop"]["spin_margin_us"], rate)
    say(
        args,
        f"sashil run: {backend} backend, {label}, road {road_text}, {rate:g} Hz, "
        f"{'until stopped' if duration is None else f'{duration:g} s'} -> {folder.path}",
    )
    quiet = bool(args.quiet)  # --quiet: warnings (overruns) only, not the real-time set-up lines
    report = lambda line: None if quiet and line.startswith("realtime:") else print(line, file=sys.stderr, flush=True)  # noqa: E731
    trace = start_can_trace(args, rig, folder.path)
    try:
        outcome = run_session(config, rig, stage, folder, clock, duration, controller=label, live=live, say=report)
    finally:
        trace_stats = trace.close() if trace is not None else None
    if isinstance(outcome.error, SashilError) and outcome.error.exit_code == ConfigError.exit_code:
        raise outcome.error  # bad input (a port that cannot be opened): nothing ran, the folder is removed
    finish_loop_run(args, folder, config, outcome.summary, trace_stats, road=road_text)
    say(args, format_timing(outcome.summary["timing"]))
    for trip in outcome.summary["trips"]:
        print(f"safety trip at {trip['time_s']:.3f} s: {trip['reason']}", file=sys.stderr)
    print(f"run folder: {folder.path}", file=sys.stderr)
    error = outcome.error
    if outcome.result.exit_status == "stopped":
        print(f"sashil run: stopped by {outcome.result.stop_reason}; damper at 0 A", file=sys.stderr)
    if error is None or isinstance(error, KeyboardInterrupt):
        return outcome.exit_code
    if isinstance(error, SashilError):
        raise error  # one line and the error's exit code (sashil.cli.main)
    print(f"sashil run: error: {type(error).__name__}: {error} (the damper was set to 0 A first)", file=sys.stderr)
    return outcome.exit_code

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
    law_help,
    open_live_tap,
    option_or_config,
    positive_seconds,
    resolve_config,
    say,
    select_law,
    setup_logging,
)
from sashil.cli.outputs import finish_loop_run, start_can_trace
from sashil.config.sections import LOOP
from sashil.drivers import open_rig
from sashil.drivers.interface import capabilities_of
from sashil.errors import ConfigError, SashilError
from sashil.experiments.road_option import DEFAULT_SIM_ROAD, RoadStage, parse_road
from sashil.experiments.road_option import SYNTAX as ROAD_SYNTAX
from sashil.models.plant import RoadProfile
from sashil.recording.run_folder import RunFolder
from sashil.recording.run_progress import RunProgress, SessionHooks
from sashil.runtime.clock import RealClock
from sashil.runtime.loop import record_columns
from sashil.runtime.session import run_session
from sashil.runtime.stages import ConstantCurrent
from sashil.runtime.timing import format_timing

HELP = "run the rig in closed loop at a fixed rate (real clock), recording data.csv and timing"
EXAMPLE = "sashil run --duration 10 --controller passive --current 0.5 --out runs/passive-0.5A"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="seconds to run (default: run.duration_s, null: until Ctrl-C / SIGTERM)",
    )
    parser.add_argument("--rate", type=float, metavar="HZ", help="loop rate (default: loop.rate_hz, 1000)")
    parser.add_argument(
        "--controller",
        metavar="LAW",
        help=f"semi-active law ({law_help()}); default controller.law",
    )
    parser.add_argument(
        "--current",
        type=float,
        metavar="A",
        help="coil current of the passive controller (default controller.current_a, 0)",
    )
    parser.add_argument(
        "--road",
        metavar="SPEC",
        help=f"road excitation theta1(t): {ROAD_SYNTAX} "
        f"(default run.road, else on the sim backend {DEFAULT_SIM_ROAD}, else none)",
    )
    add_output_options(parser)
    add_recording_options(parser)
    add_verbosity_options(parser)


def check_rate(rate: float, rig: Any) -> float:
    """``rate`` (> 0) if the loop and ``rig``'s backend (its declared ``max_rate_hz``) can run at
    it; ConfigError naming --rate otherwise."""
    limit = capabilities_of(rig).max_rate_hz
    if limit is not None and rate > limit:
        name = getattr(rig, "name", type(rig).__name__)
        raise ConfigError(f"--rate: {rate:g} Hz is above what the {name} backend can do ({limit:g} Hz)")
    top = LOOP.fields["rate_hz"].high
    if rate > top:
        raise ConfigError(f"--rate: {rate:g} Hz is above the loop's limit ({top:g} Hz, loop.rate_hz)")
    return float(rate)


def build_stage(name: str | None, config: dict[str, Any], current: float | None) -> tuple[str, Any]:
    """The loop stage for ``--controller``/``--current``, with both written into ``config['controller']``
    (the built-in passive law runs as a constant current: no estimator or observer needed)."""
    if current is not None:
        if name is not None and name != "passive":
            raise ConfigError(f"--current: only for --controller passive (got --controller {name})")
        name = "passive"
    name = select_law(config, name)
    if current is not None:
        config["controller"]["current_a"] = current_in_range("--current", current, config)
    if name == "passive":
        from sashil.control.law_config import law_context
        from sashil.control.laws import Passive

        law = Passive(law_context(config), current_a=float(config["controller"]["current_a"]))
        return f"passive {law.current_a:g} A", ConstantCurrent(law=law)
    from sashil.control.registry import make_controller

    return name, make_controller(name, config)


def resolve_road(option: str | None, config: dict[str, Any], simulated: bool) -> tuple[RoadProfile | None, str]:
    """The road of ``--road``, else ``run.road``, else the backend's default (a sine on a simulated
    rig, none on hardware); the spec that runs is written to ``run.road`` (``none`` for no road),
    so the config reruns the same excitation."""
    spec = option or config["run"]["road"] or (DEFAULT_SIM_ROAD if simulated else "none")
    try:
        road, text = parse_road(spec, config)
    except ConfigError as err:
        if option is not None:
            raise
        raise ConfigError(str(err).replace("--road", "run.road", 1)) from None
    config["run"]["road"] = spec
    return road, text


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    config = resolve_config(args)
    duration, duration_name = option_or_config(args.duration, "--duration", config, "run.duration_s")
    duration = config["run"]["duration_s"] = None if duration is None else positive_seconds(duration_name, duration)
    backend = config["driver"]["name"]
    # the rate first: the controller's estimator gains and the device's Configure both use it
    rate = float(config["loop"]["rate_hz"] if args.rate is None else args.rate)
    if not (math.isfinite(rate) and rate > 0):
        raise ConfigError(f"--rate: expected a loop rate in Hz > 0, got {rate:g}")
    config["loop"]["rate_hz"] = rate
    rig = open_rig(config)  # built, not opened: its declared capabilities (rate limit, simulated)
    try:
        check_rate(rate, rig)
        label, stage = build_stage(args.controller, config, args.current)
        road, road_text = resolve_road(args.road, config, capabilities_of(rig).simulated)
        if road is not None:
            stage = RoadStage(stage, road)  # the rig's road motor gets the profile's speed
        # open the port and greet the board now (configure is idempotent; the loop's own call finds
        # it done): a port that cannot be opened is one line, before any set-up, output or folder
        rig.configure()
    except BaseException:
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
        outcome = run_session(
            config, rig, stage, folder, clock, duration, controller=label, live=live, say=report, tune=True
        )
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

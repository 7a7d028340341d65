"""``sashil run``: closed loop with the configured backend on the real clock, into a run folder."""

from __future__ import annotations

import argparse

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    config_source,
    law_help,
    outputs_of,
    setup_logging,
)
from sashil.errors import ConfigError
from sashil.roads.syntax import DEFAULT_SIM_ROAD
from sashil.roads.syntax import SYNTAX as ROAD_SYNTAX

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
        help=f"road excitation theta1(t): {ROAD_SYNTAX} (default run.road, else on the sim backend {DEFAULT_SIM_ROAD}, else none)",
    )
    add_output_options(parser)
    add_recording_options(parser)
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    from sashil.runtime.loop_process import start_ahead

    setup_logging(args)
    start_ahead()  # the loop server imports and warms up while the config is resolved here
    return _run(args)


def _run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.engine.sashil_run import closed_loop

    if args.current is not None:
        if args.controller not in (None, "passive"):
            raise ConfigError(f"--current: only for --controller passive (got --controller {args.controller})")
        args.controller = "passive"
    options = (
        Option("--duration", "run.duration_s", args.duration),
        Option("--rate", "loop.rate_hz", args.rate),
        Option("--current", "controller.current_a", args.current),
        Option("--road", "run.road", args.road),
    )
    config = resolve(config_source(args, options), "run")
    run = closed_loop(config, outputs_of(args), printer(quiet=args.quiet), progress=not args.quiet)
    return int(run.summary.get("exit_code", 0))

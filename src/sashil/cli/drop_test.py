"""``sashil drop-test``: press the arm to theta0, release, record the free oscillation (seed 001 section 8)."""

from __future__ import annotations

import argparse

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    config_source,
    outputs_of,
    setup_logging,
)

EXAMPLE = "sashil drop-test --current 0 --current 1 --duration 10 --out runs/drop"


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


def run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.lab._drop_test import drop_test

    setup_logging(args)
    options = (
        Option("--theta0-deg", "drop_test.theta0_deg", args.theta0_deg),
        Option("--current", "drop_test.currents_a", args.current),
        Option("--duration", "drop_test.duration_s", args.duration),
    )
    config = resolve(config_source(args, options), "drop-test")
    drop_test(config, outputs_of(args), printer(quiet=args.quiet))
    return 0

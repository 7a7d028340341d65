"""``sashil calibrate``: from an unknown damper to a validated model, over any link."""

from __future__ import annotations

import argparse

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_verbosity_options,
    config_source,
    outputs_of,
    setup_logging,
)

EXAMPLE = "sashil calibrate --driver serial --port /dev/ttyACM0 --inertia 0.95 --out runs/cal"

MODEL_CHOICES = ("bouc-wen", "dahl", "lugre", "bingham", "all")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)  # the config's calibrate: section is the plan; --params: the simulated rig's damper
    add_driver_options(parser)
    parser.add_argument(
        "--inertia",
        type=float,
        metavar="J",
        help="the arm's inertia J [kg m^2] (datasheet; default calibrate.inertia_kg_m2); "
        "without it every torque is relative to J = 1",
    )
    parser.add_argument("--model", choices=MODEL_CHOICES, help="model to fit (override calibrate.model); all: ranked")
    parser.add_argument(
        "--no-profile",
        action="store_true",
        help="skip the profile of the Bouc-Wen exponent n (a few seconds; calibrate.profile_n: false)",
    )
    parser.add_argument(
        "--extra-steps",
        type=int,
        metavar="N",
        help="after the plan, run the N extra steps the report suggests (those that shrink the widest "
        "interval most) and refit with them (calibrate.extra_steps; default 0)",
    )
    add_output_options(parser)
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.lab._calibrate import calibrate

    setup_logging(args)
    options = (
        Option("--inertia", "calibrate.inertia_kg_m2", args.inertia),
        Option("--model", "calibrate.model", args.model),
        Option("--no-profile", "calibrate.profile_n", False if args.no_profile else None),
        Option("--extra-steps", "calibrate.extra_steps", args.extra_steps),
    )
    config = resolve(config_source(args, options), "calibrate")
    run = calibrate(config, outputs_of(args), printer(quiet=args.quiet), source=args.config or "config")
    return int(run.summary.get("exit_code", 0))

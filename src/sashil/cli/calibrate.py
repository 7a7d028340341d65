"""``sashil calibrate``: from an unknown damper to a validated model, over any link."""

from __future__ import annotations

import argparse
import math
import sys

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_verbosity_options,
    resolve_config,
    say,
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
    from sashil.calibrate.session import calibrate_rig, check_inertia
    from sashil.errors import ConfigError

    setup_logging(args)
    check_inertia(args.inertia)  # before the config: a bad number is the first thing to say
    config = resolve_config(args)
    section = config["calibrate"]  # the options land in the config (config.yaml says what ran)
    if args.inertia is not None:
        section["inertia_kg_m2"] = float(args.inertia)
    if args.model is not None:
        section["model"] = args.model
    if args.no_profile:
        section["profile_n"] = False
    if args.extra_steps is not None:
        if not 0 <= args.extra_steps <= 9:
            raise ConfigError(f"--extra-steps: expected 0 to 9 extra steps, got {args.extra_steps}")
        section["extra_steps"] = args.extra_steps
    inertia = section["inertia_kg_m2"]
    outcome = calibrate_rig(
        config,
        args.out,
        inertia=inertia,
        say=lambda text: say(args, text),
        source=args.config or "config",
        profile=section["profile_n"],
    )
    cal = outcome.calibration
    best = cal.best
    if inertia is None:
        print("all torques are relative to J = 1 (no --inertia): multiply them by the rig's J")
    held = ", ".join(f"{v.name} {100 * v.nrmse:.2f} %" for v in cal.validations) or "none (no held-out runs)"
    print(f"model {best.model}: fit RMS {math.degrees(best.rms_total):.4f} deg; held-out NRMSE: {held}")
    print(f"rig time {outcome.rig_s:.0f} s, fit {cal.fit_s:.1f} s; {best.convergence.get('message', '')}")
    print(f"wrote {outcome.params_path} and {outcome.report_path}")
    print(f"calibration folder: {outcome.folder}", file=sys.stderr)
    return 0

"""``sashil simulate``: run a parameter file's model on recorded inputs or a drop test, write a run folder."""

from __future__ import annotations

import argparse

from sashil.cli.common import add_config_options, add_output_options, config_source, outputs_of

EXAMPLE = "sashil simulate --params params.yaml --input runs/a/data.csv --out runs/sim-a"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_output_options(parser)
    parser.add_argument(
        "--input",
        metavar="CSV|RUN",
        help="a data.csv or a run folder (its data.csv); inputs: time_s, current_a (or current_cmd_a), optional "
        "theta_road_rad, torque_in_nm; theta_rad gives the initial angle and is compared (default simulate.input)",
    )
    parser.add_argument(
        "--theta0-deg", type=float, help="drop test without --input: initial angle (default simulate.theta0_deg, -5)"
    )
    parser.add_argument(
        "--current", type=float, help="drop test without --input: coil current [A] (default simulate.current_a, 0)"
    )
    parser.add_argument(
        "--duration", type=float, help="drop test without --input: seconds (default simulate.duration_s, 10)"
    )
    parser.add_argument(
        "--start", choices=("rest", "moving"), help="the input starts at rest or moving (default simulate.start, rest)"
    )


def run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.lab._simulate import simulate
    from sashil.models.registry import MODEL_PARAMS

    options = (
        Option("--input", "simulate.input", args.input),
        Option("--theta0-deg", "simulate.theta0_deg", args.theta0_deg),
        Option("--current", "simulate.current_a", args.current),
        Option("--duration", "simulate.duration_s", args.duration),
        Option("--start", "simulate.start", args.start),
    )
    config = resolve(config_source(args, options), "simulate", models=tuple(MODEL_PARAMS))
    run = simulate(config, outputs_of(args), printer())
    return int(run.summary.get("exit_code", 0))

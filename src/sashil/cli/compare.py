"""``sashil compare``: several laws on the same road, one table (compare.md, metrics.csv, compare.png),
and each law's run in a folder of its own.

Each ``--controller`` (a law name, ``package.module:Class`` or ``path/file.py:Class``; repeatable)
runs on the same road beside the passive damper at 0 A and at i_max, which are always included
(:func:`sashil.lab._compare.compare`). ``--set controller.<p>=v`` goes to every compared law that
declares ``p``; every other ``--set``, ``--road``, ``--duration`` and ``--jobs`` go into the config.
"""

from __future__ import annotations

import argparse

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_verbosity_options,
    config_source,
    law_help,
    outputs_of,
    setup_logging,
)
from sashil.roads.syntax import SYNTAX as ROAD_SYNTAX

EXAMPLE = "sashil compare --road iso8608:C --duration 30 --controller skyhook-add --controller clipped-optimal"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--controller",
        action="append",
        default=[],
        dest="laws",
        metavar="LAW",
        help="a law to compare (repeatable; passive at 0 A and at i_max are always included; none: the config's own "
        f"law, so a compared law's config.yaml compares it again): {law_help()}",
    )
    parser.add_argument(
        "--road", metavar="SPEC", help=f"the road every law runs on: {ROAD_SYNTAX} (default compare.road, iso8608:C)"
    )
    parser.add_argument("--duration", type=float, metavar="S", help="seconds per law (default compare.duration_s, 30)")
    parser.add_argument(
        "--jobs", type=int, metavar="N", help="simulated rig: laws in N processes (default compare.jobs)"
    )
    add_output_options(parser)
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.lab._compare import compare, laws_of, split_sets

    setup_logging(args)
    base_sets, law_sets = split_sets(list(args.overrides))
    options = (
        Option("--road", "compare.road", args.road),
        Option("--duration", "compare.duration_s", args.duration),
        Option("--jobs", "compare.jobs", args.jobs),
    )
    args.overrides = base_sets  # the laws' own parameters go to the laws, not the config
    config = resolve(config_source(args, options), "compare")
    run = compare(config, laws_of(list(args.laws), law_sets), outputs_of(args), printer(quiet=args.quiet))
    return int(run.summary.get("exit_code", 0))

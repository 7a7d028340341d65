"""``sashil replay``: a recorded run's sensor stream through a law, offline (open loop)."""

from __future__ import annotations

import argparse

from sashil.cli.common import add_config_options, add_output_options, config_source, law_help, outputs_of

EXAMPLE = "sashil replay runs/bench-skyhook --controller groundhook --set controller.c_ground=2"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_folder", metavar="RUN_FOLDER", help="a run folder with data.csv (from sashil run)")
    parser.add_argument("--controller", metavar="LAW", help=f"the law to replay ({law_help()}); default: the run's")
    add_config_options(parser)
    add_output_options(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from sashil.engine.events import printer
    from sashil.engine.resolve import resolve
    from sashil.lab._replay import recorded_config, replay

    own = recorded_config(args.run_folder)  # a run folder to replay, checked before anything else
    source = config_source(args)
    config = resolve(replace(source, config=source.config or str(own)), "replay")
    run = replay(config, args.run_folder, outputs_of(args), printer(quiet=args.quiet))
    return int(run.summary.get("exit_code", 0))

"""``sashil report``: plots and a side-by-side Markdown summary of one or more run folders."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sashil.cli.common import add_output_options, add_verbosity_options, say
from sashil.recording.matlab import export_mat
from sashil.recording.report import write_report
from sashil.recording.run_folder import RunFolder

HELP = "report on run folders: θ(t) overlays, hysteresis loops, transmissibility, timing, report.md"
EXAMPLE = "sashil report runs/drop-0A runs/drop-1A --out runs/compare"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folders written by sashil verbs")
    add_output_options(parser)
    parser.add_argument(
        "--format",
        action="append",
        choices=("mat",),
        metavar="FMT",
        help="also export each run's data.csv files: mat (MATLAB data.mat beside each data.csv)",
    )
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    progress = lambda line: say(args, f"sashil report: {line}")  # noqa: E731
    # read everything before creating the output folder: bad input leaves nothing behind
    from sashil.recording.report import load_run

    for run_dir in args.run_dirs:
        load_run(run_dir)
    folder = RunFolder.create(args.out, "report")
    _runs, files = write_report(args.run_dirs, folder.path, progress)
    if "mat" in (args.format or ()):
        for run_dir in args.run_dirs:
            for data in sorted(Path(run_dir).rglob("data.csv")):
                progress(f"wrote {export_mat(data)}")
    for path in files:
        say(args, f"  {path}")
    print(f"report: {folder.path / 'report.md'}", file=sys.stderr)
    return 0

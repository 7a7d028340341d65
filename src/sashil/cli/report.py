"""``sashil report``: plots and a side-by-side Markdown summary of one or more run folders."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sashil.cli.common import add_output_options, add_verbosity_options, say

EXAMPLE = "sashil report runs/drop-0A runs/drop-1A --out runs/compare"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folders written by sashil verbs")
    add_output_options(parser)
    parser.add_argument(
        "--format",
        action="append",
        choices=("mat", "parquet"),
        metavar="FMT",
        help="also export each run's data.csv files: mat (MATLAB data.mat) or parquet (data.parquet, units "
        "and the run's config.yaml in its metadata) beside each data.csv; repeatable",
    )
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    from sashil.api import load_run as load_run_api
    from sashil.lab.report import write_report
    from sashil.recording.formats import check_formats, write_data_formats
    from sashil.recording.matlab import export_mat
    from sashil.writer.run_folder import RunFolder

    progress = lambda line: say(args, f"sashil report: {line}")  # noqa: E731
    # read everything before creating the output folder: bad input leaves nothing behind
    from sashil.lab.report import read_record

    for run_dir in args.run_dirs:
        read_record(run_dir)
    check_formats(args.format, None)  # a missing library is named before anything is written
    folder = RunFolder.create(args.out, "report")
    _runs, files = write_report(args.run_dirs, folder.path, progress)
    formats = args.format or ()
    for run_dir in args.run_dirs if formats else ():
        for data in sorted(Path(run_dir).rglob("data.csv")):
            if "mat" in formats:
                progress(f"wrote {export_mat(data)}")
            if "parquet" in formats:
                run = load_run_api(data.parent)
                meta = {"verb": run.summary.get("verb"), "controller": run.summary.get("controller")}
                for path in write_data_formats(data.parent, ["parquet"], None, meta):
                    progress(f"wrote {path}")
    for path in files:
        say(args, f"  {path}")
    print(f"report: {folder.path / 'report.md'}", file=sys.stderr)
    return 0

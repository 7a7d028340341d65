"""``sashil identify``: fit Bouc-Wen, Dahl, LuGre or Bingham to recorded runs, write the parameter file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sashil.errors import ConfigError

HELP = "identify the damper model from recorded runs and write a parameter file"
EXAMPLE = "sashil identify runs/a/data.csv runs/b/data.csv --model all --out params.yaml"

MODEL_CHOICES = ("bouc-wen", "dahl", "lugre", "bingham", "all")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "runs",
        nargs="+",
        metavar="RUN",
        help="data.csv files, run folders, or folders of runs (a multi-current drop test: every sub-run)",
    )
    parser.add_argument("--model", choices=MODEL_CHOICES, default="bouc-wen", help="model to fit, or all to rank them")
    parser.add_argument("--out", metavar="FILE", default="params.yaml", help="parameter file to write (best model)")
    parser.add_argument(
        "--passive", action="store_true", help="runs at one current: fix the current terms (c2, alpha2, ...) at 0"
    )
    parser.add_argument(
        "--two-stage", action="store_true", help="seed 000 procedure: linear part with Coulomb friction first"
    )
    parser.add_argument("--inertia", type=float, default=1.0, metavar="J", help="arm inertia J (fixed; default 1)")
    parser.add_argument(
        "--start",
        choices=("rest", "moving"),
        default="rest",
        help="runs start at rest (drop tests) or moving (v0 from the first 20 ms)",
    )
    parser.add_argument(
        "--delta",
        type=float,
        metavar="VALUE",
        help="write Bouc-Wen with this delta (z scale) instead of the unit z bound",
    )
    parser.add_argument("--plot", metavar="PNG", help="overlay plot (default: next to --out, *_fit.png)")
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of --two-stage's genetic search (the default search is deterministic)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def data_paths(run: str) -> list[Path]:
    """The data.csv files of a RUN argument: a file itself, a run folder's data.csv, or every
    data.csv in the sub-folders of a folder without one (a multi-current drop test's ``i0.000A/``,
    ``i1.000A/``, ...; a calibration's runs), in name order."""
    path = Path(run)
    if not path.is_dir():
        return [path]
    if (path / "data.csv").is_file():
        return [path / "data.csv"]
    found = sorted(path.glob("*/data.csv")) or sorted(path.glob("*/*/data.csv"))
    return found or [path / "data.csv"]  # the last: "no such file" from the data loader


def run(args: argparse.Namespace) -> int:
    from sashil.identify.data import load_records
    from sashil.identify.fit import FitOptions, fit_model
    from sashil.identify.report import (
        comparison_table,
        format_result,
        overlay_plot,
        param_document,
        ranked,
        write_params,
    )

    if not (args.inertia > 0):
        raise ConfigError(f"--inertia: expected J > 0, got {args.inertia:g}")
    if args.delta is not None and not (args.delta > 0):
        raise ConfigError(f"--delta: expected a number > 0, got {args.delta:g}")
    out = Path(args.out)
    if not out.parent.exists():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist")
    records = load_records(
        [p for r in args.runs for p in data_paths(r)],
        need_current_change=not args.passive,
        start_at_rest=args.start == "rest",
    )
    names = ["bouc-wen", "dahl", "lugre", "bingham"] if args.model == "all" else [args.model]
    options = FitOptions(
        passive=args.passive,
        two_stage=args.two_stage,
        J=args.inertia,
        seed=args.seed,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    results = []
    for name in names:
        result = fit_model(name, records, options)
        results.append(result)
        print(format_result(result))
    best = ranked(results)[0]
    if len(results) > 1:
        print("\ncomparison (ranked by output-error RMS of theta):")
        print(comparison_table(results))
    write_params(out, param_document(best, args.delta))
    print(f"wrote {out} (model {best.model})")
    for r in results:
        if r is not best:
            other = out.with_name(f"{out.stem}.{r.model}{out.suffix or '.yaml'}")
            write_params(other, param_document(r, args.delta))
            print(f"wrote {other}")
    plot = Path(args.plot) if args.plot else out.with_name(f"{out.stem}_fit.png")
    overlay_plot(results, records, plot)
    print(f"wrote {plot}")
    return 0

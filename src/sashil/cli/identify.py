"""``sashil identify``: fit Bouc-Wen, Dahl, LuGre or Bingham to recorded runs, write the parameter file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sashil.errors import ConfigError

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
    parser.add_argument(
        "--out",
        metavar="FILE",
        default="params.yaml",
        help="parameter file to write (best model; default ./params.yaml); its folder is created",
    )
    parser.add_argument(
        "--force", action="store_true", help="overwrite files that exist (the parameter files, the plot)"
    )
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
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


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


def output_paths(out: Path, names: list[str], plot: str | None) -> list[Path]:
    """Every file identify may write: ``out``, with several models each model's
    ``<stem>.<model>.yaml`` beside it (the ones not ranked best), and the overlay plot."""
    others = [out.with_name(f"{out.stem}.{name}{out.suffix or '.yaml'}") for name in names] if len(names) > 1 else []
    return [out, *others, plot_path(out, plot)]


def plot_path(out: Path, plot: str | None) -> Path:
    """``--plot``, else ``<stem>_fit.png`` beside ``out``."""
    return Path(plot) if plot else out.with_name(f"{out.stem}_fit.png")


def check_outputs(paths: list[Path], force: bool) -> None:
    """ConfigError naming the first of ``paths`` that is a folder, or that exists (nothing is
    overwritten without ``--force``)."""
    for path in paths:
        if path.is_dir():
            raise ConfigError(f"{path}: is a folder (give a file name, e.g. --out {path / 'params.yaml'})")
        if path.exists() and not force:
            raise ConfigError(f"{path}: exists; add --force to overwrite it, or choose another --out")


def make_folders(paths: list[Path]) -> None:
    """Create the folders ``paths`` go into (ConfigError naming the one that cannot be made)."""
    for path in paths:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ConfigError(f"--out {path}: cannot create folder {path.parent} ({err.strerror})") from None


#: the intervals' jackknife block length [s] (shortened for short records, as in calibrate)
BLOCK_S = 2.0


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from sashil.identify.data import load_records
    from sashil.identify.fit import FitOptions, fit_model, initial_angle_tolerance
    from sashil.identify.intervals import interval_blocks, jackknife
    from sashil.identify.report import (
        comparison_table,
        format_intervals,
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
    names = ["bouc-wen", "dahl", "lugre", "bingham"] if args.model == "all" else [args.model]
    targets = output_paths(out, names, args.plot)
    check_outputs(targets, args.force)
    records = load_records(
        [p for r in args.runs for p in data_paths(r)],
        need_current_change=not args.passive,
        start_at_rest=args.start == "rest",
    )
    options = FitOptions(
        passive=args.passive,
        two_stage=args.two_stage,
        J=args.inertia,
        seed=args.seed,
        progress=not args.quiet and sys.stderr.isatty(),
        initial_angle_tolerance_rad=initial_angle_tolerance(records),
    )
    results = []
    intervals = {}
    current_max = max(float(np.max(r.current)) for r in records)
    for name in names:
        result = fit_model(name, records, options)
        results.append(result)
        print(format_result(result))
        block = interval_blocks(records, BLOCK_S, result.model_free)
        intervals[name] = jackknife(result, records, current_max, block)
        print(format_intervals(intervals[name]))
    best = ranked(results)[0]
    if len(results) > 1:
        print("\ncomparison (ranked by output-error RMS of theta):")
        print(comparison_table(results))
    make_folders(targets)
    write_params(out, param_document(best, args.delta, intervals[best.model]))
    print(f"wrote {out.resolve()} (model {best.model})")
    for r in results:
        if r is not best:
            other = out.with_name(f"{out.stem}.{r.model}{out.suffix or '.yaml'}")
            write_params(other, param_document(r, args.delta, intervals[r.model]))
            print(f"wrote {other.resolve()}")
    plot = plot_path(out, args.plot)
    overlay_plot(results, records, plot)
    print(f"wrote {plot.resolve()}")
    return 0

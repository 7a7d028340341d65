"""``sashil simulate``: run a parameter file's model on recorded inputs or a drop test, write a run folder."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from sashil.cli.common import add_config_options, add_output_options, positive_seconds, resolve_config
from sashil.errors import ConfigError

HELP = "simulate a model (from --params) on recorded inputs or a drop test, for validation"
EXAMPLE = "sashil simulate --params params.yaml --input runs/a/data.csv --out runs/sim-a"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_output_options(parser)
    parser.add_argument(
        "--input",
        metavar="CSV|RUN",
        help="a data.csv or a run folder (its data.csv); inputs: time_s, current_a (or current_cmd_a), optional "
        "theta_road_rad, torque_in_nm; theta_rad gives the initial angle and is compared",
    )
    parser.add_argument("--theta0-deg", type=float, default=-5.0, help="drop test without --input: initial angle")
    parser.add_argument("--current", type=float, default=0.0, help="drop test without --input: coil current [A]")
    parser.add_argument("--duration", type=float, default=10.0, help="drop test without --input: seconds")
    parser.add_argument(
        "--start", choices=("rest", "moving"), default="rest", help="the input starts at rest or moving"
    )


def input_file(value: str) -> Path:
    """``--input``'s data file: the file itself, or a run folder's ``data.csv`` (simulate takes one run)."""
    path = Path(value)
    if not path.is_dir():
        return path
    if (path / "data.csv").is_file():
        return path / "data.csv"
    runs = sorted(found.parent.name for found in path.glob("*/data.csv"))
    if runs:
        raise ConfigError(
            f"--input {path}: a folder of {len(runs)} runs ({', '.join(runs[:4])}{', ...' if len(runs) > 4 else ''}); "
            f"simulate takes one, "
            f"e.g. --input {path / runs[0]}"
        )
    raise ConfigError(f"--input {path}: a folder without data.csv (expected a data.csv or a run folder)")


def run(args: argparse.Namespace) -> int:
    from sashil.identify.simulate import drop_test_inputs, simulate_columns
    from sashil.recording.data_file import read_data_csv
    from sashil.recording.run_folder import RunFolder
    from sashil.stats import nrmse

    config = resolve_config(args)
    model = config["model"]["name"]
    params = dict(config["model"]["params"])
    if model == "bouc-wen":
        from sashil.models.hysteresis import BoucWenParams

        params = {**BoucWenParams().as_dict(), **params}
    measured = None
    if args.input:
        data_file = input_file(args.input)
        inputs = read_data_csv(data_file, required=("time_s",), min_rows=2)
        if "current_a" not in inputs and "current_cmd_a" not in inputs:
            raise ConfigError(f"{data_file}: missing column current_a (or current_cmd_a)")
        if "theta_rad" in inputs:
            measured = inputs["theta_rad"]
        else:
            inputs["theta_rad"] = np.zeros_like(inputs["time_s"])
        source = str(data_file)
    else:
        if not math.isfinite(args.theta0_deg) or abs(args.theta0_deg) > 90:
            raise ConfigError(f"--theta0-deg: expected an angle within +-90 deg, got {args.theta0_deg:g}")
        inputs = drop_test_inputs(args.theta0_deg, args.current, positive_seconds("--duration", args.duration))
        source = f"drop test theta0 {args.theta0_deg:g} deg, {args.current:g} A"
    columns = simulate_columns(model, params, inputs, start_at_rest=args.start == "rest")
    folder = RunFolder.create(args.out, "simulate")
    folder.write_config(config)
    if measured is not None:
        columns["theta_measured_rad"] = measured
    folder.write_data(columns)
    summary = {"exit_status": "ok", "model": model, "input": source, "samples": int(columns["time_s"].size)}
    if measured is not None:
        summary["rms_rad"] = float(np.sqrt(np.mean((columns["theta_rad"] - measured) ** 2)))
        summary["nrmse"] = nrmse(columns["theta_rad"], measured)
    _plot(folder.file("theta.png"), columns, model)
    folder.write_summary(summary)
    print(
        f"simulated {model} on {source}: {folder.path}"
        + (f" (NRMSE {100 * summary['nrmse']:.3g} %)" if measured is not None else "")
    )
    return 0


def _plot(path: Path, columns: dict, model: str) -> None:
    from sashil.recording.plots import pyplot, save_figure

    fig, ax = pyplot().subplots(figsize=(8, 3))
    if "theta_measured_rad" in columns:
        ax.plot(columns["time_s"], np.degrees(columns["theta_measured_rad"]), "k", lw=1.2, label="input record")
    ax.plot(columns["time_s"], np.degrees(columns["theta_rad"]), lw=0.9, label=f"{model} simulation")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("theta [deg]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)

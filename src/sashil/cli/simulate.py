"""``sashil simulate``: run a parameter file's model on recorded inputs or a drop test, write a run folder."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from sashil.cli.common import add_config_options, add_output_options, resolve_config
from sashil.config.sections import SIMULATE
from sashil.errors import ConfigError
from sashil.models.registry import MODEL_PARAMS

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


#: the options that set a key of the ``simulate`` section
OPTIONS = (
    ("--input", "input"),
    ("--theta0-deg", "theta0_deg"),
    ("--current", "current_a"),
    ("--duration", "duration_s"),
    ("--start", "start"),
)


def resolve_inputs(args: argparse.Namespace, config: dict) -> dict:
    """The config's ``simulate`` section with the options given written over it (config.yaml says
    what ran), each checked like the config key it sets."""
    section = config["simulate"]
    for option, key in OPTIONS:
        value = getattr(args, option.lstrip("-").replace("-", "_"))
        if value is not None:
            section[key] = SIMULATE.fields[key].check(value, option)
    return section


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

    config = resolve_config(args, models=tuple(MODEL_PARAMS))
    inputs_of = resolve_inputs(args, config)
    model = config["model"]["name"]
    params = dict(config["model"]["params"])
    if model == "bouc-wen":
        from sashil.models.hysteresis import BoucWenParams

        params = {**BoucWenParams().as_dict(), **params}
    measured = None
    if inputs_of["input"]:
        data_file = input_file(inputs_of["input"])
        inputs = read_data_csv(data_file, required=("time_s",), min_rows=2)
        if "current_a" not in inputs and "current_cmd_a" not in inputs:
            raise ConfigError(f"{data_file}: missing column current_a (or current_cmd_a)")
        if "theta_rad" in inputs:
            measured = inputs["theta_rad"]
        else:
            inputs["theta_rad"] = np.zeros_like(inputs["time_s"])
        source = str(data_file)
    else:
        theta0, current = inputs_of["theta0_deg"], inputs_of["current_a"]
        inputs = drop_test_inputs(theta0, current, inputs_of["duration_s"])
        source = f"drop test theta0 {theta0:g} deg, {current:g} A"
    columns = simulate_columns(model, params, inputs, start_at_rest=inputs_of["start"] == "rest")
    folder = RunFolder.create(args.out, "simulate")
    folder.write_config(config)
    if measured is not None:
        columns["theta_measured_rad"] = measured
    folder.write_data(columns)
    summary = {"exit_status": "ok", "model": model, "input": source, "samples": int(columns["time_s"].size)}
    if measured is not None:
        summary["rms_rad"] = float(np.sqrt(np.mean((columns["theta_rad"] - measured) ** 2)))
        summary["nrmse"] = nrmse(columns["theta_rad"], measured)
    _plot(folder.file("theta.png"), columns, model, source, summary.get("nrmse"))
    drops = _drop_metrics(config, columns, measured, inputs) if args.input is None or _is_drop(inputs) else None
    if drops is not None:
        summary["drop_test"] = {name: metrics.as_dict() for name, metrics in drops.items()}
    folder.write_summary(summary)
    print(
        f"simulated {model} on {source}: {folder.path}"
        + (f" (NRMSE {100 * summary['nrmse']:.3g} %)" if measured is not None else "")
    )
    if drops is not None:
        print(_drop_table(drops))
    return 0


def _is_drop(inputs: dict) -> bool:
    """Whether an input record is a drop test: no road motion and no input torque."""
    road, torque = inputs.get("theta_road_rad"), inputs.get("torque_in_nm")
    still = road is None or not np.any(np.nan_to_num(road))
    return still and (torque is None or not np.any(np.nan_to_num(torque)))


def _drop_metrics(config: dict, columns: dict, measured: np.ndarray | None, inputs: dict) -> dict:
    """Drop-test metrics (period, peaks, ζ) of the simulated angle and, when given, the recorded one,
    with the config's settling band and encoder resolution."""
    from sashil.experiments.metrics import drop_metrics

    band = config["drop_test"]["settle_band_deg"]
    resolution = 2.0 * math.pi / config["rig"]["encoder_counts_per_rev"]
    out = {"simulated": drop_metrics(columns["time_s"], columns["theta_rad"], band, resolution)}
    if measured is not None:
        out["recorded"] = drop_metrics(inputs["time_s"], measured, band, resolution)
    return out


def _drop_table(drops: dict) -> str:
    """Period, first peaks and ζ of each drop-test record, side by side."""

    def number(value: float | None, digits: int = 3) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    rows = [
        ("period [s]", lambda m: number(m.period_s)),
        ("first peaks [deg]", lambda m: ", ".join(f"{p:.2f}" for p in m.peaks_deg[:4]) or "none"),
        ("damping ratio ζ", lambda m: number(m.damping_ratio, 4)),
    ]
    names = list(drops)
    width = max(12, *(len(get(drops[n])) + 3 for n in names for _, get in rows))
    lines = [f"{'drop test':<20}" + "".join(f"{n:>{width}}" for n in names)]
    lines += [f"{title:<20}" + "".join(f"{get(drops[n]):>{width}}" for n in names) for title, get in rows]
    return "\n".join(lines)


def _plot(path: Path, columns: dict, model: str, source: str, error: float | None) -> None:
    """``theta.png``: the simulated angle (and the recorded one when given, with the residual
    simulated − recorded below it); the title names the model, the input and the NRMSE."""
    from sashil.recording.plots import BESIDE, pyplot, save_figure

    measured = columns.get("theta_measured_rad")
    rows = 2 if measured is not None else 1
    fig, axes = pyplot().subplots(
        rows, 1, figsize=(10, 2.2 + 1.6 * rows), sharex=True, squeeze=False, height_ratios=[2.5, 1][:rows]
    )
    top = axes[0, 0]
    t = columns["time_s"]
    if measured is not None:
        top.plot(t, np.degrees(measured), "k", lw=1.2, label="recorded")
    top.plot(t, np.degrees(columns["theta_rad"]), color="tab:red", lw=0.9, label=f"{model} simulation")
    top.set_ylabel("θ [deg]")
    title = f"sashil simulate: {model} on {source}"
    top.set_title(title + (f", NRMSE {100 * error:.3g} %" if error is not None else ""), fontsize=10)
    top.legend(**BESIDE)
    if measured is not None:
        bottom = axes[1, 0]
        bottom.plot(t, np.degrees(columns["theta_rad"] - measured), color="tab:blue", lw=0.7)
        bottom.axhline(0.0, color="0.4", lw=0.6)
        bottom.set_ylabel("sim − rec [deg]")
        bottom.yaxis.set_major_locator(_few_ticks())
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    save_figure(fig, path, dpi=110)


def _few_ticks() -> object:
    """At most four ticks on a short residual axis, so the labels do not collide."""
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(nbins=4, symmetric=True)

"""``sashil simulate``: run a parameter file's model on recorded inputs or a drop test, write a run folder."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sashil.cli.common import add_config_options, add_output_options, resolve_config
from sashil.config.sections import SIMULATE
from sashil.errors import ConfigError
from sashil.models.registry import MODEL_PARAMS

HELP = "simulate a model (from --params) on recorded inputs or a drop test, for validation"
EXAMPLE = "sashil simulate --params params.yaml --input runs/a/data.csv --out runs/sim-a"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_output_options(parser)
    parser.add_argument(
        "--input",
        metavar="CSV",
        help="inputs: time_s, current_a (or current_cmd_a), optional "
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
        inputs = read_data_csv(inputs_of["input"], required=("time_s",), min_rows=2)
        if "current_a" not in inputs and "current_cmd_a" not in inputs:
            raise ConfigError(f"{inputs_of['input']}: missing column current_a (or current_cmd_a)")
        if "theta_rad" in inputs:
            measured = inputs["theta_rad"]
        else:
            inputs["theta_rad"] = np.zeros_like(inputs["time_s"])
        source = str(inputs_of["input"])
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

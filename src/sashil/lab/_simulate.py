"""``sashil simulate`` as a library function: a damper model (any of bouc-wen, dahl, lugre,
bingham) run on recorded inputs or on a drop test, into a run folder (data.csv, theta.png,
summary.json), with the fit to the recorded angle when there is one."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.api import Run, load_run
from sashil.engine import assemble
from sashil.engine.checks import input_file
from sashil.engine.events import Event, Listener, ignore
from sashil.errors import ConfigError
from sashil.identify.simulate import drop_test_inputs, simulate_columns
from sashil.lab.metrics import drop_metrics
from sashil.models.hysteresis import BoucWenParams
from sashil.recording.data_file import read_data_csv
from sashil.recording.outputs import Outputs
from sashil.recording.plots import BESIDE, pyplot, save_figure
from sashil.stats import nrmse
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.config.typed import RunConfig

__all__ = ["READS", "drop_table", "simulate"]

#: ``sashil simulate``'s own values (``{name: config key}``), read once by the engine into its
#: run's ``options``
READS = {
    **{key: f"simulate.{key}" for key in ("input", "theta0_deg", "current_a", "duration_s", "start")},
    "settle_band_deg": "drop_test.settle_band_deg",
}


def _inputs(section: Mapping[str, Any]) -> tuple[dict[str, np.ndarray], np.ndarray | None, str]:
    """The model's inputs (time, current, road, torque and the initial angle), the recorded angle
    to compare with (None for a drop test) and a description of the source, from the run's
    ``options`` (:data:`READS`)."""

    if not section["input"]:
        theta0, current = section["theta0_deg"], section["current_a"]
        return (
            drop_test_inputs(theta0, current, section["duration_s"]),
            None,
            f"drop test theta0 {theta0:g} deg, {current:g} A",
        )
    data_file = input_file(section["input"], "simulate.input")
    inputs = read_data_csv(data_file, required=("time_s",), min_rows=2)
    if "current_a" not in inputs and "current_cmd_a" not in inputs:
        raise ConfigError(f"{data_file}: missing column current_a (or current_cmd_a)")
    measured = inputs.get("theta_rad")
    if measured is None:
        inputs["theta_rad"] = np.zeros_like(inputs["time_s"])
    return inputs, measured, str(data_file)


def simulate(config: RunConfig, outputs: Outputs | None = None, on_event: Listener = ignore) -> Run:
    """Run the model of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``simulate`` and ``models=sashil.models.registry.MODEL_PARAMS``) on ``simulate.input`` (a
    data.csv or a run folder; None: a drop test from ``simulate.theta0_deg`` at ``current_a`` for
    ``duration_s``), starting at rest or moving (``simulate.start``), into a new run folder.

    Returns the folder as a :class:`~sashil.api.Run`: ``data.csv`` (the simulated columns, and
    ``theta_measured_rad`` beside them for a recorded input), ``theta.png`` and ``summary.json``
    (``model``, ``input``, ``samples``; ``rms_rad`` and ``nrmse`` against the recorded angle; the
    drop-test metrics of both angles when the input is a drop). Bad input (an unreadable data file,
    one without a current column) raises ConfigError before any folder exists. Events: ``output``
    lines (the folder and the fit, the drop-test table), as ``sashil simulate`` prints them."""

    outputs = outputs if outputs is not None else Outputs()
    outputs.check_folder_only("simulate")
    run = assemble(config, reads=READS, drives_rig=False)
    model = run.stage.model.name
    params = dict(run.stage.model.params)
    if model == "bouc-wen":
        params = {**BoucWenParams().as_dict(), **params}
    inputs, measured, source = _inputs(run.options)
    columns = simulate_columns(model, params, inputs, start_at_rest=run.options["start"] == "rest")
    folder = RunFolder.create(outputs.out, "simulate")
    documents = Documents([FolderWriter(folder, "simulate", {}, several=False)])
    documents.start(None, config, run)
    if measured is not None:
        columns["theta_measured_rad"] = measured
    folder.write_data(columns)
    summary: dict[str, Any] = {"model": model, "input": source, "samples": int(columns["time_s"].size)}
    if measured is not None:
        summary["rms_rad"] = float(np.sqrt(np.mean((columns["theta_rad"] - measured) ** 2)))
        summary["nrmse"] = nrmse(columns["theta_rad"], measured)
    _plot(folder.file("theta.png"), columns, model, source, summary.get("nrmse"))
    drops = _drop_metrics(run, columns, measured, inputs) if not run.options["input"] or _is_drop(inputs) else None
    if drops is not None:
        summary["drop_test"] = {name: metrics.as_dict() for name, metrics in drops.items()}
    documents.summary(None, summary)
    fit = f" (NRMSE {100 * summary['nrmse']:.3g} %)" if measured is not None else ""
    on_event(Event("output", f"simulated {model} on {source}: {folder.path}{fit}", {"folder": str(folder.path)}))
    if drops is not None:
        on_event(Event("output", drop_table(drops), summary["drop_test"]))
    return load_run(folder.path)


def _is_drop(inputs: Mapping[str, np.ndarray]) -> bool:
    """Whether an input record is a drop test: no road motion and no input torque."""
    road, torque = inputs.get("theta_road_rad"), inputs.get("torque_in_nm")
    still = road is None or not np.any(np.nan_to_num(road))
    return still and (torque is None or not np.any(np.nan_to_num(torque)))


def _drop_metrics(
    run: RunSpec, columns: Mapping[str, np.ndarray], measured: np.ndarray | None, inputs: Mapping[str, Any]
) -> dict[str, Any]:
    """Drop-test metrics (period, peaks, ζ) of the simulated angle and, when given, the recorded one,
    with the run's settling band and encoder resolution."""

    band = run.options["settle_band_deg"]
    resolution = 2.0 * math.pi / run.stage.counts_per_rev
    out = {"simulated": drop_metrics(columns["time_s"], columns["theta_rad"], band, resolution)}
    if measured is not None:
        out["recorded"] = drop_metrics(inputs["time_s"], measured, band, resolution)
    return out


def drop_table(drops: Mapping[str, Any]) -> str:
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


def _plot(path: Path, columns: Mapping[str, np.ndarray], model: str, source: str, error: float | None) -> None:
    """``theta.png``: the simulated angle (and the recorded one when given, with the residual
    simulated − recorded below it); the title names the model, the input and the NRMSE."""
    from matplotlib.ticker import MaxNLocator

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
        bottom.yaxis.set_major_locator(MaxNLocator(nbins=4, symmetric=True))  # few ticks: labels do not collide
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    save_figure(fig, path, dpi=110)

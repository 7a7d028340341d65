"""What an identification hands back: the parameter file, the printed report, the overlay plot."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from sashil.identify.data import Record
from sashil.identify.fit import FitResult, simulate_fitted
from sashil.identify.intervals import Intervals
from sashil.identify.rig_models import bouc_wen_rescale
from sashil.recording.plots import pyplot, save_figure

OBJECTIVE = "output error: RMS of simulated minus recorded theta over all samples (seed 000 eq. 10)"


def ranked(results: Sequence[FitResult]) -> list[FitResult]:
    """Best first: smallest output-error RMS over all runs."""
    return sorted(results, key=lambda r: r.rms_total)


def param_document(result: FitResult, delta: float | None = None, intervals: Intervals | None = None) -> dict:
    """The parameter file (docs/architecture.md shape) with uncertainties and fit statistics beside ``params``.

    ``delta`` re-expresses a Bouc-Wen result with that delta (z scale) instead of the unit bound.
    ``intervals``: adds ``intervals_95`` (``name: [low, high]``, :mod:`sashil.identify.intervals`);
    with ``delta`` only the quantities the z scale leaves alone (k, c, the yield torques, c1, c2, n).
    """
    params = dict(result.params)
    stderr = dict(result.stderr)
    normalisation = result.normalisation
    if result.model == "bouc-wen" and delta is not None:
        bound = (params["delta"] / (params["beta"] + params["gamma"])) ** (1.0 / params["n"])
        zu = bound * delta / params["delta"]  # z -> kappa*z with kappa = delta_new/delta
        rescaled = bouc_wen_rescale(params, zu)
        for key in ("alpha1", "alpha2", "beta", "gamma", "delta"):
            if key in stderr and params[key] != 0.0:
                stderr[key] *= abs(rescaled[key] / params[key])
        params = rescaled
        normalisation = f"z scaled so that delta = {delta:g} (z bound {zu:.6g}); J fixed"
    doc = {
        "model": result.model,
        "params": {k: float(v) for k, v in params.items()},
        "normalisation": normalisation,
        "fixed": {k: float(v) for k, v in result.fixed.items()},
        "uncertainty_1sigma": {k: float(v) for k, v in stderr.items()},
        "correlations_above_0_95": [[a, b, round(c, 4)] for a, b, c in result.flagged],
        "fit": {
            "objective": OBJECTIVE,
            "rms_rad_total": result.rms_total,
            "runs": [
                {"file": name, "rms_rad": rms, "nrmse": nr, "initial_angle_offset_rad": offset}
                for name, rms, nr, offset in zip(
                    result.record_names,
                    result.rms_rad,
                    result.nrmse,
                    result.initial_offsets_rad or [0.0] * len(result.record_names),
                    strict=True,
                )
            ],
            "wall_s": round(result.wall_s, 3),
            "evaluations": result.evaluations,
            "stages": result.stages,
            "convergence": result.convergence,
        },
    }
    if intervals is not None:
        scaled = {"alpha1", "alpha2", "beta", "gamma", "delta"} if delta is not None else set()
        doc["intervals_95"] = {
            name: [float(f"{intervals.low[name]:.6g}"), float(f"{intervals.high[name]:.6g}")]
            for name in intervals.value
            if name not in scaled
        }
        doc["intervals_method"] = intervals.method
    return doc


def write_params(path: str | Path, document: dict) -> Path:
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(yaml.safe_dump(document, sort_keys=False, default_flow_style=False), encoding="utf-8")
    tmp.replace(path)
    return path


def format_result(result: FitResult) -> str:
    """Per-model report: parameters with 1-sigma, runs, flagged correlations, wall time."""
    lines = [
        f"model {result.model}: RMS {result.rms_total:.4g} rad, wall {result.wall_s:.2f} s, "
        f"{result.evaluations} evaluations"
    ]
    for stage in result.stages:
        lines.append(f"  {stage}")
    for name, value in result.params.items():
        if name in result.fixed:
            lines.append(f"  {name:>8} = {value:<12.6g} (fixed)")
        else:
            se = result.stderr.get(name, float("nan"))
            rel = f" ({100 * se / abs(value):.2g} %)" if value else ""
            lines.append(f"  {name:>8} = {value:<12.6g} +- {se:.3g}{rel}")
    for name, rms, nr in zip(result.record_names, result.rms_rad, result.nrmse, strict=True):
        lines.append(f"  run {name}: RMS {rms:.4g} rad, NRMSE {100 * nr:.3g} %")
    for a, b, c in result.flagged:
        lines.append(f"  WARNING correlation {a}-{b} = {c:+.4f} (> 0.95: not separately identifiable)")
    lines.append(f"  normalisation: {result.normalisation}")
    lines.append("  (1-sigma from the Jacobian assume white residuals; with encoder quantisation they are optimistic)")
    return "\n".join(lines)


def format_intervals(intervals: Intervals) -> str:
    """The 95 % intervals, one line each (lab quantities first)."""
    lines = [f"  95 % intervals ({intervals.method}):"]
    for name, value in intervals.value.items():
        lines.append(
            f"  {name:>9} = {value:<12.6g} [{intervals.low[name]:.6g}, {intervals.high[name]:.6g}] "
            f"(±{100 * intervals.half_width(name):.3g} %)"
        )
    return "\n".join(lines)


def comparison_table(results: Sequence[FitResult]) -> str:
    """Ranked table of models (``--model all``)."""
    rows = ranked(results)
    names = rows[0].record_names
    head = f"{'rank':>4}  {'model':<9} {'RMS [rad]':>11} " + " ".join(
        f"{'NRMSE run' + str(j + 1):>12}" for j in range(len(names))
    )
    lines = [head + f" {'wall [s]':>9}"]
    for rank, r in enumerate(rows, start=1):
        cells = " ".join(f"{100 * v:>11.3g}%" for v in r.nrmse)
        lines.append(f"{rank:>4}  {r.model:<9} {r.rms_total:>11.4g} {cells} {r.wall_s:>9.2f}")
    lines += [f"  run{j + 1} = {n}" for j, n in enumerate(names)]
    return "\n".join(lines)


def overlay_plot(results: Sequence[FitResult], records: Sequence[Record], path: str | Path) -> Path:
    """Recorded angle and every model's simulation, one panel per run, each with a residual panel
    (simulated − recorded) below it, so a misfit reads as structure rather than a thick line (PNG)."""
    plt = pyplot()
    n = len(records)
    fig, axes = plt.subplots(2 * n, 1, figsize=(9, 3.6 * n), squeeze=False, gridspec_kw={"height_ratios": [3, 1.3] * n})
    for k, record in enumerate(records):
        ax, res = axes[2 * k, 0], axes[2 * k + 1, 0]
        ax.plot(record.time_s, np.degrees(record.theta), color="k", lw=1.2, label="recorded")
        for r in ranked(results):
            sim = simulate_fitted(r, [record])[0]
            (line,) = ax.plot(
                record.time_s, np.degrees(sim), lw=0.9, label=f"{r.model} (RMS {np.degrees(r.rms_total):.3g} deg)"
            )
            res.plot(record.time_s, np.degrees(sim - record.theta), lw=0.7, color=line.get_color())
        ax.set_title(
            "/".join(Path(record.name).parts[-2:]) + f"  (mean current {record.mean_current:.2f} A)", fontsize=9
        )
        ax.set_ylabel("theta [deg]")
        ax.grid(alpha=0.3)
        ax.sharex(res)
        ax.tick_params(labelbottom=False)
        res.axhline(0.0, color="k", lw=0.6)
        res.set_ylabel("residual [deg]", fontsize=8)
        res.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    return save_figure(fig, path, dpi=110)

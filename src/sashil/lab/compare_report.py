"""The files of ``sashil compare``: ``metrics.csv``, ``compare.md`` and ``compare.png``."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sashil.lab.compare_metrics import METRICS, LawResult
from sashil.recording.labels import format_parameters
from sashil.recording.plots import BESIDE, pyplot, save_figure

__all__ = [
    "BOUND_TOLERANCE_PTS",
    "Scale",
    "above_bound",
    "best_law",
    "plot_compare",
    "share_of_bound",
    "shares_of_bound",
    "write_compare_md",
    "write_metrics_csv",
]

#: how far above 100 % a share may lie before it is flagged [points]: the bound is the best found
#: from a few starts on the controller's model, not a certificate, and a run's θ̈2 is the plant's
#: (or its encoders') where the bound's is the model's stepped at the loop's period; over serial the
#: shares lie within a median 5 points of the simulated rig's (:mod:`sashil.lab.hysteretic_bound`).
#: A share beyond it says the bound's model is not the rig's, or its search missed.
BOUND_TOLERANCE_PTS = 5.0

COLUMNS = ("law", "status", *METRICS, "vs_best_passive_pct", "share_of_bound_pct", "above_bound", "wall_s")
HEADINGS = {
    "rms_accel_rad_s2": "RMS θ̈2 [rad/s²]",
    "rms_theta_deg": "RMS θ [deg]",
    "peak_current_a": "peak i [A]",
    "coil_energy_j": "coil energy [J]",
    "vs_best_passive_pct": "θ̈2 vs best passive",
    "share_of_bound_pct": "share of the bound",
    "share_of_plant_bound_pct": "share of the plant's bound",
    "wall_s": "wall [s]",
}


@dataclass(frozen=True)
class Scale:
    """The one scale of compare's gains and shares: the passive baseline's row (``baseline``: its
    label, :mod:`sashil.lab.passive_baseline`) and RMS θ̈2 (0 %), the optimal bound's RMS θ̈2 on the
    runs' chain (100 %), and where the plant is known and differs from the model, the true plant's
    bound (``plant_bound``; NaN otherwise)."""

    baseline: str | None = None
    passive: float = math.nan
    bound: float = math.nan
    plant_bound: float = math.nan


def above_bound(share: float) -> bool:
    """Whether a share lies above 100 % by more than :data:`BOUND_TOLERANCE_PTS`: flagged."""
    return math.isfinite(share) and share > 100.0 + BOUND_TOLERANCE_PTS


def best_law(results: Sequence[LawResult]) -> LawResult | None:
    """The run (a law or a passive reference) with the lowest RMS arm acceleration."""
    return min((r for r in results if r.ok), key=lambda r: r.metrics["rms_accel_rad_s2"], default=None)


def share_of_bound(rms_accel: float, passive_rms_accel: float, bound_rms_accel: float) -> float:
    """Where a run's RMS θ̈2 lies on the one scale from the best passive run (0 %) to the optimal
    bound (100 %), both ends absolute RMS θ̈2 of the same road: ``100·(p − r)/(p − b)`` [%]; NaN when
    the bound is not below the best passive run (or a value is missing). Above 100 %: the run beat the
    bound (the bound's model is not the rig's)."""
    gap = passive_rms_accel - bound_rms_accel
    if not (math.isfinite(rms_accel) and math.isfinite(gap) and gap > 0.0):
        return math.nan
    return 100.0 * (passive_rms_accel - rms_accel) / gap


def shares_of_bound(results: Sequence[LawResult], scale: Scale, bound: float | None = None) -> dict[str, float]:
    """Each finished run's :func:`share_of_bound` on ``scale`` by label (its bound, or ``bound``:
    the plant's), empty without a baseline."""
    if not math.isfinite(scale.passive):
        return {}
    b = scale.bound if bound is None else bound
    return {r.label: share_of_bound(r.metrics["rms_accel_rad_s2"], scale.passive, b) for r in results if r.ok}


def _rows(results: Sequence[LawResult], scale: Scale) -> list[dict[str, Any]]:
    """Each law's values; its gain over the passive baseline [%], and its share of the way from the
    baseline to the optimal bound's RMS θ̈2 [%] (:func:`share_of_bound`), flagged above 100 % +
    :data:`BOUND_TOLERANCE_PTS`; its share of the plant's bound where the scale has one."""
    shares = shares_of_bound(results, scale)
    plant = shares_of_bound(results, scale, scale.plant_bound)
    rows = []
    for r in results:
        gain = math.nan
        share = shares.get(r.label, math.nan)
        if math.isfinite(scale.passive) and r.ok:
            gain = 100.0 * (1.0 - r.metrics["rms_accel_rad_s2"] / scale.passive)
        rows.append(
            {
                "law": r.label,
                "status": r.status,
                **r.metrics,
                "vs_best_passive_pct": gain,
                "share_of_bound_pct": share,
                "share_of_plant_bound_pct": plant.get(r.label, math.nan),
                "above_bound": above_bound(share),
                "wall_s": r.wall_s,
            }
        )
    return rows


def write_metrics_csv(path: Path, results: Sequence[LawResult], scale: Scale) -> Path:
    """One row per law: its status, the metrics (empty when it did not finish), the comfort gain
    over the passive baseline [%] (positive: better), its share of the way from the baseline to the
    optimal bound [%] (``scale``), whether that share is flagged above the bound, and its wall time;
    with a plant's bound, the share of it too."""
    columns = COLUMNS if not math.isfinite(scale.plant_bound) else (*COLUMNS[:-1], "share_of_plant_bound_pct", "wall_s")
    with open(path, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(columns)
        for row in _rows(results, scale):
            writer.writerow(["" if isinstance(v, float) and math.isnan(v) else v for v in (row[c] for c in columns)])
    return path


def _cell(key: str, value: Any) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "–"
        if key in ("vs_best_passive_pct", "share_of_bound_pct", "share_of_plant_bound_pct"):
            flag = " ⚠ above the bound" if key == "share_of_bound_pct" and above_bound(value) else ""
            return f"{value:+.1f} %{flag}"
        return f"{value:.4g}"
    return str(value)


def write_compare_md(
    path: Path,
    results: Sequence[LawResult],
    header: dict[str, str],
    notes: Sequence[str],
    scale: Scale,
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    folders: Mapping[str, str] | None = None,
) -> Path:
    """The comparison as a Markdown table, with what ran (``header``), each law's ``parameters`` and
    run folder (``folders``), by label, and how to read it (``notes``); the best law in bold, the
    passive baseline marked, a share above the bound by more than the tolerance flagged."""
    parameters, folders = parameters or {}, folders or {}
    best = best_law(results)
    lines = ["# sashil compare", ""]
    lines += [f"- **{key}:** {value}" for key, value in header.items()]
    keys: tuple[str, ...] = (*METRICS, "vs_best_passive_pct", "share_of_bound_pct")
    if math.isfinite(scale.plant_bound):
        keys += ("share_of_plant_bound_pct",)
    keys += ("wall_s",)
    lines += ["", "| law | parameters | folder | " + " | ".join(HEADINGS[k] for k in keys) + " | status |"]
    lines.append("|---|---|---|" + "---:|" * len(keys) + "---|")
    for row in _rows(results, scale):
        label = row["law"]
        name = f"**{label}** (best)" if best is not None and label == best.label else label
        if label == scale.baseline:
            name += " (baseline)"
        params = _parameter_text(parameters.get(label, {})) or "–"
        folder = f"`{folders[label]}/`" if label in folders else "–"
        cells = " | ".join(_cell(k, row[k]) for k in keys)
        lines.append(f"| {name} | {params} | {folder} | {cells} | {row['status']} |")
    lines += ["", *(f"- {note}" for note in notes), ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


#: the colours of compare.png: the best run, the best passive reference, other laws, other references
BEST, PASSIVE, OTHER, REFERENCE = "tab:green", "black", "tab:blue", "0.6"


def _parameter_text(params: Mapping[str, Any]) -> str:
    """``c_sky=2, onoff_current_a=default`` (a parameter left to the law's own default: ``default``)."""
    return format_parameters({k: "default" if v is None else v for k, v in params.items()})


def _colour(result: LawResult, best: LawResult | None, reference: LawResult | None) -> str:
    """The colour of a run's bar: the best, the passive baseline, another law or another passive."""
    if best is not None and result.label == best.label:
        return BEST
    if reference is not None and result.label == reference.label:
        return PASSIVE
    return REFERENCE if result.label.startswith("passive") else OTHER


def plot_compare(path: Path, results: Sequence[LawResult], road: str, scale: Scale) -> Path:
    """``compare.png``: RMS θ̈2 and RMS θ of every run side by side, best first, the best run and
    the passive baseline marked, and with a bound (``scale``) its RMS θ̈2 drawn and each run's share
    of the way to it (flagged above the bound); the PSD and the first seconds of θ̈2 of those two
    only (every law's are in its own run folder)."""
    bound_rms_accel = scale.bound
    plt = pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(10, 10), height_ratios=(1.3, 1.0, 1.0), width_ratios=(1.6, 1.0))
    ax_accel, ax_travel = axes[0]
    grid = axes[0][0].get_gridspec()
    for ax in (*axes[1], *axes[2]):
        ax.remove()
    ax_psd, ax_t = fig.add_subplot(grid[1, :]), fig.add_subplot(grid[2, :])
    best = best_law(results)
    reference = next((r for r in results if r.label == scale.baseline and r.ok), None)
    done = sorted((r for r in results if r.ok), key=lambda r: r.metrics["rms_accel_rad_s2"])
    order = [*done, *(r for r in results if not r.ok)]
    y = np.arange(len(order))[::-1]
    colours = [_colour(r, best, reference) for r in order]
    accel = [r.metrics["rms_accel_rad_s2"] if r.ok else 0.0 for r in order]
    travel = [r.metrics["rms_theta_deg"] if r.ok else 0.0 for r in order]
    ax_accel.barh(y, accel, color=colours)
    ax_travel.barh(y, travel, color=colours)
    ax_accel.set_yticks(y, [r.label for r in order], fontsize=9)
    ax_travel.set_yticks(y, [""] * len(order))
    top = max(accel, default=1.0) or 1.0
    shares = shares_of_bound(results, scale)
    for yi, r, value in zip(y, order, accel, strict=True):
        if not r.ok:
            ax_accel.text(0.0, yi, f" did not finish: {r.status[:40]}", va="center", fontsize=8, color="tab:red")
            continue
        text = f"{value:.3g}"
        if reference is not None:
            text += f"  ({100.0 * (1.0 - value / reference.metrics['rms_accel_rad_s2']):+.1f} %)"
        share = shares.get(r.label, math.nan)
        if math.isfinite(share):
            text += f"  share {share:.0f} %" + (" (above the bound)" if above_bound(share) else "")
        if best is not None and r.label == best.label:
            text += "  best"
        ax_accel.text(top * 1.02, yi, text, va="center", fontsize=8, fontweight="bold" if r is best else "normal")
    if reference is not None:
        ax_accel.axvline(reference.metrics["rms_accel_rad_s2"], color=PASSIVE, ls="--", lw=0.8)
    xlabel = "RMS θ̈2 [rad/s²]  (lower is more comfortable; % vs the best passive, dashed)"
    if math.isfinite(bound_rms_accel):
        ax_accel.axvline(bound_rms_accel, color="tab:red", ls=":", lw=1.0)
        xlabel += "\nshare: of the way from the best passive run (0 %) to the optimal bound (100 %, dotted red)"
    ax_accel.set_xlim(0.0, top * 1.9)
    ax_accel.set(xlabel=xlabel)
    ax_accel.set_title("comfort", fontsize=10, loc="left")
    if road:
        fig.suptitle(f"sashil compare on {road}", fontsize=10)
    ax_travel.set(xlabel="RMS θ [deg]  (travel)")
    from matplotlib.patches import Patch

    keys = [(BEST, "best (lowest RMS θ̈2)"), (PASSIVE, "passive baseline"), (OTHER, "law"), (REFERENCE, "passive")]
    ax_travel.legend(handles=[Patch(color=c, label=t) for c, t in keys], **BESIDE)
    ax_travel.set_title("travel", fontsize=10, loc="left")
    shown = [r for r in (best, reference) if r is not None]
    if reference is not None and best is not None and best.label == reference.label:
        shown = [best]
    for r in shown:
        style = {"color": _colour(r, best, reference), "lw": 1.4 if r is best else 1.0}
        f, pxx = np.asarray(r.psd_f), np.asarray(r.psd)
        ax_psd.semilogy(f[1:], pxx[1:], label=r.label + (" (best)" if r is best else " (baseline)"), **style)
        ax_t.plot(r.trace_t, r.trace, label=r.label, **style)
    peaks = [float(np.max(r.psd[1:])) for r in shown if len(r.psd) > 1]
    if peaks:
        ax_psd.set_ylim(max(peaks) * 1e-4, max(peaks) * 3.0)  # four decades: where comfort is decided
        ax_psd.set_xlim(0.0, max(float(shown[0].psd_f[-1]) / 2.0, 1.0))  # up to twice the low-pass corner
    ax_psd.set(xlabel="frequency [Hz]", ylabel="PSD of θ̈2 [(rad/s²)²/Hz]")
    ax_psd.set_title("where the best run differs from the best passive one", fontsize=10, loc="left")
    ax_t.set(xlabel="time [s] (after compare.settle_s)", ylabel="θ̈2 [rad/s²]")
    if shown:
        ax_psd.legend(**BESIDE)
        ax_t.legend(**BESIDE)
    return save_figure(fig, path)

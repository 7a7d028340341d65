"""The files of ``sashil compare``: ``metrics.csv``, ``compare.md`` and ``compare.png``."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sashil.lab.compare_metrics import METRICS, LawResult
from sashil.recording.labels import format_parameters
from sashil.recording.plots import BESIDE, pyplot, save_figure

__all__ = [
    "best_law",
    "best_passive",
    "plot_compare",
    "share_of_bound",
    "shares_of_bound",
    "write_compare_md",
    "write_metrics_csv",
]

COLUMNS = ("law", "status", *METRICS, "vs_best_passive_pct", "share_of_bound_pct", "wall_s")
HEADINGS = {
    "rms_accel_rad_s2": "RMS θ̈2 [rad/s²]",
    "rms_theta_deg": "RMS θ [deg]",
    "peak_current_a": "peak i [A]",
    "coil_energy_j": "coil energy [J]",
    "vs_best_passive_pct": "θ̈2 vs best passive",
    "share_of_bound_pct": "share of the bound",
    "wall_s": "wall [s]",
}


def best_passive(results: Sequence[LawResult]) -> LawResult | None:
    """The passive run (a constant current) with the lowest RMS arm acceleration."""
    passive = [r for r in results if r.label.startswith("passive") and r.ok]
    return min(passive, key=lambda r: r.metrics["rms_accel_rad_s2"], default=None)


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


def shares_of_bound(results: Sequence[LawResult], bound_rms_accel: float) -> dict[str, float]:
    """Each finished run's :func:`share_of_bound` by label (empty without a best passive run)."""
    best = best_passive(results)
    if best is None:
        return {}
    p = best.metrics["rms_accel_rad_s2"]
    return {r.label: share_of_bound(r.metrics["rms_accel_rad_s2"], p, bound_rms_accel) for r in results if r.ok}


def _rows(results: Sequence[LawResult], bound_rms_accel: float) -> list[dict[str, Any]]:
    """Each law's values; its gain over the best passive run [%], and its share of the way from the
    best passive run to the optimal bound's RMS θ̈2 [%] (:func:`share_of_bound`)."""
    best = best_passive(results)
    shares = shares_of_bound(results, bound_rms_accel)
    rows = []
    for r in results:
        gain = math.nan
        share = shares.get(r.label, math.nan)
        if best is not None and r.ok:
            gain = 100.0 * (1.0 - r.metrics["rms_accel_rad_s2"] / best.metrics["rms_accel_rad_s2"])
        rows.append(
            {
                "law": r.label,
                "status": r.status,
                **r.metrics,
                "vs_best_passive_pct": gain,
                "share_of_bound_pct": share,
                "wall_s": r.wall_s,
            }
        )
    return rows


def write_metrics_csv(path: Path, results: Sequence[LawResult], bound_rms_accel: float = math.nan) -> Path:
    """One row per law: its status, the metrics (empty when it did not finish), the comfort gain
    over the best passive setting [%] (positive: better), its share of the way from the best
    passive run to the optimal bound (``bound_rms_accel``, RMS θ̈2) [%] and its wall time."""
    with open(path, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(COLUMNS)
        for row in _rows(results, bound_rms_accel):
            writer.writerow(["" if isinstance(v, float) and math.isnan(v) else v for v in (row[c] for c in COLUMNS)])
    return path


def _cell(key: str, value: Any) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "–"
        if key in ("vs_best_passive_pct", "share_of_bound_pct"):
            return f"{value:+.1f} %"
        return f"{value:.4g}"
    return str(value)


def write_compare_md(
    path: Path,
    results: Sequence[LawResult],
    header: dict[str, str],
    notes: Sequence[str],
    bound_rms_accel: float = math.nan,
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    folders: Mapping[str, str] | None = None,
) -> Path:
    """The comparison as a Markdown table, with what ran (``header``), each law's ``parameters`` and
    run folder (``folders``), by label, and how to read it (``notes``); the best law in bold."""
    parameters, folders = parameters or {}, folders or {}
    best = best_law(results)
    lines = ["# sashil compare", ""]
    lines += [f"- **{key}:** {value}" for key, value in header.items()]
    keys = (*METRICS, "vs_best_passive_pct", "share_of_bound_pct", "wall_s")
    lines += ["", "| law | parameters | folder | " + " | ".join(HEADINGS[k] for k in keys) + " | status |"]
    lines.append("|---|---|---|" + "---:|" * len(keys) + "---|")
    for row in _rows(results, bound_rms_accel):
        label = row["law"]
        name = f"**{label}** (best)" if best is not None and label == best.label else label
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
    if best is not None and result.label == best.label:
        return BEST
    if reference is not None and result.label == reference.label:
        return PASSIVE
    return REFERENCE if result.label.startswith("passive") else OTHER


def plot_compare(path: Path, results: Sequence[LawResult], road: str = "", bound_rms_accel: float = math.nan) -> Path:
    """``compare.png``: RMS θ̈2 and RMS θ of every run side by side, best first, the best run and
    the best passive reference marked, and with a bound (``bound_rms_accel``) its RMS θ̈2 drawn and
    each run's share of the way to it; the PSD and the first seconds of θ̈2 of those two only (every
    law's are in its own run folder)."""
    plt = pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(10, 10), height_ratios=(1.3, 1.0, 1.0), width_ratios=(1.6, 1.0))
    ax_accel, ax_travel = axes[0]
    grid = axes[0][0].get_gridspec()
    for ax in (*axes[1], *axes[2]):
        ax.remove()
    ax_psd, ax_t = fig.add_subplot(grid[1, :]), fig.add_subplot(grid[2, :])
    best, reference = best_law(results), best_passive(results)
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
    shares = shares_of_bound(results, bound_rms_accel)
    for yi, r, value in zip(y, order, accel, strict=True):
        if not r.ok:
            ax_accel.text(0.0, yi, f" did not finish: {r.status[:40]}", va="center", fontsize=8, color="tab:red")
            continue
        text = f"{value:.3g}"
        if reference is not None:
            text += f"  ({100.0 * (1.0 - value / reference.metrics['rms_accel_rad_s2']):+.1f} %)"
        share = shares.get(r.label, math.nan)
        if math.isfinite(share):
            text += f"  share {share:.0f} %"
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

    keys = [(BEST, "best (lowest RMS θ̈2)"), (PASSIVE, "best passive"), (OTHER, "law"), (REFERENCE, "passive")]
    ax_travel.legend(handles=[Patch(color=c, label=t) for c, t in keys], **BESIDE)
    ax_travel.set_title("travel", fontsize=10, loc="left")
    shown = [r for r in (best, reference) if r is not None]
    if reference is not None and best is not None and best.label == reference.label:
        shown = [best]
    for r in shown:
        style = {"color": _colour(r, best, reference), "lw": 1.4 if r is best else 1.0}
        f, pxx = np.asarray(r.psd_f), np.asarray(r.psd)
        ax_psd.semilogy(f[1:], pxx[1:], label=r.label + (" (best)" if r is best else " (best passive)"), **style)
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

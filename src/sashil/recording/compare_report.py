"""The files of ``sashil compare``: ``metrics.csv``, ``compare.md`` and ``compare.png``."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sashil.experiments.compare import METRICS, LawResult
from sashil.recording.plots import BESIDE, pyplot, save_figure

__all__ = ["best_passive", "plot_compare", "write_compare_md", "write_metrics_csv"]

COLUMNS = ("law", "status", *METRICS, "vs_best_passive_pct", "share_of_bound_pct", "wall_s")
HEADINGS = {
    "rms_accel_rad_s2": "RMS θ̈2 [rad/s²]",
    "rms_theta_deg": "RMS θ [deg]",
    "rms_road_torque_nm": "RMS road torque [N m]",
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


def _rows(results: Sequence[LawResult], bound_gain_pct: float) -> list[dict[str, Any]]:
    """Each law's values; its gain over the best passive run [%], and that gain as a share of the
    bound's gain over the best constant damping [%] (NaN without a bound above passive)."""
    best = best_passive(results)
    rows = []
    for r in results:
        gain = share = math.nan
        if best is not None and r.ok:
            gain = 100.0 * (1.0 - r.metrics["rms_accel_rad_s2"] / best.metrics["rms_accel_rad_s2"])
            if bound_gain_pct > 0.0:
                share = 100.0 * gain / bound_gain_pct
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


def write_metrics_csv(path: Path, results: Sequence[LawResult], bound_gain_pct: float = math.nan) -> Path:
    """One row per law: its status, the metrics (empty when it did not finish), the comfort gain
    over the best passive setting [%] (positive: better), that gain as a share of the optimal
    bound's [%] and its wall time."""
    with open(path, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(COLUMNS)
        for row in _rows(results, bound_gain_pct):
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
    bound_gain_pct: float = math.nan,
) -> Path:
    """The comparison as a Markdown table, with what ran (``header``) and how to read it (``notes``)."""
    lines = ["# sashil compare", ""]
    lines += [f"- **{key}:** {value}" for key, value in header.items()]
    keys = (*METRICS, "vs_best_passive_pct", "share_of_bound_pct", "wall_s")
    lines += ["", "| law | " + " | ".join(HEADINGS[k] for k in keys) + " | status |"]
    lines.append("|---|" + "---:|" * len(keys) + "---|")
    for row in _rows(results, bound_gain_pct):
        lines.append(f"| {row['law']} | " + " | ".join(_cell(k, row[k]) for k in keys) + f" | {row['status']} |")
    lines += ["", *(f"- {note}" for note in notes), ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def plot_compare(path: Path, results: Sequence[LawResult]) -> Path:
    """PSD of the arm acceleration, its first seconds, and a bar chart of RMS θ̈2 and RMS θ."""
    plt = pyplot()
    fig, (ax_psd, ax_t, ax_bar) = plt.subplots(3, 1, figsize=(9, 10))
    done = [r for r in results if r.ok]
    for r in done:
        ax_psd.loglog(r.psd_f[1:], r.psd[1:], label=r.label, lw=1)
        ax_t.plot(r.trace_t, r.trace, label=r.label, lw=0.8)
    ax_psd.set(xlabel="frequency [Hz]", ylabel="PSD of θ̈2 [(rad/s²)²/Hz]", title="arm acceleration")
    ax_t.set(xlabel="time [s]", ylabel="θ̈2 [rad/s²]")
    if done:
        ax_psd.legend(**BESIDE)
        ax_t.legend(**BESIDE)
    labels = [r.label for r in results]
    accel = [r.metrics["rms_accel_rad_s2"] if r.ok else 0.0 for r in results]
    travel = [r.metrics["rms_theta_deg"] if r.ok else 0.0 for r in results]
    x = range(len(results))
    ax_bar.bar([i - 0.2 for i in x], accel, width=0.4, label="RMS θ̈2 [rad/s²]")
    ax_travel = ax_bar.twinx()
    ax_travel.bar([i + 0.2 for i in x], travel, width=0.4, color="tab:orange", label="RMS θ [deg]")
    ax_bar.set_xticks(list(x), labels, rotation=30, ha="right", fontsize=8)
    ax_bar.set_ylabel("RMS θ̈2 [rad/s²]")
    ax_travel.set_ylabel("RMS θ [deg]")
    for i, r in enumerate(results):
        if not r.ok:
            ax_bar.text(i, 0.0, "failed", rotation=90, ha="center", va="bottom", fontsize=8)
    return save_figure(fig, path)

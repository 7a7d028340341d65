"""PNG plots of runs (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_angle_overlay(
    path: str | Path,
    runs: Sequence[tuple[str, np.ndarray, np.ndarray]],
    title: str,
    band_deg: float | None = None,
) -> Path:
    """theta(t) in degrees of several runs overlaid; ``runs`` = [(label, time_s, theta_rad), ...]."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.5), dpi=110)
    for label, time_s, theta in runs:
        ax.plot(time_s, np.degrees(theta), linewidth=1.0, label=label)
    if band_deg is not None:
        ax.axhspan(-band_deg, band_deg, color="0.85", zorder=0, label=f"±{band_deg:g}° settling band")
    ax.axhline(0.0, color="0.4", linewidth=0.6)
    ax.set_xlabel("time after release [s]")
    ax.set_ylabel("arm angle θ [deg]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def degrees_list(values_rad: Sequence[float]) -> list[float]:
    return [math.degrees(v) for v in values_rad]


def plot_run(path: str | Path, folder: str | Path, summary: dict | None = None) -> Path:
    """``run.png`` of a loop run folder: angles (θ, and the road θ1 when it moves), coil current
    (measured and commanded) and torque (observer T̂ and target T* when a controller recorded them)."""
    from sashil.recording.data_file import read_data_csv

    cols = read_data_csv(Path(folder) / "data.csv", required=("time_s",), min_rows=0)
    plt = _pyplot()
    has_torque = any(name in cols and np.isfinite(cols[name]).any() for name in ("torque_hat_nm", "torque_cmd_nm"))
    rows = 3 if has_torque else 2
    fig, axes = plt.subplots(rows, 1, figsize=(9, 2.4 * rows + 0.6), dpi=110, sharex=True)
    t = cols["time_s"]
    ax = axes[0]
    if "theta_rad" in cols:
        ax.plot(t, np.degrees(cols["theta_rad"]), lw=0.9, label="θ (relative angle)")
    road = cols.get("theta_road_rad")
    if road is not None and np.any(road):
        ax.plot(t, np.degrees(road), lw=0.9, label="θ1 (road)")
        if "theta_rad" in cols:
            ax.plot(t, np.degrees(cols["theta_rad"] + road), lw=0.8, label="θ2 (arm)")
    ax.set_ylabel("angle [deg]")
    ax = axes[1]
    for name, label in (("current_a", "measured i"), ("current_cmd_a", "commanded i*")):
        if name in cols:
            ax.plot(t, cols[name], lw=0.9, label=label)
    ax.set_ylabel("coil current [A]")
    if has_torque:
        ax = axes[2]
        for name, label in (("torque_hat_nm", "observer T̂"), ("torque_cmd_nm", "target T*")):
            if name in cols:
                ax.plot(t, cols[name], lw=0.8, label=label)
        ax.set_ylabel("damper torque [N·m]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    title = "sashil run"
    if summary:
        title += f": {summary.get('controller', '')}, {summary.get('driver', '')} backend"
        timing = summary.get("timing") or {}
        late = timing.get("lateness_us") or {}
        if late.get("p99") is not None:
            title += f", lateness p99 {late['p99']:.0f} µs"
        if summary.get("trips"):
            title += f", {len(summary['trips'])} trip(s)"
    axes[0].set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path

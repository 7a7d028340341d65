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

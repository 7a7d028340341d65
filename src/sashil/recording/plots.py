"""PNG plots of runs (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (imported on first use: the loop never pays for it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, dpi: float | None = None) -> Path:
    """Lay out, write and close ``fig``; returns the path written."""
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=dpi if dpi is not None else "figure")
    pyplot().close(fig)
    return path


def plot_run(path: str | Path, folder: str | Path, summary: dict | None = None) -> Path:
    """``run.png`` of a loop run folder: angles (θ, and the road θ1 when it moves), coil current
    (measured and commanded) and torque (observer T̂ and target T* when a controller recorded them)."""
    from sashil.recording.data_file import read_data_csv

    cols = read_data_csv(Path(folder) / "data.csv", required=("time_s",), min_rows=0)
    plt = pyplot()
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
    return save_figure(fig, path)


def plot_drop_test(
    path: str | Path,
    runs: Sequence[dict],
    title: str,
    band_deg: float | None = None,
) -> Path:
    """``drop_test.png``: θ(t) of each run with its positive peaks marked, the envelope the mean
    log decrement δ implies (``A0·exp(−δ·(t − t0)/T)``) and ζ = δ/√(4π² + δ²) in the legend.

    ``runs``: dicts with ``label``, ``time_s``, ``theta_rad`` and the drop-test metrics
    (``peak_times_s``, ``peaks_deg``, ``log_decrement``, ``damping_ratio``, ``period_s``), plus
    ``release_estimated`` (the release found from the data, or known from the backend).
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.8), dpi=110)
    for run in runs:
        theta_deg = np.degrees(run["theta_rad"])
        ratio, decrement = run.get("damping_ratio"), run.get("log_decrement")
        label = run["label"]
        if ratio is not None:
            label += f": ζ = {ratio:.3f} (δ = {decrement:.3f})"
        (line,) = ax.plot(run["time_s"], theta_deg, linewidth=1.0, label=label)
        peaks, times = run.get("peaks_deg") or [], run.get("peak_times_s") or []
        count = min(len(peaks), len(times))
        if count:
            ax.plot(times[:count], peaks[:count], "v", color=line.get_color(), markersize=5)
        period = run.get("period_s")
        if count >= 2 and decrement is not None and period:
            t = np.linspace(times[0], run["time_s"][-1], 200)
            ax.plot(t, peaks[0] * np.exp(-decrement * (t - times[0]) / period), "--", color=line.get_color(), lw=0.7)
    if band_deg is not None:
        ax.axhspan(-band_deg, band_deg, color="0.85", zorder=0, label=f"±{band_deg:g}° settling band")
    estimated = any(run.get("release_estimated") for run in runs)
    ax.axvline(
        0.0,
        color="0.3",
        linewidth=0.8,
        linestyle=":",
        label="release (detected from the data)" if estimated else "release (by the backend)",
    )
    ax.axhline(0.0, color="0.4", linewidth=0.6)
    ax.set_xlabel("time after release [s]")
    ax.set_ylabel("arm angle θ [deg]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, path)


def transmissibility_axes(ax: Any) -> None:
    """Log-log axes for a transmissibility plot, with the unity line (what passes unchanged)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1.0, color="0.4", linewidth=0.6)
    ax.set_xlabel("road frequency [Hz]")
    ax.set_ylabel("transmissibility RMS(θ2) / RMS(θ1)")
    ax.grid(True, which="both", alpha=0.3)
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.xaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def plot_transmissibility(
    path: str | Path, curves: Sequence[tuple[str, Sequence[float] | np.ndarray, Sequence[float] | np.ndarray]]
) -> Path:
    """``transmissibility.png``: body RMS / road RMS against frequency on log-log axes;
    ``curves`` = [(label, frequency_hz, transmissibility), ...]."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    for label, freq, trans in curves:
        ax.plot(freq, trans, "o-", markersize=3, label=label)
    transmissibility_axes(ax)
    ax.set_title("transmissibility (stepped sine)")
    ax.legend(fontsize=8)
    return save_figure(fig, path)


#: the percentiles a timing plot marks (the tail is what a real-time loop is judged by)
TIMING_PERCENTILES = (50.0, 90.0, 99.0, 99.9, 99.99)


def plot_timing(path: str | Path, runs: Sequence[tuple[str, dict]]) -> Path:
    """``timing.png``: wake-up lateness and compute time as percentile curves ("how late is the
    worst x % of cycles"), on a log axis of 1/(1 − p) so p50, p99, p99.9 and the maximum are evenly
    spaced; a few outliers no longer hide the distribution. ``runs`` = [(label, timing.npz arrays)]."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for ax, key, title in (
        (axes[0], "lateness_ns", "wake-up lateness"),
        (axes[1], "compute_ns", "compute time per cycle"),
    ):
        for label, timing in runs:
            values = np.asarray(timing.get(key, ()), dtype=float) * 1e-3
            if values.size == 0:
                continue
            p = np.concatenate([np.linspace(0.0, 99.0, 100), 100.0 - np.geomspace(1.0, 100.0 / values.size, 100)])
            p = np.clip(p, 0.0, 100.0 * (1.0 - 1.0 / values.size))
            (line,) = ax.plot(100.0 / (100.0 - p), np.percentile(values, p), lw=1.0, label=label)
            marks = [q for q in TIMING_PERCENTILES if q < 100.0 * (1.0 - 1.0 / values.size)]
            ax.plot([100.0 / (100.0 - q) for q in marks], np.percentile(values, marks), "o", color=line.get_color())
            ax.plot([values.size], [values.max()], "x", color=line.get_color())
        ticks = list(TIMING_PERCENTILES)
        ax.set_xscale("log")
        ax.set_yscale("symlog", linthresh=10.0)  # linear below 10 µs, logarithmic above
        ax.set_ylim(bottom=0.0)
        ax.set_xticks([100.0 / (100.0 - q) for q in ticks])
        ax.set_xticklabels([f"p{q:g}" for q in ticks])
        ax.set_xlabel("percentile of cycles (× : the maximum)")
        ax.set_ylabel(f"{title} [µs]")
        ax.set_title(title)
        ax.grid(True, which="major", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_chirp(path: str | Path, columns: dict, title: str) -> Path:
    """``chirp.png`` of a chirp sweep: road θ1 and body θ2 against time (the chirp's frequency
    range in ``title``), and the measured and commanded coil current."""
    plt = pyplot()
    t = np.asarray(columns["time_s"])
    road = np.asarray(columns["theta_road_rad"])
    body = np.asarray(columns["theta_rad"]) + road
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), dpi=110, sharex=True)
    axes[0].plot(t, np.degrees(road), lw=0.8, label="road θ1")
    axes[0].plot(t, np.degrees(body), lw=0.8, label="body θ2 = θ + θ1")
    axes[0].set_ylabel("angle [deg]")
    axes[0].set_title(title)
    axes[1].plot(t, columns["current_a"], lw=0.8, label="measured i")
    axes[1].plot(t, columns["current_cmd_a"], lw=0.6, alpha=0.7, label="commanded i*")
    axes[1].set_ylabel("coil current [A]")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    return save_figure(fig, path)

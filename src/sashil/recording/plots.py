"""PNG plots of runs (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sashil.config.recorded import RecordedModel
from sashil.recording.data_file import read_data_csv
from sashil.recording.labels import controller_label


class _Figures:
    """``subplots(...)`` as pyplot has it, for figures that are only ever written to a file: each a
    :class:`matplotlib.figure.Figure` on the Agg canvas, with none of pyplot's global state (and its
    import, a sixth of a second, is not paid)."""

    SUBPLOT_KEYS = ("sharex", "sharey", "squeeze", "width_ratios", "height_ratios", "subplot_kw", "gridspec_kw")

    @classmethod
    def subplots(cls, nrows: int = 1, ncols: int = 1, **kwargs: Any) -> tuple[Any, Any]:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        layout = {key: kwargs.pop(key) for key in cls.SUBPLOT_KEYS if key in kwargs}
        fig = Figure(**kwargs)
        FigureCanvasAgg(fig)
        return fig, fig.subplots(nrows, ncols, **layout)


def pyplot() -> _Figures:
    """The figure factory of every plot sashil writes (``pyplot().subplots(...)``, imported on first
    use: the loop never pays for it)."""
    return _Figures()


def save_figure(fig: Any, path: str | Path, dpi: float | None = None, layout: bool = True) -> Path:
    """Lay out (unless the caller did: ``layout`` False), write and close ``fig``; returns the path."""
    if layout:
        fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=dpi if dpi is not None else "figure")
    return path


#: legend placement beside an axes (outside it, so no legend covers a trace)
BESIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0, "fontsize": 8}


def has_values(cols: dict[str, np.ndarray], name: str) -> bool:
    """Whether ``cols`` holds column ``name`` with at least one finite value (a law without a
    target torque, e.g. an on-off law, records ``torque_cmd_nm`` as all NaN)."""
    return name in cols and bool(np.isfinite(cols[name]).any())


def read_run_config(folder: str | Path) -> dict[str, Any]:
    """The run folder's ``config.yaml`` as a mapping ({} when absent or unreadable)."""
    import yaml

    try:
        doc = yaml.safe_load((Path(folder) / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, ValueError, yaml.YAMLError):
        return {}
    return doc if isinstance(doc, dict) else {}


def add_feasible_band(cols: dict[str, np.ndarray], config: dict[str, Any]) -> bool:
    """Make sure ``cols`` holds ``band_lo_nm``/``band_hi_nm``, the torque range T(0)..T(i_max) of the
    damper at the observed state: as recorded, or computed from ``z_hat`` and ``theta_dot_rad_s`` with
    the Bouc-Wen model of the run's config. Returns whether the band is there."""
    if not (has_values(cols, "band_lo_nm") and has_values(cols, "band_hi_nm")):
        model = RecordedModel.read(config)
        if model.name != "bouc-wen" or model.params is None or model.current_max_a is None:
            return False
        if not (has_values(cols, "z_hat") and has_values(cols, "theta_dot_rad_s")):
            return False
        from sashil.recording.rerun_log import feasible_band

        cols.pop("band_lo_nm", None)
        cols.pop("band_hi_nm", None)
        try:
            feasible_band(cols, model.params, model.current_max_a)
        except (KeyError, TypeError, ValueError):
            return False
    return "band_lo_nm" in cols and "band_hi_nm" in cols


def _angles_panel(ax: Any, cols: dict[str, np.ndarray]) -> None:
    """θ, and the road θ1 and arm θ2 = θ + θ1 when the road moves."""
    t = cols["time_s"]
    if "theta_rad" in cols:
        ax.plot(t, np.degrees(cols["theta_rad"]), lw=0.9, label="θ (relative angle)")
    road = cols.get("theta_road_rad")
    if road is not None and np.any(road):
        ax.plot(t, np.degrees(road), lw=0.9, label="θ1 (road)")
        if "theta_rad" in cols:
            ax.plot(t, np.degrees(cols["theta_rad"] + road), lw=0.8, label="θ2 (arm)")
    ax.set_ylabel("angle [deg]")


def _current_panel(ax: Any, cols: dict[str, np.ndarray]) -> None:
    """Measured and commanded coil current, and a current law's own output (what it asked for)."""
    traces = (
        ("current_a", "measured i", "-"),
        ("current_cmd_a", "commanded i*", "-"),
        ("current_law_a", "law's i", ":"),
    )
    for name, label, style in traces:
        if has_values(cols, name):
            ax.plot(cols["time_s"], cols[name], lw=0.9, ls=style, label=label)
    ax.set_ylabel("coil current [A]")


def _torque_panel(ax: Any, cols: dict[str, np.ndarray], band: bool) -> None:
    """Observer T̂, target T* (when the law sets one) and the feasible band T(0)..T(i_max)."""
    t = cols["time_s"]
    if band:
        ax.fill_between(
            t,
            cols["band_lo_nm"],
            cols["band_hi_nm"],
            color="tab:green",
            alpha=0.18,
            lw=0,
            label="feasible band, 0 A … i_max",
        )
    for name, label in (("torque_hat_nm", "observer T̂"), ("torque_cmd_nm", "target T*")):
        if has_values(cols, name):
            ax.plot(t, cols[name], lw=0.8, label=label)
    ax.set_ylabel("damper torque [N·m]")


def run_title(summary: dict | None, config: dict[str, Any] | None = None) -> str:
    """``sashil run: <law and parameters>, <backend>, road …, lateness p99 …, trips``."""
    title = "sashil run"
    if not summary:
        return title

    parts = [controller_label(summary, config or {}), f"{summary.get('driver', '?')} backend"]
    if summary.get("road"):
        parts.append(f"road {summary['road']}")
    late = (summary.get("timing") or {}).get("lateness_us") or {}
    if late.get("p99") is not None:
        parts.append(f"lateness p99 {late['p99']:.0f} µs")
    if summary.get("trips"):
        parts.append(f"{len(summary['trips'])} trip(s)")
    if summary.get("exit_status") == "lossy":
        parts.append(f"LOSSY: {summary.get('error')}")
    return f"{title}: " + ", ".join(parts)


def _mark_live_changes(axes: Any, tuning: dict | None) -> None:
    """A dotted line on every panel at each live parameter change (``summary.json`` → ``tuning``),
    named on the top panel."""
    if not tuning:
        return
    for event in tuning.get("events", ()):
        if event.get("status") != "applied" or event.get("time_s") is None:
            continue
        for ax in axes:
            ax.axvline(event["time_s"], color="0.3", lw=0.8, ls=":")
        ramp = f" ({event['ramp_s']:g} s ramp)" if event.get("ramp_s") else ""
        axes[0].annotate(
            f"{event['key']} = {event['new']}{ramp}",
            (event["time_s"], 1.0),
            xycoords=("data", "axes fraction"),
            rotation=90,
            fontsize=7,
            va="top",
            ha="right",
        )


def plot_run(path: str | Path, folder: str | Path, summary: dict | None = None) -> Path:
    """``run.png`` of a loop run folder: angles (θ, and the road θ1 and arm θ2 when the road moves),
    coil current (measured and commanded) and damper torque (observer T̂, target T* when the law
    sets one, and the feasible band T(0)..T(i_max) at the observed state). Legends sit beside the
    panels, outside the traces."""
    cols = read_data_csv(Path(folder) / "data.csv", required=("time_s",), min_rows=0)
    config = read_run_config(folder)
    has_torque = has_values(cols, "torque_hat_nm") or has_values(cols, "torque_cmd_nm")
    rows = 3 if has_torque else 2
    plt = pyplot()
    fig, axes = plt.subplots(rows, 1, figsize=(10.5, 2.4 * rows + 0.7), dpi=110, sharex=True)
    _angles_panel(axes[0], cols)
    _current_panel(axes[1], cols)
    if has_torque:
        _torque_panel(axes[2], cols, add_feasible_band(cols, config))
    _mark_live_changes(axes, (summary or {}).get("tuning"))
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(**BESIDE)
    axes[-1].set_xlabel("time [s]")
    # from the left edge, wrapped to the figure's width: a long title is never cut
    axes[0].set_title(textwrap.fill(run_title(summary, config), 110), fontsize=10, loc="left")
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


#: mantissas of the ticks on a log axis, densest first: 1-2-3-5 (0.3, 0.5, 1, 2, 3, 5), then sparser
LOG_TICK_MANTISSAS = ((1, 2, 3, 5), (1, 2, 5), (1, 3), (1,))


def readable_log_ticks(low: float, high: float, most: int = 8) -> list[float]:
    """Tick values within [low, high] (both > 0) a reader reads off a log axis: 0.3, 0.5, 1, 2, 5, …;
    the densest 1-2-3-5 style set with at most ``most`` ticks. A range narrower than one such step
    gets evenly spaced round values instead."""
    low, high = sorted((float(low), float(high)))
    if not (low > 0.0 and np.isfinite(high)):
        return []
    decades = range(int(np.floor(np.log10(low))), int(np.ceil(np.log10(high))) + 1)
    ticks: list[float] = []
    for mantissas in LOG_TICK_MANTISSAS:
        ticks = [float(f"{m * 10.0**e:.6g}") for e in decades for m in mantissas if low <= m * 10.0**e <= high]
        if len(ticks) <= most:
            break
    if len(ticks) < 2:
        from matplotlib.ticker import MaxNLocator

        steps = MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]).tick_values(low, high)
        ticks = [float(f"{v:.6g}") for v in steps if low <= v <= high]
    return ticks


def tick_text(value: float, _pos: Any = None) -> str:
    """A tick label without exponent notation: ``0.3``, ``5``, ``200``, ``1e+04`` only past 10⁵."""
    return f"{value:g}" if abs(value) < 1e5 else f"{value:.0e}"


def set_readable_log_ticks(axis: Any, low: float, high: float, extra: Sequence[float] = ()) -> None:
    """Major ticks of a log (or symlog) ``axis`` at :func:`readable_log_ticks` plus ``extra`` (e.g. 0
    on a symlog axis), labelled as plain numbers; minor ticks unlabelled."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    axis.set_major_locator(FixedLocator(sorted({*extra, *readable_log_ticks(low, high)})))
    axis.set_major_formatter(FuncFormatter(tick_text))
    axis.set_minor_formatter(NullFormatter())


def transmissibility_axes(ax: Any) -> None:
    """Log-log axes for a transmissibility plot (call after plotting), with the unity line (what
    passes unchanged) and readable ticks on both axes (0.3, 0.5, 1, 2, 5)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1.0, color="0.4", linewidth=0.6)
    ax.set_xlabel("road frequency [Hz]")
    ax.set_ylabel("transmissibility RMS(θ2) / RMS(θ1)")
    ax.grid(True, which="major", alpha=0.35)
    ax.grid(True, which="minor", alpha=0.12)
    ax.autoscale_view()
    for axis, (low, high) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        set_readable_log_ticks(axis, low, high)


def plot_transmissibility(
    path: str | Path,
    curves: Sequence[tuple[str, Sequence[float] | np.ndarray, Sequence[float] | np.ndarray]],
    title: str = "transmissibility (stepped sine)",
) -> Path:
    """``transmissibility.png``: body RMS / road RMS against frequency on log-log axes;
    ``curves`` = [(label, frequency_hz, transmissibility), ...], labelled by law and current."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    for label, freq, trans in curves:
        ax.plot(freq, trans, "o-", markersize=3, label=label)
    transmissibility_axes(ax)
    ax.set_title(title)
    ax.legend(fontsize=8, loc="lower left")
    return save_figure(fig, path)


#: the percentiles a timing plot marks (the tail is what a real-time loop is judged by)
TIMING_PERCENTILES = (50.0, 90.0, 99.0, 99.9, 99.99)

#: below this [µs] a timing axis that holds zeros is linear (symlog), above logarithmic
TIMING_LINEAR_US = 1.0


def _percentile_curve(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of a percentile curve: x = 1/(1 − p) from p0 to the last percentile below the maximum."""
    p = np.concatenate([np.linspace(0.0, 99.0, 100), 100.0 - np.geomspace(1.0, 100.0 / values.size, 100)])
    p = np.clip(p, 0.0, 100.0 * (1.0 - 1.0 / values.size))
    return 100.0 / (100.0 - p), np.percentile(values, p)


def _timing_panel(ax: Any, runs: Sequence[tuple[str, dict]], key: str, title: str) -> None:
    """One timing quantity of every run: curve, percentile marks (●) and the maximum (×), with the
    x axis ending just past the longest run's maximum and y ticks a reader can read."""
    cycles, values_all = 1, []
    for label, timing in runs:
        values = np.asarray(timing.get(key, ()), dtype=float) * 1e-3
        if values.size == 0:
            continue
        values_all.append(values)
        cycles = max(cycles, values.size)
        x, y = _percentile_curve(values)
        (line,) = ax.plot(x, y, lw=1.0, label=label)
        marks = [q for q in TIMING_PERCENTILES if q < 100.0 * (1.0 - 1.0 / values.size)]
        ax.plot([100.0 / (100.0 - q) for q in marks], np.percentile(values, marks), "o", color=line.get_color())
        ax.plot([values.size], [values.max()], "x", color=line.get_color(), markersize=7, mew=1.5, clip_on=False)
    ax.set_xscale("log")
    ticks = [q for q in TIMING_PERCENTILES if 100.0 / (100.0 - q) <= cycles]
    ax.set_xticks([100.0 / (100.0 - q) for q in ticks])
    ax.set_xticklabels([f"p{q:g}" for q in ticks])
    ax.xaxis.set_minor_formatter(_null_formatter())
    ax.set_xlim(0.9, cycles * 1.6)
    _timing_y_axis(ax, np.concatenate(values_all) if values_all else np.zeros(0))
    ax.set_xlabel("percentile of cycles (× : the maximum)")
    ax.set_ylabel(f"{title} [µs]")
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)


def _null_formatter() -> Any:
    from matplotlib.ticker import NullFormatter

    return NullFormatter()


def _timing_y_axis(ax: Any, values: np.ndarray) -> None:
    """Log y (symlog, linear below TIMING_LINEAR_US, when some values are 0) from the smallest to
    above the largest value, so the maximum's × is not cut, with readable ticks."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return
    top = max(float(finite.max()), TIMING_LINEAR_US) * 1.8
    positive = finite[finite > 0]
    if positive.size == finite.size:
        bottom = float(positive.min()) / 1.5
        ax.set_yscale("log")
        ax.set_ylim(bottom, top)
        set_readable_log_ticks(ax.yaxis, bottom, top)
    else:
        ax.set_yscale("symlog", linthresh=TIMING_LINEAR_US, linscale=0.5)
        ax.set_ylim(0.0, top)
        set_readable_log_ticks(ax.yaxis, TIMING_LINEAR_US, top, extra=(0.0,))


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
        _timing_panel(ax, runs, key, title)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="upper left")
    return save_figure(fig, path)


def chirp_frequency(time_s: np.ndarray, f_start_hz: float, f_stop_hz: float, sweep_s: float) -> np.ndarray:
    """Instantaneous road frequency of the linear chirp at ``time_s`` (held at ``f_stop_hz`` after
    ``sweep_s``), as :func:`sashil.lab._sweep.chirp_profile` drives it."""
    frac = np.clip(np.asarray(time_s, dtype=float) / sweep_s, 0.0, 1.0)
    return f_start_hz + (f_stop_hz - f_start_hz) * frac


def _frequency_axis(ax: Any, f_start_hz: float, f_stop_hz: float, sweep_s: float) -> Any:
    """A second x axis on top of ``ax`` marking the chirp's instantaneous frequency (linear in time;
    ``f_stop_hz`` above ``f_start_hz``)."""
    from matplotlib.ticker import MaxNLocator

    top = ax.secondary_xaxis("top")
    steps = MaxNLocator(nbins=10, steps=[1, 2, 2.5, 5, 10]).tick_values(f_start_hz, f_stop_hz)
    ticks = [float(f"{f:.6g}") for f in steps if f_start_hz - 1e-9 <= f <= f_stop_hz + 1e-9]
    top.set_xticks([sweep_s * (f - f_start_hz) / (f_stop_hz - f_start_hz) for f in ticks])
    top.set_xticklabels([tick_text(f) for f in ticks])
    top.set_xlabel("road frequency [Hz]")
    return top


def plot_chirp(
    path: str | Path,
    columns: dict,
    title: str,
    chirp: tuple[float, float, float] | None = None,
) -> Path:
    """``chirp.png`` of a chirp sweep: road θ1 and body θ2 against time and the measured and commanded
    coil current; with ``chirp`` = (f_start_hz, f_stop_hz, sweep_s) a second axis on top reads the
    instantaneous road frequency (a fast chirp's largest swing lags the resonance: for the
    resonance itself, a stepped sweep's transmissibility)."""
    plt = pyplot()
    t = np.asarray(columns["time_s"])
    road = np.asarray(columns["theta_road_rad"])
    body = np.asarray(columns["theta_rad"]) + road
    fig, axes = plt.subplots(2, 1, figsize=(10.5, 6.0), dpi=110, sharex=True)
    axes[0].plot(t, np.degrees(road), lw=0.8, label="road θ1")
    axes[0].plot(t, np.degrees(body), lw=0.8, label="body θ2 = θ + θ1")
    axes[0].set_ylabel("angle [deg]")
    axes[1].plot(t, columns["current_a"], lw=0.8, label="measured i")
    if has_values(columns, "current_cmd_a"):
        axes[1].plot(t, columns["current_cmd_a"], lw=0.6, alpha=0.7, label="commanded i*")
    axes[1].set_ylabel("coil current [A]")
    axes[1].set_xlabel("time [s]")
    if chirp is not None and chirp[1] > chirp[0]:  # a sine (f_stop = f_start) has one frequency: in the title
        _frequency_axis(axes[0], *chirp)
    axes[0].set_title(title, fontsize=10)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(**BESIDE)
    return save_figure(fig, path)

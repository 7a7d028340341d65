"""``sashil report``: plots and a Markdown summary comparing run folders.

For each run folder (``summary.json`` plus ``data.csv``, or sub-folders per current for a
multi-current drop test) the report collects the recorded traces and writes:

* ``theta.png`` — θ(t) of every trace overlaid (degrees);
* ``hysteresis.png`` — damper torque against θ̇ and against θ. The observer's T̂
  (``torque_hat_nm``) when the run recorded it; otherwise, for a drop test (θ1 = 0, no input
  torque), the torque the rig equation implies, seed 001 eq. 13: ``T_d = −k·θ − J·θ̈`` with θ̇, θ̈
  from a Savitzky–Golay fit (k, J from the run's config.yaml);
* ``transmissibility.png`` — when a run holds a sweep table (``transmissibility.csv``);
* ``timing.png`` — loop lateness and compute time as percentile curves (p50, p99, p99.9, …, the
  maximum) when a run holds per-cycle timing (``timing.npz``);
* ``report.md`` — the runs side by side: exit status, drop-test metrics per current, timing.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sashil.errors import DataFileError
from sashil.recording.data_file import read_data_csv
from sashil.recording.plots import pyplot, save_figure

#: Savitzky-Golay window for the drop-test torque estimate [s] and polynomial order
SG_WINDOW_S = 0.121
SG_ORDER = 3


@dataclass
class Trace:
    label: str
    columns: dict[str, np.ndarray]
    metrics: dict[str, Any] | None = None
    params: dict[str, float] | None = None


@dataclass
class RunRecord:
    path: Path
    label: str
    summary: dict[str, Any]
    traces: list[Trace] = field(default_factory=list)
    sweep: dict[str, np.ndarray] | None = None
    timing: dict[str, np.ndarray] | None = None


def _read_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataFileError(f"{path}: no such file (is {path.parent} a sashil run folder?)") from None
    except (OSError, ValueError) as err:
        raise DataFileError(f"{path}: not readable JSON ({err})") from None
    if not isinstance(doc, dict):
        raise DataFileError(f"{path}: expected a JSON object")
    return doc


def _model_params(folder: Path) -> dict[str, float] | None:
    """k, J of the run's config.yaml (None when absent)."""
    try:
        import yaml

        config = yaml.safe_load((folder / "config.yaml").read_text(encoding="utf-8"))
        params = config["model"]["params"]
        return {"k": float(params["k"]), "J": float(params.get("J", 1.0))}
    except (OSError, KeyError, TypeError, ValueError, ImportError):
        return None
    except Exception:
        return None


def load_run(path: str | Path) -> RunRecord:
    """One run folder: its summary, its traces (one per drop-test current), sweep table, timing."""
    path = Path(path)
    if not path.is_dir():
        raise DataFileError(f"{path}: not a folder (expected a sashil run folder)")
    summary = _read_json(path / "summary.json")
    record = RunRecord(path, path.name, summary)
    runs = summary.get("runs") if isinstance(summary.get("runs"), list) else None
    if summary.get("mode") == "stepped":
        runs = None  # a stepped sweep's sub-runs (one per frequency) are summarised by its table
    if runs:
        for entry in runs:
            sub = path / str(entry.get("folder", "."))
            label = (
                f"{path.name} {entry.get('current_a', '?'):g} A"
                if isinstance(entry.get("current_a"), (int, float))
                else path.name
            )
            columns = read_data_csv(sub / "data.csv")
            record.traces.append(Trace(label, columns, entry, _model_params(sub) or _model_params(path)))
    elif (path / "data.csv").exists():
        record.traces.append(Trace(path.name, read_data_csv(path / "data.csv"), None, _model_params(path)))
    table = path / "transmissibility.csv"
    if table.exists():
        record.sweep = read_data_csv(table, required=("frequency_hz", "transmissibility"), min_rows=1)
    timing = path / "timing.npz"
    if timing.exists():
        try:
            with np.load(timing) as data:
                record.timing = {name: np.asarray(data[name]) for name in data.files}
        except (OSError, ValueError) as err:
            raise DataFileError(f"{timing}: not a readable timing file ({err})") from None
    if not record.traces and record.sweep is None:
        raise DataFileError(f"{path}: no data.csv or transmissibility.csv in this run folder")
    return record


def drop_torque(time_s: np.ndarray, theta: np.ndarray, k: float, J: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θ, θ̇, T_d) (smoothed) of a drop test from the rig equation (seed 001 eq. 13 with θ1 = 0, T_in = 0):
    ``J θ̈ = −k θ − T_d`` so ``T_d = −k θ − J θ̈``; θ̇, θ̈ from a Savitzky–Golay fit."""
    from scipy.signal import savgol_filter

    dt = float(np.median(np.diff(time_s)))
    window = max(int(round(SG_WINDOW_S / dt)) | 1, SG_ORDER + 2 | 1)
    if theta.size <= window:
        raise DataFileError(f"drop test record of {theta.size} samples is too short for the torque estimate")
    smooth = savgol_filter(theta, window, SG_ORDER)
    velocity = savgol_filter(theta, window, SG_ORDER, deriv=1, delta=dt)
    accel = savgol_filter(theta, window, SG_ORDER, deriv=2, delta=dt)
    return smooth, velocity, -k * smooth - J * accel


def hysteresis_of(trace: Trace) -> tuple[np.ndarray, np.ndarray, np.ndarray, str] | None:
    """(θ, θ̇, torque, what the torque is) of a trace, or None when neither source exists."""
    cols = trace.columns
    if "torque_hat_nm" in cols and np.isfinite(cols["torque_hat_nm"]).any():
        velocity = cols.get("theta_dot_rad_s")
        if velocity is None:
            velocity = np.gradient(cols["theta_rad"], cols["time_s"])
        return cols["theta_rad"], velocity, cols["torque_hat_nm"], "observer T̂"
    road = cols.get("theta_road_rad")
    if trace.params is not None and (road is None or not np.any(road)) and "torque_in_nm" not in cols:
        theta, velocity, torque = drop_torque(cols["time_s"], cols["theta_rad"], trace.params["k"], trace.params["J"])
        return theta, velocity, torque, "T_d = −kθ − Jθ̈"
    return None


# plots ---------------------------------------------------------------------------------------


def _axes(ax: Any, xlabel: str, ylabel: str, title: str | None = None) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)


def plot_theta(path: Path, traces: Sequence[Trace]) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.5), dpi=110)
    for trace in traces:
        ax.plot(trace.columns["time_s"], np.degrees(trace.columns["theta_rad"]), linewidth=1.0, label=trace.label)
    ax.axhline(0.0, color="0.4", linewidth=0.6)
    _axes(ax, "time [s]", "arm angle θ [deg]", "θ(t)")
    ax.legend(loc="upper right", fontsize=8)
    return save_figure(fig, path)


def plot_hysteresis(path: Path, loops: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray, str]]) -> Path:
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for label, theta, velocity, torque, source in loops:
        left.plot(velocity, torque, linewidth=0.7, label=f"{label} ({source})")
        right.plot(np.degrees(theta), torque, linewidth=0.7, label=label)
    _axes(left, "θ̇ [rad/s]", "damper torque [N·m]", "torque against velocity")
    _axes(right, "θ [deg]", "damper torque [N·m]", "torque against angle")
    left.legend(fontsize=7)
    return save_figure(fig, path)


def plot_transmissibility(path: Path, runs: Sequence[RunRecord]) -> Path:
    """Transmissibility of every stepped sweep among ``runs``, log-log."""
    from sashil.recording import plots

    curves = [
        (run.label, run.sweep["frequency_hz"], run.sweep["transmissibility"]) for run in runs if run.sweep is not None
    ]
    return plots.plot_transmissibility(path, curves)


def plot_timing(path: Path, runs: Sequence[RunRecord]) -> Path:
    """Loop timing of every run with ``timing.npz`` as percentile curves (p50 ... max)."""
    from sashil.recording import plots

    return plots.plot_timing(path, [(run.label, run.timing) for run in runs if run.timing is not None])


# summary -------------------------------------------------------------------------------------
def _fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}g}" if abs(value) < 10**digits else f"{value:.0f}"
    if isinstance(value, list):
        return ", ".join(_fmt(v, digits) for v in value[:4]) + (" …" if len(value) > 4 else "")
    return str(value)


DROP_ROWS = (
    ("current [A]", "current_a"),
    ("period [s]", "period_s"),
    ("frequency [Hz]", "frequency_hz"),
    ("log decrement", "log_decrement"),
    ("damping ratio", "damping_ratio"),
    ("first peaks [deg]", "peaks_deg"),
    ("settling time [s]", "settling_time_s"),
)


def markdown_summary(runs: Sequence[RunRecord], plots: Sequence[Path]) -> str:
    lines = ["# sashil report", "", "Runs: " + ", ".join(f"`{run.path}`" for run in runs), ""]
    lines += ["| run | verb | exit status | started (UTC) | sashil | git |", "|---|---|---|---|---|---|"]
    for run in runs:
        s, prov = run.summary, run.summary.get("provenance") or {}
        lines.append(
            f"| {run.label} | {_fmt(s.get('verb'))} | {_fmt(s.get('exit_status'))} | {_fmt(s.get('started_utc'))} "
            f"| {_fmt(prov.get('sashil_version'))} | {_fmt(prov.get('git_revision'))} |"
        )
    drops = [trace for run in runs for trace in run.traces if trace.metrics]
    if drops:
        lines += ["", "## Drop tests", "", "| metric | " + " | ".join(t.label for t in drops) + " |"]
        lines.append("|---" * (len(drops) + 1) + "|")
        for title, key in DROP_ROWS:
            lines.append(f"| {title} | " + " | ".join(_fmt(t.metrics.get(key)) for t in drops) + " |")  # type: ignore[union-attr]
    timed = [run for run in runs if isinstance(run.summary.get("timing"), dict)]
    if timed:
        lines += ["", "## Loop timing", "", "| | " + " | ".join(run.label for run in timed) + " |"]
        lines.append("|---" * (len(timed) + 1) + "|")
        rows: list[tuple[str, Callable[[dict], Any]]] = [
            ("rate [Hz]", lambda t: t.get("rate_hz")),
            ("cycles", lambda t: t.get("cycles")),
            ("missed deadlines", lambda t: t.get("missed_deadlines")),
            ("lateness p50 / p99 / max [µs]", lambda t: _triple(t.get("lateness_us"))),
            ("compute p50 / p99 / max [µs]", lambda t: _triple(t.get("compute_us"))),
        ]
        for title, get in rows:
            lines.append(f"| {title} | " + " | ".join(_fmt(get(run.summary["timing"])) for run in timed) + " |")
        lines.append("| trips | " + " | ".join(_trips(run.summary.get("trips")) for run in timed) + " |")
    if plots:
        lines += ["", "## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots]
    return "\n".join(lines) + "\n"


def _triple(stats: Any) -> str:
    if not isinstance(stats, dict):
        return "–"
    return " / ".join(_fmt(stats.get(key), 4) for key in ("p50", "p99", "max"))


def _trips(trips: Any) -> str:
    if not trips:
        return "none"
    return "; ".join(f"{_fmt(t.get('time_s'))} s {t.get('reason', '')}" for t in trips)


def write_report(
    run_dirs: Sequence[str | Path], out: Path, progress: Callable[[str], None] = lambda _: None
) -> tuple[list[RunRecord], list[Path]]:
    """Load ``run_dirs``, write the plots and ``report.md`` into ``out``; returns runs and files."""
    runs = []
    for run_dir in run_dirs:
        progress(f"reading {run_dir}")
        runs.append(load_run(run_dir))
    traces = [trace for run in runs for trace in run.traces]
    plots: list[Path] = []
    if traces:
        progress("plotting θ(t)")
        plots.append(plot_theta(out / "theta.png", traces))
        loops = []
        for trace in traces:
            loop = hysteresis_of(trace)
            if loop is not None:
                loops.append((trace.label, *loop))
        if loops:
            progress("plotting hysteresis loops")
            plots.append(plot_hysteresis(out / "hysteresis.png", loops))
    if any(run.sweep is not None for run in runs):
        progress("plotting transmissibility")
        plots.append(plot_transmissibility(out / "transmissibility.png", runs))
    if any(run.timing is not None for run in runs):
        progress("plotting timing percentiles")
        plots.append(plot_timing(out / "timing.png", runs))
    summary = out / "report.md"
    summary.write_text(markdown_summary(runs, plots), encoding="utf-8")
    return runs, [*plots, summary]

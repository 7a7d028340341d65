"""``sashil report``: plots and a Markdown summary comparing run folders.

For each run folder (``summary.json`` plus ``data.csv``, or sub-folders per current for a
multi-current drop test) the report collects the recorded traces, names each by its law, the
law's parameters and current (not by its folder), and writes:

* ``theta.png`` — θ(t) of every trace overlaid (degrees);
* ``hysteresis.png`` — damper torque against θ̇ and against θ. The observer's T̂
  (``torque_hat_nm``) when the run recorded it; otherwise, for a drop test (θ1 = 0, no input
  torque), the torque the rig equation implies, seed 001 eq. 13: ``T_d = −k·θ − J·θ̈`` with θ
  low-passed (zero phase) at three times the natural frequency before it is differentiated, up to
  the settling time (k, J from the run's config.yaml); the legend says which;
* ``transmissibility.png`` — when a run holds a sweep table (``transmissibility.csv``);
* ``timing.png`` — loop lateness and compute time as percentile curves (p50, p99, p99.9, …, the
  maximum) when a run holds per-cycle timing (``timing.npz``);
* ``report.md`` — the runs side by side: controller and parameters, road, RMS body angle and
  acceleration, clipped share, transmissibility, drop-test metrics per current, timing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sashil.api import load_run
from sashil.config.recorded import RecordedModel
from sashil.errors import DataFileError
from sashil.recording import plots
from sashil.recording.labels import (
    changed_parameters,
    controller_label,
    controller_section,
    format_parameters,
    format_value,
    law_name,
    law_parameters,
    unique_labels,
)
from sashil.recording.plots import BESIDE, pyplot, save_figure

#: the drop-test torque's low-pass cut-off as a multiple of the natural frequency sqrt(k/J)/2pi
DROP_CUTOFF_RATIO = 3.0
#: the body acceleration's low-pass cut-off [Hz] (above the sweeps' 5 Hz, below the encoder's noise)
BODY_ACCEL_CUTOFF_HZ = 10.0
#: order of the (zero-phase, forward-backward) Butterworth low-pass
LOWPASS_ORDER = 4


@dataclass
class Trace:
    """One recorded time series: its label (law, parameters, current), columns, drop-test metrics,
    the model's k and J, and its run folder's summary and config (what ran)."""

    label: str
    columns: dict[str, np.ndarray]
    metrics: dict[str, Any] | None = None
    params: dict[str, float] | None = None
    folder: str = ""
    #: the trace's own run: its config.yaml and summary.json (a sub-run's, else the folder's)
    config: dict[str, Any] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass
class RunRecord:
    """One run folder: its summary, config, traces, sweep table and loop timing."""

    path: Path
    label: str
    summary: dict[str, Any]
    traces: list[Trace] = field(default_factory=list)
    sweep: dict[str, np.ndarray] | None = None
    timing: dict[str, np.ndarray] | None = None
    config: dict[str, Any] = field(default_factory=dict)


def _model_params(config: dict[str, Any]) -> dict[str, float] | None:
    """k, J of a run's config (None when it has no model)."""
    params = RecordedModel.read(config).params
    try:
        return {"k": float(params["k"]), "J": float(params.get("J", 1.0))} if params is not None else None
    except (KeyError, TypeError, ValueError):
        return None


def _trace_label(entry: dict[str, Any] | None, summary: dict[str, Any], config: dict[str, Any]) -> str:
    """A trace's name: the law and its parameters; a drop-test current's own ``controller`` entry
    (``passive 1 A``) when the summary lists one per current."""
    if entry and isinstance(entry.get("controller"), str):
        return controller_label({"controller": entry["controller"]}, config)
    if entry and isinstance(entry.get("current_a"), (int, float)):
        return controller_label({"controller": f"passive {entry['current_a']:g} A"}, config)
    return controller_label(summary, config)


def read_record(path: str | Path) -> RunRecord:
    """One run folder as the report needs it: its summary, its traces (one per drop-test current),
    sweep table and timing, read through :func:`sashil.api.load_run`, the one run-folder reader."""
    run = load_run(path)
    if not (run.path / "summary.json").is_file():
        raise DataFileError(f"{run.path / 'summary.json'}: no such file (is {run.path} a sashil run folder?)")
    summary, config = run.summary, run.config
    label = controller_label(summary, config)
    if summary.get("verb") == "compare" and isinstance(summary.get("laws"), list):
        label = f"compare of {len(summary['laws'])} laws"  # the folder's own config runs none of them
    record = RunRecord(run.path, label, summary, config=config)
    entries = summary.get("runs") if isinstance(summary.get("runs"), list) else None
    if summary.get("mode") == "stepped":
        entries = None  # a stepped sweep's sub-runs (one per frequency) are summarised by its table
    for sub in run.runs if entries or run.data_file is not None else ():
        if sub.data_file is None:
            continue
        columns = sub.data
        missing = [name for name in ("time_s", "theta_rad", "current_a") if name not in columns]
        if missing:
            raise DataFileError(f"{sub.data_file}: missing column(s) {', '.join(missing)}")
        entry = sub.metrics if entries else None
        own = sub.config or config
        trace_label = _trace_label(entry, summary, own) if entries else record.label
        params = _model_params(sub.config) or _model_params(config)
        folder = run.path.name if sub is run else f"{run.path.name}/{sub.name}"
        own_summary = sub.summary if sub is not run else summary
        record.traces.append(Trace(trace_label, columns, entry, params, folder, own, own_summary))
    table = run.tables.get("transmissibility")
    if table is not None:
        for name in ("frequency_hz", "transmissibility"):
            if name not in table:
                raise DataFileError(f"{run.path / 'transmissibility.csv'}: missing column {name}")
        record.sweep = table
    record.timing = run.timing
    compared = summary.get("verb") == "compare" and isinstance(summary.get("laws"), list)
    if not record.traces and record.sweep is None and not compared:  # an older compare folder: its table
        raise DataFileError(f"{run.path}: no data.csv or transmissibility.csv in this run folder")
    return record


def name_uniquely(runs: Sequence[RunRecord]) -> None:
    """Add the folder to the labels of runs and traces that would otherwise read the same (a run's
    label and its only trace's label are one name)."""
    named: list[Any] = []
    for run in runs:
        named += [run] if len(run.traces) != 1 else []
        named += run.traces
    folders = [item.path.name if isinstance(item, RunRecord) else item.folder for item in named]
    for item, label in zip(named, unique_labels([item.label for item in named], folders), strict=True):
        item.label = label
    for run in runs:
        if len(run.traces) == 1:
            run.label = run.traces[0].label


def lowpass(time_s: np.ndarray, values: np.ndarray, cutoff_hz: float, padtype: str = "odd") -> np.ndarray:
    """``values`` low-passed at ``cutoff_hz`` with a zero-phase Butterworth filter (forward and
    backward), flat in its pass band so a slow oscillation keeps its amplitude. ``padtype``: how the
    record is extended past its ends (scipy's ``sosfiltfilt``), over two periods of the cut-off."""
    from scipy.signal import butter, sosfiltfilt

    dt = float(np.median(np.diff(time_s)))
    cutoff = min(cutoff_hz, 0.4 / dt)
    sos = butter(LOWPASS_ORDER, cutoff, fs=1.0 / dt, output="sos")
    padlen = min(int(round(2.0 / cutoff / dt)), values.size - 1)
    return np.asarray(sosfiltfilt(sos, values, padtype=padtype, padlen=padlen))


def drop_torque(
    time_s: np.ndarray, theta: np.ndarray, k: float, J: float, until_s: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(θ, θ̇, T_d, cut-off [Hz]) of a drop test from the rig equation (seed 001 eq. 13 with θ1 = 0,
    T_in = 0): ``J θ̈ = −k θ − T_d`` so ``T_d = −k θ − J θ̈``.

    T_d is the difference of two large terms, so the encoder's steps would swamp θ̈: θ is low-passed
    first (zero phase) at DROP_CUTOFF_RATIO times the natural frequency, then differentiated. The arm
    is at rest at the release and at the end, so the record is mirrored (even) past both ends, which
    keeps θ̈ continuous there. The first quarter period of the cut-off after the release and
    everything after ``until_s`` (the settling time, when only the encoder's steps
    move) are NaN in θ̇ and T_d."""
    time_s, theta = np.asarray(time_s, dtype=float), np.asarray(theta, dtype=float)
    cutoff = DROP_CUTOFF_RATIO * math.sqrt(k / J) / (2.0 * math.pi)
    if theta.size < 16 or float(time_s[-1] - time_s[0]) < 2.0 / cutoff:
        raise DataFileError(f"drop test record of {theta.size} samples is too short for the torque estimate")
    smooth = lowpass(time_s, theta, cutoff, padtype="even")
    velocity = np.gradient(smooth, time_s)
    torque = -k * smooth - J * np.gradient(velocity, time_s)
    hidden = time_s < time_s[0] + 0.25 / cutoff  # the release itself: the filter cannot follow its step in θ̈
    if until_s is not None:
        hidden |= time_s > until_s
    velocity[hidden] = np.nan
    torque[hidden] = np.nan
    return smooth, velocity, torque, cutoff


def hysteresis_of(trace: Trace) -> tuple[np.ndarray, np.ndarray, np.ndarray, str] | None:
    """(θ, θ̇, torque, what the torque is) of a trace, or None when neither source exists: the
    observer's T̂ when recorded, else for a drop test the low-passed T_d up to the settling time."""
    cols = trace.columns
    if "torque_hat_nm" in cols and np.isfinite(cols["torque_hat_nm"]).any():
        velocity = cols.get("theta_dot_rad_s")
        if velocity is None:
            velocity = np.gradient(cols["theta_rad"], cols["time_s"])
        return cols["theta_rad"], velocity, cols["torque_hat_nm"], "observer T̂, recorded"
    road = cols.get("theta_road_rad")
    if trace.params is not None and (road is None or not np.any(road)) and "torque_in_nm" not in cols:
        settled = (trace.metrics or {}).get("settling_time_s")
        theta, velocity, torque, cutoff = drop_torque(
            cols["time_s"], cols["theta_rad"], trace.params["k"], trace.params["J"], settled
        )
        return theta, velocity, torque, f"T_d = −kθ − Jθ̈, θ low-passed at {cutoff:.1f} Hz"
    return None


# plots ---------------------------------------------------------------------------------------


def _axes(ax: Any, xlabel: str, ylabel: str, title: str | None = None) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)


def plot_theta(path: Path, traces: Sequence[Trace]) -> Path:
    """θ(t) of every trace overlaid, named by law and current."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10.5, 4.5), dpi=110)
    for trace in traces:
        ax.plot(trace.columns["time_s"], np.degrees(trace.columns["theta_rad"]), linewidth=1.0, label=trace.label)
    ax.axhline(0.0, color="0.4", linewidth=0.6)
    _axes(ax, "time [s]", "arm angle θ [deg]", "relative angle θ(t)")
    ax.legend(**BESIDE)
    return save_figure(fig, path)


def plot_hysteresis(path: Path, loops: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray, str]]) -> Path:
    """Damper torque against θ̇ and against θ; each legend entry says where its torque comes from
    (the observer's T̂, or T_d from the rig equation)."""
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8), dpi=110)
    for label, theta, velocity, torque, source in loops:
        (line,) = left.plot(velocity, torque, linewidth=0.7, label=f"{label}: {source}")
        right.plot(np.degrees(theta), torque, linewidth=0.7, color=line.get_color())
    _axes(left, "θ̇ [rad/s]", "damper torque [N·m]", "torque against velocity")
    _axes(right, "θ [deg]", "damper torque [N·m]", "torque against angle")
    fig.legend(*left.get_legend_handles_labels(), loc="lower center", ncol=min(len(loops), 2), fontsize=8)
    fig.tight_layout(rect=(0.0, 0.06 + 0.035 * ((len(loops) + 1) // 2), 1.0, 1.0))
    return save_figure(fig, path, layout=False)


def plot_transmissibility(path: Path, runs: Sequence[RunRecord]) -> Path:
    """Transmissibility of every stepped sweep among ``runs``, log-log."""
    curves = [
        (run.label, run.sweep["frequency_hz"], run.sweep["transmissibility"]) for run in runs if run.sweep is not None
    ]
    return plots.plot_transmissibility(path, curves)


def plot_timing(path: Path, runs: Sequence[RunRecord]) -> Path:
    """Loop timing of every run with ``timing.npz`` as percentile curves (p50 ... max)."""
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


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """A Markdown table."""
    out = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    return out + ["| " + " | ".join(row) + " |" for row in rows]


@dataclass
class Column:
    """One column of the comparison: a trace (a run, or one current of a drop test), or a stepped
    sweep summarised by its table."""

    label: str
    run: RunRecord
    trace: Trace | None


def comparison_columns(runs: Sequence[RunRecord]) -> list[Column]:
    """Every trace of every run, and each run without a trace (a stepped sweep; not a compare folder
    whose laws' runs it does not hold)."""
    out = []
    for run in runs:
        if not run.traces and run.summary.get("verb") == "compare":
            continue  # a compare folder without its laws' runs (an older one): its own table says it all
        out += [Column(trace.label, run, trace) for trace in run.traces] or [Column(run.label, run, None)]
    return out


def body_motion(trace: Trace) -> tuple[float, float]:
    """RMS of the body (arm) angle θ2 = θ + θ1 about its mean [rad], and of its acceleration θ̈2
    [rad/s²] from θ2 low-passed at BODY_ACCEL_CUTOFF_HZ (the encoder's steps would swamp it)."""
    cols = trace.columns
    road = cols.get("theta_road_rad")
    body = cols["theta_rad"] + (np.nan_to_num(road) if road is not None else 0.0)
    angle = float(np.sqrt(np.mean((body - body.mean()) ** 2)))
    if body.size < 64:
        return angle, math.nan
    smooth = lowpass(cols["time_s"], body, BODY_ACCEL_CUTOFF_HZ)
    accel = np.gradient(np.gradient(smooth, cols["time_s"]), cols["time_s"])
    return angle, float(np.sqrt(np.mean(accel**2)))


def _data_rows(csv: Path) -> int:
    """Rows of a data.csv (lines after the header; 0 when absent)."""
    try:
        with csv.open("rb") as handle:
            return max(sum(1 for _ in handle) - 1, 0)
    except OSError:
        return 0


def clipped_share(column: Column) -> tuple[int, int] | None:
    """(clipped cycles, cycles) of a column's controller: ``controller_stats.clipped_cycles`` over the
    loop's cycles (``timing.cycles``, else the recorded rows); a stepped sweep's over all frequencies."""
    run, trace = column.run, column.trace
    metrics = (trace.metrics if trace else None) or {}
    own = (trace.summary if trace else None) or run.summary
    stats = metrics.get("controller_stats") or own.get("controller_stats")
    if isinstance(stats, dict) and isinstance(stats.get("clipped_cycles"), int):
        timing = metrics.get("timing") or own.get("timing") or {}
        cycles = timing.get("cycles") if isinstance(timing, dict) else None
        if not isinstance(cycles, int) or cycles <= 0:
            cycles = int(trace.columns["time_s"].size) if trace is not None else 0
        return (stats["clipped_cycles"], cycles) if cycles else None
    points = run.summary.get("points")
    if trace is None and isinstance(points, list) and points:
        clipped = sum(int(p.get("clipped_cycles") or 0) for p in points)
        folders = [entry.get("folder") for entry in run.summary.get("runs") or [] if entry.get("folder")]
        cycles = sum(_data_rows(run.path / folder / "data.csv") for folder in folders)
        return (clipped, cycles) if cycles else None
    return None


def road_of(column: Column) -> str:
    """The road input: as the summary says it; a drop test's release angle; else none."""
    summary, metrics = column.run.summary, (column.trace.metrics if column.trace else None) or {}
    if isinstance(summary.get("road"), str):
        return summary["road"]
    if isinstance(metrics.get("theta0_deg"), (int, float)):
        return f"none (drop from {metrics['theta0_deg']:g}°)"
    if summary.get("verb") == "drop-test":
        return "none (drop test)"
    if column.trace is not None and not np.any(column.trace.columns.get("theta_road_rad", 0.0)):
        return "none"
    return "–"


def _share_text(share: tuple[int, int] | None) -> str:
    if share is None:
        return "–"
    clipped, cycles = share
    return f"{100.0 * clipped / cycles:.1f} % ({clipped} of {cycles})"


def compare_section(columns: Sequence[Column]) -> list[str]:
    """What ran and how the body moved, one column per trace: the comparison of controllers."""
    rows: list[tuple[str, Callable[[Column], str]]] = [
        ("folder", lambda c: f"`{c.trace.folder if c.trace and c.trace.folder else c.run.path.name}`"),
        ("controller", lambda c: law_name((c.trace.metrics if c.trace else None) or c.run.summary, _config_of(c))),
        (
            "parameters (set away from the defaults)",
            lambda c: format_parameters(changed_parameters(_config_of(c))) or "–",
        ),
        ("road", road_of),
        ("RMS body angle θ2 [deg]", lambda c: _body_text(c, 0)),
        ("RMS body acceleration θ̈2 [rad/s²]", lambda c: _body_text(c, 1)),
        ("clipped share (cycles the inverse clipped T*)", lambda c: _share_text(clipped_share(c))),
    ]
    lines = ["", "## Controllers compared", ""]
    lines += _table(["", *(c.label for c in columns)], [[title, *(get(c) for c in columns)] for title, get in rows])
    lines += [
        "",
        f"RMS body angle about its mean; acceleration from θ2 low-passed at {BODY_ACCEL_CUTOFF_HZ:g} Hz (zero "
        "phase). A stepped sweep gives its body RMS integrated over the frequencies.",
    ]
    return lines


def _config_of(column: Column) -> dict[str, Any]:
    """The config a column ran with: its trace's own run's, else its folder's."""
    return column.trace.config if column.trace is not None and column.trace.config else column.run.config


def compared_laws_section(runs: Sequence[RunRecord]) -> list[str]:
    """Each compare folder's own table (its ``summary.json`` ``laws``): comfort as compare measured
    it (θ̈2 of the plant on a simulated rig, else of the encoders, low-passed at
    ``compare.accel_bandwidth_hz``), after ``compare.settle_s``."""
    lines: list[str] = []
    for run in runs:
        laws = run.summary.get("laws")
        if run.summary.get("verb") != "compare" or not isinstance(laws, list):
            continue
        lines += ["", f"## Compare `{run.path.name}` (its metrics.csv)", ""]
        rows = [
            [
                str(law.get("law")),
                _fmt(law.get("rms_accel_rad_s2")),
                _fmt(law.get("rms_theta_deg")),
                _fmt(law.get("peak_current_a")),
                _fmt(law.get("coil_energy_j")),
                str(law.get("status")),
            ]
            for law in laws
            if isinstance(law, dict)
        ]
        header = ["law", "RMS θ̈2 [rad/s²]", "RMS θ [deg]", "peak i [A]", "coil energy [J]", "status"]
        lines += _table(header, rows)
        lines += ["", f"Road: {run.summary.get('road', '–')}; see `{run.path.name}/compare.md` for the notes."]
    return lines


def _body_text(column: Column, which: int) -> str:
    if column.trace is not None:
        value = body_motion(column.trace)[which]
        return _fmt(math.degrees(value) if which == 0 else value)
    integrated = column.run.summary.get("integrated_body_rms_rad")
    if which == 0 and isinstance(integrated, (int, float)):
        return _fmt(math.degrees(integrated))
    return "–"


def settings_section(runs: Sequence[RunRecord]) -> list[str]:
    """The controller keys each run's config.yaml set (not null) side by side (each law of a compare
    folder: its own run's): with several the keys whose values differ, and one line for those every
    run shares."""
    pairs: list[tuple[str, dict[str, Any]]] = []
    for run in runs:  # a compare folder's laws each ran with a config of their own
        if run.summary.get("verb") == "compare" and run.traces:
            pairs += [(trace.label, trace.config) for trace in run.traces]
        else:
            pairs.append((run.label, run.config))
    if not any(controller_section(config) for _, config in pairs):
        return []
    params = [{"law": controller_section(config).get("law"), **law_parameters(config)} for _, config in pairs]
    keys = list(dict.fromkeys(key for p in params for key in p))
    cells = {key: [format_value(p[key]) if p.get(key) is not None else "–" for p in params] for key in keys}
    same = [key for key in keys if len(pairs) > 1 and len(set(cells[key])) == 1]
    rows = [[f"`{key}`", *cells[key]] for key in keys if key not in same]
    lines = ["", "## Controller settings (config.yaml `controller:`)", ""]
    if rows:
        lines += _table(["key", *(label for label, _ in pairs)], rows)
    if same:
        lines += ["", "The same in every run: " + ", ".join(f"`{key}` = {cells[key][0]}" for key in same) + "."]
    return lines


def transmissibility_section(runs: Sequence[RunRecord]) -> list[str]:
    """The stepped sweeps' transmissibility side by side (one table per set of frequencies)."""
    swept = [run for run in runs if run.sweep is not None]
    groups: dict[tuple[float, ...], list[RunRecord]] = {}
    for run in swept:
        key = tuple(round(float(f), 3) for f in run.sweep["frequency_hz"])  # type: ignore[index]
        groups.setdefault(key, []).append(run)
    lines: list[str] = []
    for freqs, group in groups.items():
        lines += ["", "## Transmissibility RMS(θ2) / RMS(θ1)", ""]
        rows = [
            [f"{f:g}", *(_fmt(float(run.sweep["transmissibility"][i])) for run in group)]  # type: ignore[index]
            for i, f in enumerate(freqs)
        ]
        lines += _table(["frequency [Hz]", *(run.label for run in group)], rows)
    return lines


def markdown_summary(runs: Sequence[RunRecord], plots: Sequence[Path]) -> str:
    """``report.md``: the runs, the controllers compared, their settings, transmissibility, drop
    tests and loop timing side by side, and the plots."""
    lines = ["# sashil report", "", "Runs: " + ", ".join(f"`{run.path}`" for run in runs), ""]
    lines += ["| run | folder | verb | exit status | started (UTC) | sashil | git |", "|---" * 7 + "|"]
    for run in runs:
        s, prov = run.summary, run.summary.get("provenance") or {}
        lines.append(
            f"| {run.label} | `{Path(run.path).name}` | {_fmt(s.get('verb'))} | {_fmt(s.get('exit_status'))} "
            f"| {_fmt(s.get('started_utc'))} | {_fmt(prov.get('sashil_version'))} | {_fmt(prov.get('git_revision'))} |"
        )
    columns = comparison_columns(runs)
    if columns:
        lines += compare_section(columns)
    lines += compared_laws_section(runs)
    lines += settings_section(runs)
    lines += transmissibility_section(runs)
    drops = [trace for run in runs for trace in run.traces if trace.metrics and "period_s" in trace.metrics]
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
        runs.append(read_record(run_dir))
    name_uniquely(runs)
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

"""What a calibration hands back: ``params.yaml``, ``report.md`` and its PNG plots.

The parameter file is the one ``sashil identify`` writes (:func:`sashil.identify.report.param_document`,
docs/architecture.md shape) with a ``calibration`` block and ``intervals_95`` (``[low, high]`` of k, c_0a,
c_max, yield_0a, yield_max and every free raw parameter) beside it. The intervals are the block
jackknife's (:mod:`sashil.identify.intervals`); the Jacobian's white-residual 1-sigma stays in
``uncertainty_1sigma`` for comparison.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sashil.identify.data import Record
from sashil.identify.fit import FitResult, simulate_fitted
from sashil.identify.intervals import LAB, Intervals
from sashil.identify.report import param_document
from sashil.lab.calibration.analysis import PROFILE_NFEV, Calibration
from sashil.lab.calibration.rig import StepResult
from sashil.recording.plots import BESIDE, pyplot, save_figure

#: a parameter whose 95 % interval is wider than +- this fraction of its value is "not pinned down"
LOOSE = 0.25
#: a held-out NRMSE above this says the fit went wrong: no interval around it holds (typical: 2-8 %)
SUSPECT_NRMSE = 0.10


def quantisation_floor(theta: np.ndarray, counts_per_rev: int) -> float:
    """NRMSE a perfect model would show against an encoder-quantised record: (q/sqrt 12)/std."""
    q = 2.0 * math.pi / counts_per_rev
    return float(q / math.sqrt(12.0) / max(float(np.std(theta)), 1e-15))


def physical(result: FitResult, current_max_a: float) -> list[tuple[str, float, str]]:
    """The torques a Bouc-Wen/Dahl fit pins down, at 0 A and at the largest current."""
    p = result.params
    out: list[tuple[str, float, str]] = [("k", p["k"], "N m/rad")]
    if "c1" in p:
        for i in (0.0, current_max_a):
            out.append((f"c({i:g} A)", p["c1"] + p["c2"] * i, "N m s/rad"))
    if result.model == "bouc-wen":
        bound = (p["delta"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"])
        for i in (0.0, current_max_a):
            out.append((f"yield torque alpha({i:g} A)*z_u", (p["alpha1"] + p["alpha2"] * i) * bound, "N m"))
    out.append(("natural frequency sqrt(k/J)/2pi", math.sqrt(p["k"] / p["J"]) / (2 * math.pi), "Hz"))
    return out


def params_document(cal: Calibration, inertia_given: bool, rig_s: float, plan_rows: list[dict]) -> dict[str, Any]:
    doc = param_document(cal.best)
    doc["calibration"] = {
        "inertia": "given (--inertia)" if inertia_given else "not given: every torque is relative to J = 1",
        "held_out_nrmse": {v.name: round(v.nrmse, 6) for v in cal.validations},
        "held_out_nrmse_mean": None if math.isnan(cal.validation_nrmse) else round(cal.validation_nrmse, 6),
        "uncertainty_inflation": round(cal.inflation, 3),
        "n_profile": [
            {
                "n": p.n,
                "rms_rad": p.rms_rad,
                "held_out_nrmse": None if math.isnan(p.validation_nrmse) else p.validation_nrmse,
            }
            for p in cal.profile
        ],
        "rig_time_s": round(rig_s, 2),
        "fit_s": round(cal.fit_s, 2),
        "intervals_s": round(cal.intervals_s, 2),
        "runs": plan_rows,
    }
    if cal.intervals is not None:
        doc["calibration"]["intervals"] = {
            "level": 0.95,
            "method": cal.intervals.method,
            "blocks": cal.intervals.blocks,
            "block_s": cal.intervals.block_s,
            "fit_suspect": bool(cal.validation_nrmse > SUSPECT_NRMSE),
        }
        doc["intervals_95"] = interval_document(cal.intervals)
    if cal.suggestions:
        first = cal.suggestions[0]
        doc["calibration"]["widest_interval"] = {
            "quantity": first.quantity,
            "relative_half_width": _sig(first.now, 4),
            "extra_steps": [
                {"step": s.step.describe(), "predicted_relative_half_width": _sig(s.predicted, 4)}
                for s in cal.suggestions[:3]
            ],
        }
        if cal.extra_note:
            doc["calibration"]["widest_interval"]["extra_steps_not_kept"] = cal.extra_note
    return doc


def interval_document(intervals: Intervals) -> dict[str, list[float]]:
    """``intervals_95``: ``name: [low, high]`` for the lab's quantities, then the raw parameters."""
    return {name: [_sig(intervals.low[name]), _sig(intervals.high[name])] for name in intervals.value}


def _sig(value: float, digits: int = 6) -> float:
    """``value`` to ``digits`` significant digits (a readable YAML number)."""
    return float(f"{value:.{digits}g}")


#: one run's road angle for the fit plot: (time [s], θ1 [rad])
Road = tuple[np.ndarray, np.ndarray]


def road_angles(results: Sequence[StepResult]) -> dict[str, Road]:
    """The road angle θ1 of every step that moved the road, by step name."""
    out = {}
    for res in results:
        cols = res.columns
        road = cols.get("theta_road_rad")
        if res.step.road is not None and road is not None and cols.get("time_s") is not None and np.any(road):
            out[res.step.name] = (np.asarray(cols["time_s"], dtype=float), np.asarray(road, dtype=float))
    return out


def _overlay(
    records: Sequence[Record],
    sims: Sequence[np.ndarray],
    path: Path,
    title: str,
    roads: dict[str, Road] | None = None,
) -> Path:
    """Recorded and simulated angle per run (and the road angle θ1 of a road run), with the residual
    below each (PNG)."""
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    rows = len(records)
    height = 2.9 * rows + 0.7
    fig, axes = plt.subplots(
        2 * rows, 1, figsize=(10, height), squeeze=False, gridspec_kw={"height_ratios": [2.4, 1] * rows}
    )
    for k, (record, sim) in enumerate(zip(records, sims, strict=True)):
        top, bottom = axes[2 * k, 0], axes[2 * k + 1, 0]
        bottom.sharex(top)
        top.plot(record.time_s, np.degrees(record.theta), color="k", lw=1.0, label="recorded θ")
        top.plot(record.time_s, np.degrees(sim), color="tab:red", lw=0.9, label="model θ")
        road = (roads or {}).get(record.name)
        if road is not None:
            top.plot(road[0], np.degrees(road[1]), color="tab:green", lw=0.8, label="road θ1 (input)")
            span = float(record.time_s[-1] - record.time_s[0])
            top.set_xlim(record.time_s[0] - 0.03 * span, record.time_s[-1] + 0.03 * span)
        top.set_title(f"{record.name}  (mean current {record.mean_current:.2f} A)", fontsize=9)
        top.set_ylabel("angle [deg]")
        top.grid(alpha=0.3)
        if k == 0 or road is not None:
            top.legend(**BESIDE)
        bottom.plot(record.time_s, np.degrees(sim - record.theta), color="tab:blue", lw=0.7)
        bottom.set_ylabel("model − rec\n[deg]", fontsize=8)
        bottom.yaxis.set_major_locator(MaxNLocator(nbins=2, symmetric=True))
        bottom.tick_params(axis="y", labelsize=8)
        bottom.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time since release [s]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.3 / height))
    return save_figure(fig, path, dpi=90, layout=False)


def _profile_plot(cal: Calibration, path: Path) -> Path:
    """``n_profile.png``: fit RMS above the best and held-out NRMSE with n held at each value."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    ns = [p.n for p in cal.profile]
    ref = next(p.rms_rad for p in cal.profile if p.fitted)
    ax.plot(ns, [100 * p.rms_rad / ref - 100 for p in cal.profile], "o-", label="fit RMS above the best [%]")
    if cal.validations:
        ax.plot(ns, [100 * p.validation_nrmse for p in cal.profile], "s--", label="held-out NRMSE [%]")
    ax.axvline(cal.best.params["n"], color="k", lw=0.8, ls=":", label=f"fitted n = {cal.best.params['n']:.3g}")
    ax.set_xscale("log")
    ax.xaxis.set_major_locator(FixedLocator(sorted(set(ns))))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:.3g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("n (held)")
    ax.set_ylabel("fit RMS / held-out NRMSE [%]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Bouc-Wen exponent n: the rest refitted at each value", fontsize=9)
    return save_figure(fig, path, dpi=90)


#: what each quantity of ``intervals_95`` is, for the report's table
MEANING = {
    "k": "k: stiffness [N m/rad]",
    "c_0a": "c(0 A) = c1 [N m s/rad]",
    "c_max": "c(i_max) = c1 + c2 i_max [N m s/rad]",
    "yield_0a": "yield torque α(0)·z_u [N m]",
    "yield_max": "yield torque α(i_max)·z_u [N m]",
}


def interval_table(lines: list[str], cal: Calibration, best: FitResult) -> list[str]:
    """The intervals' table (lab quantities, then raw parameters) appended to ``lines``; returns the
    raw parameters whose interval is wider than LOOSE of their value."""
    loose: list[str] = []
    iv = cal.intervals
    if iv is None:
        return loose
    lines.append(
        f"95 % intervals from a {iv.method}: the residuals of quantised records are correlated, so each "
        f"block of {iv.block_s:g} s is left out as a whole (the white-residual Jacobian σ, kept in "
        f"params.yaml's uncertainty_1sigma, understates the scatter even ×{cal.inflation:.2f}). "
        "`intervals_95` in params.yaml holds the same numbers."
    )
    if cal.validation_nrmse > SUSPECT_NRMSE:
        lines += [
            "",
            f"**The held-out NRMSE ({100 * cal.validation_nrmse:.1f} %) is above {100 * SUSPECT_NRMSE:.0f} %: the fit "
            "went wrong, and no interval around it holds. Repeat the calibration before using these numbers.**",
        ]
    lines += ["", _row(["quantity", "value", "95 % interval", "± relative"]), _row(["---"] * 4)]
    for name in iv.value:
        rel = iv.half_width(name)
        if name not in LAB and rel > LOOSE:
            loose.append(name)
        label = MEANING.get(name, name)
        lines.append(
            _row([label, f"{iv.value[name]:.5g}", f"[{iv.low[name]:.5g}, {iv.high[name]:.5g}]", f"{100 * rel:.3g} %"])
        )
    for name, value in best.params.items():
        if name in best.fixed:
            lines.append(_row([name, f"{value:.6g}", "fixed", "-"]))
    return loose


def _row(cells: Sequence[Any]) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def write_report(
    folder: Path,
    cal: Calibration,
    results: Sequence[StepResult],
    inertia: float,
    inertia_given: bool,
    counts_per_rev: int,
    current_max_a: float,
    rig_s: float,
    virtual: bool = False,
) -> Path:
    """``report.md`` and its plots in ``folder``; returns the report's path."""
    best = cal.best
    _write_plots(folder, cal, results)
    lines = _heading(cal, inertia, inertia_given, rig_s, virtual)
    lines += _runs_section(cal, results, counts_per_rev)
    loose = _parameters_section(lines, cal, current_max_a)
    lines += _suggestions_section(cal)
    lines += _correlations_section(cal)
    lines += _identifiability_section(cal, loose, inertia_given)
    lines += _comparison_section(cal)
    lines += ["", "## Fit stages", ""] + [f"- {s}" for s in best.stages]
    path = folder / "report.md"
    tmp = path.with_name("report.md.part")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def _write_plots(folder: Path, cal: Calibration, results: Sequence[StepResult]) -> None:
    """The fit's overlay, the held-out runs' overlay and the n profile, as PNG files in ``folder``."""
    best = cal.best
    fit_sims = simulate_fitted(best, cal.fit_records)
    roads = road_angles(results)
    _overlay(cal.fit_records, fit_sims, folder / "fit.png", f"{best.model} fit (the runs the fit saw)", roads)
    if cal.validations:
        _overlay(
            cal.validate_records,
            [v.simulated for v in cal.validations],
            folder / "validation.png",
            "held-out validation (runs the fit never saw)",
            roads,
        )
    if cal.profile:
        _profile_plot(cal, folder / "n_profile.png")


def _heading(cal: Calibration, inertia: float, inertia_given: bool, rig_s: float, virtual: bool) -> list[str]:
    """The title (the inertia the torques are relative to) and the line of headline figures."""
    best = cal.best
    lines: list[str] = []
    if inertia_given:
        lines.append(f"# Calibration: {best.model}, J = {inertia:g} kg m² (given with --inertia)")
    else:
        lines.append(
            "**All torques are relative to J = 1** (no --inertia given): the angles fix the damper torque "
            "only up to the arm's inertia; multiply k, c, alpha and every torque below by the rig's J."
        )
        lines.append("")
        lines.append(f"# Calibration: {best.model}")
    lines.append("")
    held = cal.validation_nrmse
    worst = max((v.nrmse for v in cal.validations), default=math.nan)
    lines.append(
        f"Held-out NRMSE (runs the fit never saw): mean {100 * held:.2f} %, worst {100 * worst:.2f} %. "
        f"Rig time {rig_s:.0f} s{' (simulated rig on the virtual clock: wall time)' if virtual else ''}, "
        f"fit {cal.fit_s:.1f} s (+{cal.analysis_s:.1f} s identifiability). "
        f"Convergence: {best.convergence.get('message', '?')} ({best.convergence.get('refinements_within_0_5pct', '?')} "
        f"of {best.convergence.get('refinements', '?')} refinements reached the best cost within 0.5 %)."
    )
    return lines


def _runs_section(cal: Calibration, results: Sequence[StepResult], counts_per_rev: int) -> list[str]:
    """The table of the runs, what its columns mean, and the fit's plots."""
    best = cal.best
    lines: list[str] = []
    lines += [
        "",
        "## Runs",
        "",
        _row(
            [
                "run",
                "role",
                "held at [deg]",
                "current [A]",
                "record [s]",
                "road",
                "fit/held-out NRMSE",
                "quantisation floor",
                "start searched [counts]",
            ]
        ),
    ]
    lines.append(_row(["---"] * 9))
    q = 2.0 * math.pi / counts_per_rev
    start = dict(zip(best.record_names, best.initial_offsets_rad, strict=False))
    nr = dict(zip(best.record_names, best.nrmse, strict=True))
    nr.update({v.name: v.nrmse for v in cal.validations})
    records = {r.name: r for r in [*cal.fit_records, *cal.validate_records]}
    for res in results:
        s = res.step
        rec = records.get(s.name)
        floor = quantisation_floor(rec.theta, counts_per_rev) if rec is not None else math.nan
        road = (
            f"chirp {s.road.f_start_hz:g}-{s.road.f_stop_hz:g} Hz, {math.degrees(s.road.amplitude_rad):g} deg"
            if s.road
            else "-"
        )
        lines.append(
            _row(
                [
                    s.name,
                    s.role,
                    f"{res.hold_angle_deg:.2f}",
                    f"{s.current_a:g}",
                    f"{rec.time_s[-1]:.2f}" if rec is not None else "-",
                    road,
                    f"{100 * nr[s.name]:.2f} %" if s.name in nr else "-",
                    f"{100 * floor:.2f} %",
                    f"{start[s.name] / q:+.2f}" if s.name in start else "-",
                ]
            )
        )
    lines += [
        "",
        "The quantisation floor is the NRMSE a perfect model would show against the record: the encoder's "
        f"{counts_per_rev} counts per revolution alone (q/√12 over the record's standard deviation). Drop records "
        "are cut 0.5 s after the arm came to rest. The fit searched each run's initial angle within two counts of "
        "its first sample (the encoder gives the held arm's angle only to within its count and noise); "
        "'start searched' is where it put it, in counts from that sample.",
        "",
        "![fit](fit.png)",
        "",
    ]
    if cal.validations:
        lines += ["## Held-out validation", "", "![validation](validation.png)", ""]

    return lines


def _parameters_section(lines: list[str], cal: Calibration, current_max_a: float) -> list[str]:
    """The parameters with their intervals and the derived quantities, appended to ``lines``; the
    parameters whose intervals are loose."""
    best = cal.best
    lines += ["## Parameters and 95 % intervals", ""]
    loose = interval_table(lines, cal, best)
    lines += ["", _row(["derived", "value", "unit"]), _row(["---"] * 3)]
    for name, value, unit in physical(best, current_max_a):
        lines.append(_row([name, f"{value:.5g}", unit]))
    lines += ["", f"Normalisation: {best.normalisation}.", ""]
    return loose


def _suggestions_section(cal: Calibration) -> list[str]:
    """The extra steps that would shrink the widest interval most, when the analysis ranked some."""
    lines: list[str] = []
    if cal.suggestions:
        first = cal.suggestions[0]
        lines += [
            "## A plan that shrinks the widest interval",
            "",
            f"The widest interval is {MEANING.get(first.quantity, first.quantity)}: ±{100 * first.now:.3g} %. "
            f"The extra step that would shrink it most is a {first.step.describe().replace(' (fit)', '')}; "
            "`sashil calibrate --extra-steps N` runs the first N below after the plan and refits. Predicted from "
            "the fitted model's sensitivity to each candidate (linearised, assuming its residuals scatter like "
            "these runs'): a ranking, not a measurement.",
            "",
            _row(["extra step", f"predicted ± of {first.quantity}"]),
            _row(["---"] * 2),
        ]
        for s in cal.suggestions:
            lines.append(_row([s.step.describe().replace(" (fit)", ""), f"{100 * s.predicted:.3g} %"]))
        lines.append("")
        if cal.extra_note:
            lines += [f"**--extra-steps: {cal.extra_note}.**", ""]

    return lines


def _correlations_section(cal: Calibration) -> list[str]:
    """The pairs of parameters that correlate above 0.9."""
    best = cal.best
    lines = ["## Correlations", ""]
    names = [n for n in best.params if n in best.correlations]
    pairs = sorted(
        ((a, b, best.correlations[a][b]) for i, a in enumerate(names) for b in names[i + 1 :]),
        key=lambda item: -abs(item[2]),
    )
    strong = [p for p in pairs if abs(p[2]) >= 0.9]
    if strong:
        lines += [_row(["pair", "correlation"]), _row(["---"] * 2)]
        lines += [_row([f"{a}–{b}", f"{c:+.3f}"]) for a, b, c in strong]
    else:
        lines.append("No pair of parameters correlates above 0.9.")
    return lines


def _identifiability_section(cal: Calibration, loose: list[str], inertia_given: bool) -> list[str]:
    """What these runs pin down and what they do not: loose intervals, the z scale, n's profile, J."""
    best = cal.best
    lines = ["", "## Identifiability", ""]
    if loose:
        lines.append(
            f"- Not pinned down by these runs (95 % interval wider than ±{100 * LOOSE:.0f} % of the value): {', '.join(loose)}."
        )
    else:
        lines.append(f"- Every parameter's 95 % interval is within ±{100 * LOOSE:.0f} % of its value.")
    if best.model == "bouc-wen":
        lines.append(
            "- The z scale is not identifiable beside α (fixed by δ = β + γ, |z| ≤ 1); β, γ, δ then describe "
            "only the shape of the hysteresis loop, and n how sharply it bends."
        )
    if cal.profile:
        ref = next(p.rms_rad for p in cal.profile if p.fitted)
        others = [p for p in cal.profile if not p.fitted]
        within = [p.n for p in cal.profile if p.rms_rad <= 1.05 * ref]
        text = (
            f"- n: the fit chose {best.params['n']:.3g}; with n held at {', '.join(f'{p.n:g}' for p in others)} "
            f"and the rest refitted ({PROFILE_NFEV} output-error iterations each, so an upper bound), the fit RMS is "
            f"{', '.join(f'{100 * (p.rms_rad / ref - 1):+.1f} %' for p in others)} from the best"
        )
        if cal.validations:
            text += (
                f" and the held-out NRMSE {', '.join(f'{100 * p.validation_nrmse:.2f} %' for p in others)} "
                f"(fitted n: {100 * cal.validation_nrmse:.2f} %)"
            )
        text += ". "
        if len(within) > 1:
            text += (
                f"**n is not identifiable from this plan: any n in [{min(within):.3g}, {max(within):.3g}] fits within "
                "5 % of the best RMS.** Its jackknife interval is local (one Gauss-Newton step from the fit) and "
                "should not be read as a measurement; the prediction barely depends on n (see the held-out NRMSE "
                "across the profile), and the lab's quantities above carry its trade-off with α, β and δ."
            )
        else:
            text += "n is determined by these runs (only values near the fitted one fit within 5 % of the best RMS)."
        lines += [text, "", "![n profile](n_profile.png)"]
    lines.append(
        "- J is not identifiable from angles (every torque scales with it): "
        + ("given with --inertia." if inertia_given else "assumed 1 (see the first line).")
    )
    return lines


def _comparison_section(cal: Calibration) -> list[str]:
    """The models ranked by their output-error RMS, when more than one was fitted."""
    lines: list[str] = []
    if len(cal.results) > 1:
        lines += [
            "",
            "## Model comparison (output-error RMS over the fit runs)",
            "",
            _row(["rank", "model", "RMS [deg]", "held-out NRMSE"]),
            _row(["---"] * 4),
        ]
        from sashil.lab.calibration.analysis import validate

        for rank, r in enumerate(cal.results, start=1):
            vals = validate(r, cal.validate_records)
            held_r = f"{100 * float(np.mean([v.nrmse for v in vals])):.2f} %" if vals else "-"
            lines.append(_row([rank, r.model, f"{math.degrees(r.rms_total):.4f}", held_r]))
    return lines

#!/usr/bin/env python3
"""Benchmark: each law's share of the optimal bound, laws x dampers x roads, the median beside the
worst; whether the bound bounds; the preview law's compute per cycle.

For each damper of ``tools/bench_drop_damping.py`` (the Bouc-Wen exponent n, the yield torque through
alpha1 and delta, the inertia J, c1 and k, varied around seed 001's set, and combinations: the
team's 18) and each ISO 8608 road (class B and C, each at two speeds), on the simulated rig (virtual
clock, the controller's model exact), each law runs as ``sashil compare`` runs it (the same job,
the same metric: RMS θ̈2 after ``compare.settle_s``), beside compare's passive baseline, the best
constant current on the road (:func:`sashil.lab.passive_baseline.best_constant_current`, a bounded
search over [0, i_max]).

Share of the bound, on the one scale of ``sashil compare``
(:func:`sashil.lab.compare_report.share_of_bound`): 0 % the baseline's RMS θ̈2, 100 %
the bound's. Two bounds:

- ``hysteretic``: compare's own (:mod:`sashil.lab.hysteretic_bound`): the optimiser on the
  plant's Bouc-Wen model and the coil's lag, θ̈2 low-passed as compare measures it, over the
  metric's window, the best of starts independent of every law; the model the preview law plans
  on. A share above 100 % means the law beat it;
- ``envelope``: the plant's viscous envelope (:mod:`sashil.lab.optimal_bound`), for reference:
  it leaves the hysteresis out, so laws beat it where the rig's hard end is harder, and it lies out
  of reach where the hysteresis stiffens the damper.

With ``--mismatch F`` it measures instead the preview law (and ``lqr-clipped``) built on a model
off by F (``mismatch.fraction`` F, signs alternating over J, k, c1, c2, α1, α2, β, γ, δ, n; the
coil's lag F slower) against the true plant, beside the same law built on the true plant, on the
one scale of the true plant's passive runs and bound.

With ``--curve`` it measures instead the share of the receding-horizon preview law
(``controller.plan: receding``) against its preview length (:data:`PREVIEWS`: 0, 50, 100,
250, 500 ms and 1 s of road known ahead; the horizon stays 1 s, the road taken at rest past the
preview), and of the open-loop plan of the whole road beside it, on four plants: the law's model
exact, models 10 % and 20 % off in every parameter (as ``--mismatch``), and a plant whose
hysteresis is Dahl's (:mod:`sashil.models.dahl`, seed 001 eqs. 5-6) with the law still on Bouc-Wen.
The Dahl plant has the damper's yield torque and its stiffness before yield: w' = ρ·(θ̇ − |θ̇|·w),
T = c(i)·θ̇ + (kwa + kwb·i)·w with kwa = α1·z_u, kwb = α2·z_u, ρ = δ/z_u (z_u the Bouc-Wen
bound): seed 001 eq. 17 as :mod:`sashil.models.hysteresis` writes it (γ the coefficient of
|θ̇|·z·|z|^(n−1), β of θ̇·|z|^n) with n = 1, β = 0, γ = δ = ρ, so the simulated rig runs it as it is and
the true plant's bound is computed on it. Each share is of the true plant's bound, over its best
passive run. It writes the cases and the figures as JSON (``--json``, with the commit and the
machine's load) and the curve as a PNG (``--png``).

The preview law's compute per cycle: the controller stage's ``step`` (estimator, observer, law,
inverse) timed with ``perf_counter_ns`` over one run on the seed damper; p50 and p99 [µs]. The
machine's load is printed with it (a shared machine inflates the tail).

    .venv/bin/python tools/bench_preview.py [--quick] [--dampers N|all] [--skip N] [--duration S] [--jobs N] [--json PATH]
        [--mismatch F] [--curve] [--png PATH] [--set controller.KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

# the numeric libraries on one thread: L-BFGS-B's small factorisations on a BLAS thread pool ran ten
# times slower on a busy machine (set before numpy loads them)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_drop_damping import DAMPERS
from bench_record import provenance

from sashil.config.parts import StageParts
from sashil.drivers import rig_parts
from sashil.engine import assemble
from sashil.engine.resolve import apply_overrides, default_config
from sashil.lab._compare import LawJob, run_job
from sashil.lab.compare_report import share_of_bound
from sashil.lab.hysteretic_bound import hysteretic_bound as hysteretic_bound_of
from sashil.lab.optimal_bound import optimal_bound
from sashil.lab.passive_baseline import best_constant_current, passive_label
from sashil.models.hysteresis import BoucWenParams
from sashil.roads.option import RoadParts, parse_road

#: the laws measured (the best causal laws of docs/benchmarks.md and the preview law)
LAWS = ("lqr-clipped", "clipped-optimal", "skyhook-add", "preview-optimal")
#: the roads: ISO 8608 class and speed [m/s]
ROADS = ("iso8608:B:10", "iso8608:B:20", "iso8608:C:10", "iso8608:C:20")
QUICK_ROADS = ("iso8608:C:10",)
#: the order dampers are taken in when fewer than all are asked for: the seed, then one of each kind
ORDER = (
    "seed",
    "n 1",
    "alpha1 2",
    "delta 300",
    "J 2",
    "c1 0.05",
    "k 70",
    "k 160",
    "c1 0.05 alpha1 0.3",
    "n 1 delta 300 alpha1 2",
    "J 0.5",
    "n 0.3",
    "alpha1 0.3",
    "delta 1500",
    "J 1.5",
    "c1 0.3",
    "c1 2",
    "J 2 k 70",
)


@dataclass
class Case:
    """One damper on one road: the RMS θ̈2 of each run and of both bounds, and each law's shares."""

    damper: str
    road: str
    rms: dict[str, float] = field(default_factory=dict)
    best_passive: float = math.nan
    envelope: float = math.nan
    hysteretic: float = math.nan
    share_envelope: dict[str, float] = field(default_factory=dict)
    share_hysteretic: dict[str, float] = field(default_factory=dict)
    status: dict[str, str] = field(default_factory=dict)


def config_of(params: dict[str, float], duration: float) -> dict[str, Any]:
    config: dict[str, Any] = default_config()
    config["model"]["params"].update(params)
    config["road"]["period_s"] = max(10.0, duration)
    return config


def hysteretic_bound(config: dict[str, Any], road: Any, duration: float) -> float:
    """RMS θ̈2 after the settling, low-passed as compare measures it, of the plan on the plant's
    hysteresis and coil lag, the whole road at once (compare's own hysteretic bound)."""
    params = BoucWenParams.from_mapping(config["model"]["params"])
    bandwidth = float(config["compare"]["accel_bandwidth_hz"])
    return hysteretic_bound_of(
        params,
        float(config["rig"]["current_max_a"]),
        float(config["rig"]["coil_tau_s"]),
        road,
        duration,
        float(config["compare"]["settle_s"]),
        bandwidth_hz=bandwidth,
    )


def law_overrides(law: str, preview: list[str]) -> list[str]:
    """The overrides of one law's run: the law, and for the preview law ``preview`` (controller keys)."""
    return [f"controller.law={law}", *(preview if law == "preview-optimal" else [])]


def best_passive(
    config: dict[str, Any], road_text: str, duration: float, known: dict[float, Any] | None = None
) -> float:
    """RMS θ̈2 of the best constant current on the road (:func:`best_constant_current`, compare's own
    baseline: a bounded search over [0, i_max] on this simulated rig); ``known``: runs already made."""

    def run_current(current: float) -> Any:
        overrides = ["controller.law=passive", f"controller.current_a={current}"]
        return run_job(LawJob(passive_label(current), apply_overrides(config, overrides), road_text, duration))

    return best_constant_current(run_current, float(config["rig"]["current_max_a"]), known=known).rms_accel


def run_case(damper: str, road_text: str, duration: float, preview: list[str] | None = None) -> Case:
    params = dict(DAMPERS)[damper]
    config = config_of(params, duration)
    case = Case(damper, road_text)
    jobs = [
        LawJob(law, apply_overrides(config, law_overrides(law, preview or [])), road_text, duration) for law in LAWS
    ]
    for job in jobs:
        result = run_job(job)
        case.status[job.label] = result.status
        case.rms[job.label] = result.metrics["rms_accel_rad_s2"] if result.ok else math.nan
    road, _ = parse_road(road_text, RoadParts.read(config))
    settle = float(config["compare"]["settle_s"])
    case.envelope = optimal_bound(
        BoucWenParams.from_mapping(config["model"]["params"]),
        float(config["rig"]["current_max_a"]),
        road,
        duration,
        settle,
    ).rms_accel_bound
    case.hysteretic = hysteretic_bound(config, road, duration)
    case.best_passive = best_passive(config, road_text, duration)
    for law in LAWS:
        case.share_envelope[law] = share_of_bound(case.rms[law], case.best_passive, case.envelope)
        case.share_hysteretic[law] = share_of_bound(case.rms[law], case.best_passive, case.hysteretic)
    return case


#: the laws measured on a model that is not the plant
MISMATCH_LAWS = ("preview-optimal", "lqr-clipped")


def mismatch_case(
    damper: str, road_text: str, duration: float, fraction: float, preview: list[str]
) -> dict[str, float]:
    """Each of :data:`MISMATCH_LAWS` built on the true plant ("exact") and on a model off by
    ``fraction`` ("off"), run against the true plant: their shares of the true plant's bound."""
    from sashil.drivers.mismatch import plant_sections

    nominal = apply_overrides(
        config_of(dict(DAMPERS)[damper], duration), [f"mismatch.fraction={fraction}", f"mismatch.coil_tau={fraction}"]
    )
    model, rig = plant_sections(nominal["model"], nominal["rig"], nominal["mismatch"])
    exact = config_of(dict(model["params"]), duration)
    exact["rig"]["coil_tau_s"] = float(rig["coil_tau_s"])
    best = best_passive(exact, road_text, duration)
    road, _ = parse_road(road_text, RoadParts.read(exact))
    bound = hysteretic_bound(exact, road, duration)
    shares = {}
    for law in MISMATCH_LAWS:
        for which, config in (("exact", exact), ("off", nominal)):
            result = run_job(LawJob(law, apply_overrides(config, law_overrides(law, preview)), road_text, duration))
            rms = result.metrics["rms_accel_rad_s2"] if result.ok else math.nan
            shares[f"{law} {which}"] = share_of_bound(rms, best, bound)
    return shares


def mismatch_table(rows: list[tuple[str, str, dict[str, float]]], fraction: float) -> None:
    """Per case the shares exact / off; then each law's median and worst of both and of off − exact."""
    print()
    print(f"share of the true plant's bound, the law built on the plant (exact) and on a model off by {fraction:g}")
    for damper, road, shares in rows:
        cells = "  ".join(
            f"{law} {shares[law + ' exact']:6.1f}% / {shares[law + ' off']:6.1f}%" for law in MISMATCH_LAWS
        )
        print(f"  {damper:24s} {road:14s} {cells}")
    for law in MISMATCH_LAWS:
        exact = [shares[f"{law} exact"] for _, _, shares in rows]
        off = [shares[f"{law} off"] for _, _, shares in rows]
        change = [b - a for a, b in zip(exact, off, strict=True)]
        print(f"  {law:16s} median / worst: exact {_fmt(exact)}  off {_fmt(off)}  off − exact {_fmt(change)}")


#: where the curve's figure goes
OUT_PNG = Path(__file__).resolve().parent / "out" / "preview_curve.png"
#: the preview lengths of the curve [s]: up to the law's 1 s, then 2 and 3 s (how much of the gap
#: to the whole road's plan is the road a 1 s preview does not show)
PREVIEWS = (0.0, 0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 3.0)
QUICK_PREVIEWS = (0.0, 0.25)
#: the horizon a re-plan looks past its preview at least [s] (the law's default horizon is 2 s)
HORIZON_PAST_PREVIEW_S = 1.0
#: the cases of the manual's figure (docs/figures/preview_curve.png, ``tools/figures.py``)
FIGURE_DAMPERS = ORDER[:3]
FIGURE_ROADS = ("iso8608:B:20", "iso8608:C:10")
FIGURE_DURATION_S = 6.0
#: the plants of the curve: the law's model exact, 10 % and 20 % off, and Dahl's hysteresis
PLANTS = ("exact", "10 % off", "20 % off", "dahl")
OPEN_LOOP = "open-loop"


def dahl_plant(params: dict[str, float]) -> dict[str, float]:
    """The Bouc-Wen parameters of the Dahl plant of the damper ``params`` (module docstring)."""
    p = BoucWenParams.from_mapping(params)
    z_u = p.z_bound
    rho = p.delta / z_u
    return {
        **{k: float(v) for k, v in asdict(p).items()},
        "alpha1": p.alpha1 * z_u,
        "alpha2": p.alpha2 * z_u,
        "n": 1.0,
        "beta": 0.0,
        "gamma": rho,
        "delta": rho,
    }


@contextmanager
def plant_params(params: dict[str, float] | None) -> Iterator[None]:
    """Runs of :func:`run_job` inside it go on a simulated rig whose plant is ``params`` (Bouc-Wen
    parameters), whatever model the config gives the controller (None: the config's plant)."""
    from sashil.config.parts import RigParts
    from sashil.config.section_parts import ModelPart
    from sashil.lab import _compare

    if params is None:
        yield
        return
    original = _compare.open_rig

    def open_plant(parts: RigParts) -> Any:
        model = ModelPart("bouc-wen", dict(params))
        return original(replace(parts, model=model, mismatch=None))

    _compare.open_rig = open_plant  # type: ignore[assignment]
    try:
        yield
    finally:
        _compare.open_rig = original


def preview_keys(preview_s: float) -> list[str]:
    """The keys of a receding run that sees ``preview_s`` ahead: a preview longer than the law's
    horizon less :data:`HORIZON_PAST_PREVIEW_S` lengthens the horizon to that."""
    keys = [f"controller.preview_s={preview_s:g}"]
    if preview_s + HORIZON_PAST_PREVIEW_S > 2.0:
        keys.append(f"controller.horizon_s={preview_s + HORIZON_PAST_PREVIEW_S:g}")
    return keys


def curve_case(
    damper: str, road_text: str, duration: float, previews: list[float], preview: list[str]
) -> dict[str, Any]:
    """The shares of the receding law at each preview length and of the open-loop plan on each of
    :data:`PLANTS` (module docstring), and each plant's passive and bound RMS θ̈2."""
    from sashil.drivers.mismatch import plant_sections

    law = config_of(dict(DAMPERS)[damper], duration)
    out: dict[str, Any] = {"damper": damper, "road": road_text, "plants": {}}
    for plant in PLANTS:
        if plant == "dahl":
            true = config_of(dahl_plant(law["model"]["params"]), duration)
            model_config, patch = law, dict(true["model"]["params"])
        else:
            fraction = {"exact": 0.0, "10 % off": 0.1, "20 % off": 0.2}[plant]
            model_config = apply_overrides(law, [f"mismatch.fraction={fraction}", f"mismatch.coil_tau={fraction}"])
            model, rig = plant_sections(model_config["model"], model_config["rig"], model_config["mismatch"])
            true = config_of(dict(model["params"]), duration)
            true["rig"]["coil_tau_s"] = float(rig["coil_tau_s"])
            patch = None
        best = best_passive(true, road_text, duration)
        road, _ = parse_road(road_text, RoadParts.read(true))
        bound = hysteretic_bound(true, road, duration)
        shares: dict[str, float] = {}
        runs = [(f"{s:g}", ["controller.plan=receding", *preview_keys(s)]) for s in previews] + [
            (OPEN_LOOP, ["controller.plan=open-loop"])
        ]
        for key, keys in runs:
            config = apply_overrides(model_config, law_overrides("preview-optimal", [*preview, *keys]))
            with plant_params(patch):
                result = run_job(LawJob("preview-optimal", config, road_text, duration))
            rms = result.metrics["rms_accel_rad_s2"] if result.ok else math.nan
            shares[key] = share_of_bound(rms, best, bound)
        out["plants"][plant] = {"best_passive": best, "bound": bound, "share": shares}
    return out


def previews_of(text: str) -> list[float]:
    """The preview lengths of ``--previews`` [s]: numbers >= 0, comma-separated."""
    try:
        previews = [float(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers of seconds, got {text!r}") from None
    if any(not math.isfinite(s) or s < 0.0 for s in previews):
        raise argparse.ArgumentTypeError(f"expected preview lengths >= 0 s, got {text!r}")
    return previews


def curve_figures(cases: list[dict[str, Any]], previews: list[float]) -> dict[str, Any]:
    """Per plant and preview length (and the open-loop plan): the median and worst share."""
    figures: dict[str, Any] = {}
    for plant in PLANTS:
        row = {}
        for key in [*(f"{s:g}" for s in previews), OPEN_LOOP]:
            values = [c["plants"][plant]["share"][key] for c in cases]
            known = [v for v in values if math.isfinite(v)]
            row[key] = {
                "median": statistics.median(known) if known else math.nan,
                "worst": min(known) if known else math.nan,
            }
        figures[plant] = row
    return figures


def kept_gain(cases: list[dict[str, Any]], previews: list[float]) -> dict[str, Any]:
    """Per plant other than ``exact`` and per preview length (and the open-loop plan): the median and
    worst, over the cases, of the share on that plant over the share on the exact model [%] (the
    part of its exact-model gain a law keeps on a rig that is not its model); cases whose exact
    share is not above 0 are left out."""
    kept: dict[str, Any] = {}
    for plant in PLANTS[1:]:
        row = {}
        for key in [*(f"{s:g}" for s in previews), OPEN_LOOP]:
            ratios = [
                100.0 * c["plants"][plant]["share"][key] / c["plants"]["exact"]["share"][key]
                for c in cases
                if c["plants"]["exact"]["share"][key] > 0.0 and math.isfinite(c["plants"][plant]["share"][key])
            ]
            row[key] = {
                "median": statistics.median(ratios) if ratios else math.nan,
                "worst": min(ratios) if ratios else math.nan,
                "cases": len(ratios),
            }
        kept[plant] = row
    return kept


def curve_table(figures: dict[str, Any], previews: list[float], count: int, kept: dict[str, Any]) -> None:
    print()
    print(f"share of the true plant's bound against the preview length, median / worst over {count} cases")
    keys = [*(f"{s:g}" for s in previews), OPEN_LOOP]
    print("  plant       " + "".join(f"{(k + ' s') if k != OPEN_LOOP else k:>17s}" for k in keys))
    for plant, row in figures.items():
        print(f"  {plant:10s}  " + "".join(f"{row[k]['median']:7.1f}% {row[k]['worst']:6.1f}%  " for k in keys))
    print("the share kept of the exact model's (share on the plant / share on the exact model), median / worst")
    for plant, row in kept.items():
        print(f"  {plant:10s}  " + "".join(f"{row[k]['median']:7.1f}% {row[k]['worst']:6.1f}%  " for k in keys))


def curve_png(path: Path, figures: dict[str, Any], previews: list[float], count: int) -> None:
    """The median share (the worst as a thin line) against the preview length, one colour per plant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ms = [1000.0 * s for s in previews]
    for plant, row in figures.items():
        median = [row[f"{s:g}"]["median"] for s in previews]
        worst = [row[f"{s:g}"]["worst"] for s in previews]
        (line,) = ax.plot(ms, median, marker="o", label=f"{plant} (median)")
        ax.plot(ms, worst, linestyle=":", color=line.get_color(), linewidth=1.0)
        ax.axhline(row[OPEN_LOOP]["median"], color=line.get_color(), linewidth=0.6, linestyle="--")
    ax.set_xlabel("road known ahead [ms]")
    ax.set_ylabel("share of the true plant's bound [%]")
    ax.set_title(f"receding-horizon preview law, {count} cases (dotted: worst; dashed: open-loop plan)", fontsize=9)
    ax.grid(True, linewidth=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _rounded(value: Any) -> Any:
    """``value`` with each float to 0.1 (the figure's data: the numbers its caption states)."""
    if isinstance(value, dict):
        return {key: _rounded(item) for key, item in value.items()}
    return round(value, 1) if isinstance(value, float) else value


def figure(out: Path, jobs: int = 2) -> None:
    """The manual's figure ``out``/preview_curve.png and its data ``out``/preview_curve.json: the
    curve on :data:`FIGURE_DAMPERS` x :data:`FIGURE_ROADS`, :data:`FIGURE_DURATION_S` each, every
    length of :data:`PREVIEWS` (``tools/figures.py --figure preview_curve``; minutes)."""
    pairs = [(d, r) for d in FIGURE_DAMPERS for r in FIGURE_ROADS]
    previews = list(PREVIEWS)
    before = provenance()
    curve = each_case(curve_case, pairs, jobs, FIGURE_DURATION_S, previews, [])
    figures = curve_figures(curve, previews)
    kept = kept_gain(curve, previews)
    curve_table(figures, previews, len(curve), kept)
    curve_png(out / "preview_curve.png", figures, previews, len(curve))
    record = {
        "tool": "tools/figures.py --figure preview_curve (tools/bench_preview.py)",
        "started": before,
        "ended": provenance(),
        "dampers": list(FIGURE_DAMPERS),
        "roads": list(FIGURE_ROADS),
        "duration_s": FIGURE_DURATION_S,
        "previews_s": previews,
        "figures": _rounded(figures),
        "kept_of_exact": _rounded(kept),
        "cases": curve,
    }
    write_record(out / "preview_curve.json", record)


def write_record(path: Path, record: Any) -> None:
    """Write one of the benchmark's JSON records to ``path`` (its folder made)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")


def loop_cost(pairs: int, duration: float, preview: list[str], out: Path) -> dict[str, Any]:
    """``pairs`` pairs of ``sashil run`` on the real clock (the loop in its own process, the simulated
    rig, ISO 8608 class C at 10 m/s): ``passive`` at 0.5 A, then ``preview-optimal`` with its planner
    process beside, one after the other so both see the same minute of a shared machine; per run
    the lateness and compute quantiles [µs], missed deadlines and the load; per pair the difference
    of the p99 lateness (preview − passive)."""
    import sashil

    runs: list[dict[str, Any]] = []
    for index in range(pairs):
        pair = {}
        for law in ("passive", "preview-optimal"):
            folder = out / f"loop-{index}-{law}"
            keys = ["controller.current_a=0.5"] if law == "passive" else ["controller.plan=receding", *preview]
            run = sashil.run(law, duration_s=duration, road="iso8608:C:10", set=keys, out=folder)
            timing = run.summary["timing"]
            pair[law] = {
                "exit_status": run.summary["exit_status"],
                "lateness_us": timing["lateness_us"],
                "compute_us": timing["compute_us"],
                "missed_deadlines": timing["missed_deadlines"],
                "load": os.getloadavg()[0],
            }
        p99 = {law: float(pair[law]["lateness_us"]["p99"]) for law in pair}
        pair["p99_lateness_change_us"] = p99["preview-optimal"] - p99["passive"]
        runs.append(pair)
        print(
            f"  pair {index}: p99 lateness passive {p99['passive']:.1f} µs, preview-optimal "
            f"{p99['preview-optimal']:.1f} µs (change {pair['p99_lateness_change_us']:+.1f} µs); compute p99 "
            f"{pair['passive']['compute_us']['p99']:.1f} / {pair['preview-optimal']['compute_us']['p99']:.1f} µs; "
            f"missed {pair['passive']['missed_deadlines']} / {pair['preview-optimal']['missed_deadlines']} "
            f"(load {os.getloadavg()[0]:.2f})",
            flush=True,
        )
    changes = [pair["p99_lateness_change_us"] for pair in runs]
    return {"pairs": runs, "median_p99_change_us": statistics.median(changes), "worst_p99_change_us": max(changes)}


def cycle_us(duration: float, preview: list[str] | None = None) -> tuple[float, float, float]:
    """p50, p99 and max of the preview law's controller step [µs] over one run on the seed damper."""
    from sashil.control.registry import make_controller
    from sashil.drivers import open_rig
    from sashil.roads.option import RoadStage
    from sashil.runtime.clock import default_clock
    from sashil.runtime.runner import run_plan

    config = apply_overrides(config_of({}, duration), law_overrides("preview-optimal", preview or []))
    controller = make_controller(None, StageParts.read(config))
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    times: list[int] = []

    class Timed:
        def __init__(self, stage: Any):
            self.stage = stage
            self.signal_names = stage.signal_names

        def __getattr__(self, name: str) -> Any:
            if name == "stage":
                raise AttributeError(name)
            return getattr(self.stage, name)

        def step(self, sample: Any, t_ns: int, dt_ns: int) -> Any:
            t0 = time.perf_counter_ns()
            cmd = self.stage.step(sample, t_ns, dt_ns)
            times.append(time.perf_counter_ns() - t0)
            return cmd

    stage = RoadStage(controller, road, duration)
    from sashil.runtime.planner import PlannerProcess, plan_beside_loop

    # the loop's own cost: re-plans in the planner process, as on the real clock (run_plan on
    # simulated time leaves a planner already beside the loop in place)
    beside = plan_beside_loop(stage, virtual=False)
    if isinstance(beside, PlannerProcess):
        beside.wait_ready()
    run_plan(
        assemble(config),
        open_rig(rig_parts(config)),
        Timed(stage),
        default_clock(assemble(config)),
        duration,
        realtime=False,
        say=lambda _: None,
    )
    steps = np.asarray(times[10:], dtype=float) / 1e3  # after the first cycles (compile, caches)
    return float(np.percentile(steps, 50)), float(np.percentile(steps, 99)), float(np.max(steps))


def _fmt(values: list[float]) -> str:
    known = [v for v in values if math.isfinite(v)]
    if not known:
        return f"{'–':>7s} {'–':>7s}"
    return f"{statistics.median(known):6.1f}% {min(known):6.1f}%"


def table(cases: list[Case]) -> None:
    """Per law and road: the share's median beside its worst, on both bounds; then per damper."""
    roads = sorted({c.road for c in cases})
    print()
    print(f"share of the bound (0 %: best passive run, 100 %: the bound), {len({c.damper for c in cases})} dampers")
    print("                      " + "".join(f"{road:>17s}" for road in [*roads, "all"]))
    print("  law (bound)         " + "   median   worst" * (len(roads) + 1))
    for which in ("envelope", "hysteretic"):
        for law in LAWS:
            cells = []
            for road in [*roads, None]:
                chosen = [c for c in cases if road is None or c.road == road]
                shares = [(c.share_envelope if which == "envelope" else c.share_hysteretic)[law] for c in chosen]
                cells.append(_fmt(shares))
            print(f"  {law:16s}{which[:4]:>4s}  " + "  ".join(f"{cell:>15s}" for cell in cells))
    print()
    print("per case: RMS θ̈2 [rad/s²] of the best passive run, the bounds, and the preview law; its shares")
    for c in cases:
        print(
            f"  {c.damper:24s} {c.road:14s} passive {c.best_passive:6.3f}  envelope {c.envelope:6.3f}  "
            f"hysteretic {c.hysteretic:6.3f}  preview {c.rms['preview-optimal']:6.3f}  "
            f"share {c.share_envelope['preview-optimal']:6.1f}% / {c.share_hysteretic['preview-optimal']:6.1f}%"
        )
    over = [
        (c, law, c.share_hysteretic[law])
        for c in cases
        for law in LAWS
        if math.isfinite(c.share_hysteretic[law]) and c.share_hysteretic[law] > 100.0
    ]
    over_env = [
        (c, law, c.share_envelope[law])
        for c in cases
        for law in LAWS
        if math.isfinite(c.share_envelope[law]) and c.share_envelope[law] > 100.0
    ]
    print()
    print(f"above 100 % of the envelope bound: {len(over_env)} of {len(cases) * len(LAWS)} runs")
    for c, law, share in over_env:
        print(f"  {law} on {c.damper}, {c.road}: {share:.1f} %")
    print(f"above 100 % of the hysteretic bound: {len(over)} of {len(cases) * len(LAWS)} runs")
    for c, law, share in over:
        print(f"  {law} on {c.damper}, {c.road}: {share:.1f} %")


def each_case(work: Any, pairs: list[tuple[str, str]], jobs: int, *args: Any) -> list[Any]:
    """``work(damper, road, *args)`` for every pair, in ``jobs`` processes, each reported when done."""
    start = time.perf_counter()
    done: list[Any] = []
    if jobs > 1:
        with ProcessPoolExecutor(jobs, mp_context=get_context("spawn")) as pool:
            futures = [pool.submit(work, d, r, *args) for d, r in pairs]
            for (d, r), future in zip(pairs, futures, strict=True):
                done.append(future.result())
                print(f"  {d}, {r}: done ({time.perf_counter() - start:.0f} s)", flush=True)
    else:
        for d, r in pairs:
            done.append(work(d, r, *args))
            print(f"  {d}, {r}: done ({time.perf_counter() - start:.0f} s)", flush=True)
    return done


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the curve on one damper, one road, 4 s, two previews")
    parser.add_argument("--dampers", default="10", help="how many dampers (in ORDER), or all")
    parser.add_argument("--skip", type=int, default=0, help="leave out the first N of those (a run in parts)")
    parser.add_argument("--roads", default=",".join(ROADS), help="comma-separated --road values")
    parser.add_argument("--duration", type=float, default=12.0, help="seconds per run (the first 2 s left out)")
    parser.add_argument("--jobs", type=int, default=1, help="cases in parallel processes")
    parser.add_argument("--json", type=Path, help="write every case here")
    parser.add_argument("--mismatch", type=float, help="measure the laws built on a model off by this fraction")
    parser.add_argument("--curve", action="store_true", help="the share against the preview length on four plants")
    parser.add_argument(
        "--png", type=Path, help="the curve's figure (default tools/out/preview_curve.png; --quick: a temporary file)"
    )
    parser.add_argument(
        "--previews",
        type=previews_of,
        default=",".join(f"{s:g}" for s in PREVIEWS),
        help="with --curve: comma-separated preview lengths [s] (fewer for the whole spread)",
    )
    parser.add_argument("--loop-cost", type=int, metavar="PAIRS", help="PAIRS of real-clock runs, passive and preview")
    parser.add_argument("--set", action="append", default=[], help="controller.KEY=VALUE for the preview law (repeat)")
    args = parser.parse_args()
    if args.quick:  # the curve on one case, a short horizon: the code path in seconds
        dampers, roads, duration = ["seed"], list(QUICK_ROADS), 4.0
        args.set = ["controller.horizon_s=0.25", "controller.replan_iterations=10", *args.set]
    else:
        count = len(ORDER) if args.dampers == "all" else int(args.dampers)
        dampers, roads, duration = list(ORDER[args.skip : count]), args.roads.split(","), args.duration
    print(
        f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; {len(dampers)} dampers x {len(roads)} roads, "
        f"{duration:g} s each; preview-optimal {' '.join(args.set) or 'as it is'}"
    )
    start = time.perf_counter()
    pairs = [(d, r) for d in dampers for r in roads]
    if args.loop_cost:
        before = provenance()
        with tempfile.TemporaryDirectory(prefix="bench-preview-") as scratch:
            cost = loop_cost(args.loop_cost, duration, args.set, Path(scratch))
        print(
            f"p99 lateness, preview-optimal − passive: median {cost['median_p99_change_us']:+.1f} µs, "
            f"worst {cost['worst_p99_change_us']:+.1f} µs over {args.loop_cost} pairs (goal: within 5 µs)"
        )
        if args.json is not None:
            record = {"tool": "tools/bench_preview.py --loop-cost", "started": before, "ended": provenance(), **cost}
            write_record(args.json, record)
        return 0
    if args.curve or args.quick:
        previews = list(QUICK_PREVIEWS) if args.quick else args.previews
        before = provenance()
        curve = each_case(curve_case, pairs, args.jobs, duration, previews, args.set)
        figures = curve_figures(curve, previews)
        kept = kept_gain(curve, previews)
        curve_table(figures, previews, len(curve), kept)
        if args.png is None and args.quick:  # the quick mode draws, and leaves the repository's figure alone
            with tempfile.TemporaryDirectory(prefix="bench-preview-") as scratch:
                curve_png(Path(scratch) / "curve.png", figures, previews, len(curve))
        else:
            args.png = args.png or OUT_PNG
            curve_png(args.png, figures, previews, len(curve))
        print(f"figure: {args.png}; wall {time.perf_counter() - start:.0f} s (load {os.getloadavg()[0]:.2f})")
        if args.json is not None:
            record = {
                "tool": "tools/bench_preview.py --curve",
                "started": before,
                "ended": provenance(),
                "duration_s": duration,
                "previews_s": previews,
                "set": args.set,
                "figures": figures,
                "kept_of_exact": kept,
                "cases": curve,
            }
            write_record(args.json, record)
        return 0
    if args.mismatch is not None:
        before = provenance()
        shares = each_case(mismatch_case, pairs, args.jobs, duration, args.mismatch, args.set)
        mismatch_table([(d, r, s) for (d, r), s in zip(pairs, shares, strict=True)], args.mismatch)
        print(f"wall {time.perf_counter() - start:.0f} s (load {os.getloadavg()[0]:.2f})")
        if args.json is not None:
            record = {
                "tool": "tools/bench_preview.py --mismatch",
                "started": before,
                "ended": provenance(),
                "fraction": args.mismatch,
                "duration_s": duration,
                "set": args.set,
                "cases": [{"damper": d, "road": r, "share": s} for (d, r), s in zip(pairs, shares, strict=True)],
            }
            write_record(args.json, record)
        return 0
    cases = each_case(run_case, pairs, args.jobs, duration, args.set)
    table(cases)
    p50, p99, worst = cycle_us(duration, args.set)
    print()
    print(
        f"preview-optimal controller step (estimator, observer, law, inverse): p50 {p50:.1f} µs, p99 {p99:.1f} µs, "
        f"max {worst:.1f} µs (load {os.getloadavg()[0]:.2f}); goal p99 <= 200 µs"
    )
    print(f"wall {time.perf_counter() - start:.0f} s")
    if args.json is not None:
        write_record(args.json, [asdict(c) for c in cases])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

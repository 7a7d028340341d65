#!/usr/bin/env python3
"""Benchmark: the comparison laws against the best constant current, their cost per cycle, and the
wall time of ``sashil compare``.

For the spread of dampers of ``tools/bench_drop_damping.py`` (the Bouc-Wen exponent n, the yield
torque through alpha1 and delta, the inertia J, c1 and k, varied around seed 001's set, and
combinations), each with the controller's model exact and 10 % off (``mismatch.fraction: 0.1``,
alternating signs, the coil lag 10 % slower), on ISO 8608 class C at the rig's speed (``road.speed_m_s``),
30 s per run on the simulated rig (virtual clock, 4096-count encoders):

- the passive baseline, compare's own (:func:`sashil.lab.passive_baseline.best_constant_current`):
  the best constant current by RMS arm acceleration (the ``sashil compare`` metric), a bounded search
  over [0, i_max], each candidate a run of the same road and seed; beside it the better of 0 A and
  i_max (the two-current rule it replaces);
- each law's RMS arm acceleration as a gain over it (positive: better), worst and median over the
  dampers. Goal (clipped-optimal and skyhook-add): >= 10 % on every damper.
- the optimal bound, compare's own (:func:`sashil.lab._compare.compare_bound`: the controller's
  model, the road known in advance, its starts no law's plan): how far it lies below the baseline,
  its starts' spread, and each law's share of it on compare's scale, flagged above 100 % + the
  tolerance; with the 10 %-off model also the share of the true plant's bound.
- the same figures on the training dampers (every other one of the list, from the first: the set the
  LQR laws' default weights were chosen on) and on the others (unseen by that choice).
- each law's own compute per cycle (its torque/current call on recorded states), median and p99.
  Goal: <= 10 us median.
- ``sashil compare`` with 8 laws x 30 s on the simulated rig, in 1 and 2 processes. Goal: <= 30 s.

    .venv/bin/python tools/bench_compare.py [--quick] [--jobs N] [--dampers all|train|unseen] [--json PATH]

The figures are kept as JSON (``tools/bench_record.py``: the commit, the date, the load):
``tools/out/bench_compare.json``, or ``--json PATH``.

``--quick``: the same tables on a tiny problem: two dampers (one training, one unseen), the exact model,
the best of 0 A and 1 A as the baseline, 2.5 s runs (0.5 s after the settle), 2000 calls per law and
``sashil compare`` of 2.5 s runs; the figures mean little (kept only with ``--json``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_drop_damping import DAMPERS
from bench_record import Recorder, out_path

from sashil.config.frozen import freeze_config
from sashil.config.parts import StageParts
from sashil.control.law_api import LawState
from sashil.control.law_config import build_law
from sashil.control.law_registry import find_law
from sashil.engine import assemble
from sashil.engine.resolve import apply_overrides, default_config
from sashil.lab._compare import READS, LawJob, compare_bound, passive_job, plant_bound, run_job, scale_bound
from sashil.lab.compare_metrics import LawResult
from sashil.lab.compare_report import BOUND_TOLERANCE_PTS, above_bound, share_of_bound
from sashil.lab.passive_baseline import best_constant_current
from sashil.roads.option import RoadParts, parse_road

#: the laws measured, with the --set parameters they need
LAWS: dict[str, list[str]] = {
    "clipped-optimal": [],
    "lqr-clipped": [],
    "skyhook-add": [],
    "pdd": [],
    "groundhook-hybrid": [],
    "skyhook": ["controller.c_sky=2.2"],
}
#: the laws the >= 10 % goal is about
GOAL_LAWS = ("clipped-optimal", "skyhook-add")
GOAL_GAIN_PCT = 10.0
GOAL_CYCLE_US = 10.0
GOAL_COMPARE_S = 30.0
QUICK_DAMPERS = ("seed", "J 2")
#: the dampers the LQR laws' default weights were chosen on: every other one of the list, from the
#: first (each kind of variation lands on both sides); the rest are unseen by that choice
TRAIN_DAMPERS = tuple(name for name, _ in DAMPERS[::2])
ROAD = "iso8608:C"


@dataclass
class Case:
    """One damper and model: the passive baseline (and the two-current rule's), the bound and its
    starts' spread, each law's gain over the baseline and share of the bound [%]."""

    damper: str
    mismatch: float
    best_current_a: float
    rms_accel_best: float
    two_current_a: float
    rms_accel_two_current: float
    baseline_runs: int
    bound_rms_accel: float
    bound_gain_pct: float
    bound_spread_pct: float
    gains_pct: dict[str, float | None]
    shares_pct: dict[str, float | None] = field(default_factory=dict)
    plant_shares_pct: dict[str, float | None] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"{self.damper}, {'exact' if not self.mismatch else '10 % off'}"


def config_of(params: dict[str, float], mismatch: float, duration: float) -> dict[str, Any]:
    config: dict[str, Any] = default_config()
    config["model"]["params"].update(params)
    config["compare"]["road"], config["compare"]["duration_s"] = ROAD, duration
    if mismatch:
        config["mismatch"]["fraction"] = mismatch
        config["mismatch"]["coil_tau"] = mismatch
    return config


def measure(case: tuple[str, dict[str, float], float, float, bool]) -> Case:
    """One damper and model, as ``sashil compare`` measures it: the baseline, the laws, the bound."""
    name, params, mismatch, duration, quick = case
    config = config_of(params, mismatch, duration)
    run = assemble(freeze_config(config), reads=READS)
    i_max = run.stage.current_max_a

    def run_current(current: float) -> LawResult:
        return run_job(passive_job(config, current, ROAD, duration))

    baseline = best_constant_current(run_current, i_max, [0.0, i_max] if quick else None)
    ends = {c: baseline.evaluated[c] for c in (0.0, i_max) if baseline.evaluated[c].ok}
    two = min(ends, key=lambda c: ends[c].metrics["rms_accel_rad_s2"])
    road, _ = parse_road(ROAD, RoadParts.of(run.options))
    bound = compare_bound(run, road, duration)
    plant = plant_bound(config, run, road, duration)
    b = scale_bound(run, road, duration, bound.rms_accel_bound if bound else math.nan, baseline)
    b_plant = scale_bound(run, road, duration, plant.rms_accel_bound if plant else math.nan, baseline)
    p = baseline.rms_accel
    out = Case(
        name,
        mismatch,
        baseline.current_a,
        p,
        two,
        ends[two].metrics["rms_accel_rad_s2"],
        len(baseline.evaluated),
        b,
        100.0 * (1.0 - b / p),
        bound.spread_pct if bound else math.nan,
        {},
    )
    for law, sets in LAWS.items():
        r = run_job(LawJob(law, apply_overrides(config, [f"controller.law={law}", *sets]), ROAD, duration))
        if not r.ok:
            out.gains_pct[law] = out.shares_pct[law] = None
            print(f"  {name} {law}: {r.status}")
            continue
        a = r.metrics["rms_accel_rad_s2"]
        out.gains_pct[law] = 100.0 * (1.0 - a / p)
        out.shares_pct[law] = share_of_bound(a, p, b)
        if plant is not None:
            out.plant_shares_pct[law] = share_of_bound(a, p, b_plant)
    return out


def law_cycle_us(law_name: str, sets: list[str], samples: int) -> tuple[float, float]:
    """Median and p99 of one call of the law's output on varied states [us]."""
    config = apply_overrides(default_config(), [f"controller.law={law_name}", *sets])
    entry = find_law(law_name)
    law = build_law(entry, StageParts.read(config), config["controller"])
    output = law.current if entry.cls.output_kind() == "current" else law.torque
    rng = np.random.default_rng(0)
    states = []
    for values in rng.normal(0.0, 1.0, size=(256, 6)):
        s = LawState()
        s.theta_rad, s.theta_dot_rad_s, s.body_dot_rad_s = 0.02 * values[0], values[1], values[2]
        s.road_dot_rad_s, s.body_ddot_rad_s2, s.torque_hat_nm = values[3], 10.0 * values[4], 0.5 * values[5]
        s.band_lo_nm, s.band_hi_nm = -1.0, 1.0
        states.append(s)
    times = []
    clock = time.perf_counter_ns
    for i in range(samples):
        s = states[i & 255]
        s.time_s = i * 1e-3
        t0 = clock()
        output(s)
        times.append(clock() - t0)
    times.sort()
    return times[len(times) // 2] / 1e3, times[int(0.99 * len(times))] / 1e3


def compare_wall_s(duration: float, jobs: int) -> float:
    """Wall time of ``sashil compare`` with 6 laws + the 2 references."""
    from sashil.cli import main

    laws = [arg for law in LAWS for arg in ("--controller", law)]
    with TemporaryDirectory() as tmp, contextlib.redirect_stderr(io.StringIO()):
        args = ["compare", "--duration", f"{duration:g}", *laws, "--set", "controller.c_sky=2.2"]
        start = time.perf_counter()
        code = main([*args, "--jobs", str(jobs), "--out", str(Path(tmp) / "cmp"), "-q"])
        wall = time.perf_counter() - start
    if code != 0:
        raise SystemExit(f"sashil compare exited {code}")
    return wall


def _spread(values: list[float]) -> str:
    return f"worst {min(values):+6.1f} %, median {statistics.median(values):+6.1f} %" if values else "none"


def summarise(title: str, rows: list[Case]) -> None:
    """Per law: the worst and median gain over the passive baseline, and its share of the bound."""
    print()
    print(f"{title}: {len(rows)} runs per law")
    bounds = [r.bound_gain_pct for r in rows]
    better = [100.0 * (1.0 - r.rms_accel_best / r.rms_accel_two_current) for r in rows]
    print(
        f"  passive baseline below the two-current rule's (the better of 0 A and i_max): median "
        f"{statistics.median(better):.2f} %, most {max(better):.2f} %; inner current on {sum(b > 0 for b in better)} "
        f"of {len(rows)}"
    )
    print(
        f"  optimal bound below the baseline (compare's bound, the controller's model): worst {min(bounds):.1f} %, "
        f"median {statistics.median(bounds):.1f} %, best {max(bounds):.1f} %; its starts' spread at most "
        f"{max(r.bound_spread_pct for r in rows):.2g} % of the gap"
    )
    print("  gain in RMS arm acceleration over the baseline (positive: better); share of the bound on compare's scale")
    for law in LAWS:
        gains = [g for r in rows if (g := r.gains_pct.get(law)) is not None]
        failed = len(rows) - len(gains)
        if not gains:
            print(f"    {law:18s} no finished run")
            continue
        shares = [v for r in rows if (v := r.shares_pct.get(law)) is not None and math.isfinite(v)]
        flagged = sum(above_bound(v) for v in shares)
        plant = [v for r in rows if (v := r.plant_shares_pct.get(law)) is not None and math.isfinite(v)]
        goal = ""
        if law in GOAL_LAWS:
            met = not failed and min(gains) >= GOAL_GAIN_PCT
            goal = f"   [goal >= {GOAL_GAIN_PCT:g} % on every damper: {'met' if met else 'NOT met'}]"
        print(
            f"    {law:18s} gain {_spread(gains)}; share {_spread(shares)}"
            + (f" ({flagged} above 100 % + {BOUND_TOLERANCE_PTS:g})" if flagged else "")
            + (f"; of the plant's bound {_spread(plant)}" if plant else "")
            + (f"; {failed} failed" if failed else "")
            + goal
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="two dampers, exact model, 0 A and 1 A, 2.5 s runs (0.5 s after the settle)",
    )
    parser.add_argument("--jobs", type=int, default=2, help="processes for the damper runs (default 2)")
    parser.add_argument(
        "--dampers", choices=("all", "train", "unseen"), default="all", help="which part of the spread (default all)"
    )
    parser.add_argument(
        "--json", metavar="PATH", type=Path, help="write the record here (default: tools/out/bench_compare.json)"
    )
    args = parser.parse_args()
    record = Recorder("bench_compare")
    duration = 2.5 if args.quick else 30.0  # compare.settle_s (2 s) is left out of each run's metrics
    dampers = [(n, p) for n, p in DAMPERS if not args.quick or n in QUICK_DAMPERS]
    if args.dampers != "all":
        dampers = [(n, p) for n, p in dampers if (n in TRAIN_DAMPERS) == (args.dampers == "train")]
    mismatches = (0.0,) if args.quick else (0.0, 0.1)
    print(
        f"ISO 8608 class C, {duration:g} s per run, {len(dampers)} dampers x {len(mismatches)} models, "
        f"load {os.getloadavg()[0]:.2f}, commit {record.start['commit']}"
    )
    header = (
        f"{'damper':26s} {'model':6s} {'best i':>6s} {'runs':>4s} {'best θ̈2':>8s} {'2-cur':>6s} {'bound':>6s} "
        + " ".join(f"{law[:13]:>13s}" for law in LAWS)
    )
    print(header)
    start = time.perf_counter()
    cases = [(name, params, m, duration, args.quick) for name, params in dampers for m in mismatches]
    if args.jobs > 1:
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=get_context("fork")) as pool:
            rows = list(pool.map(measure, cases))
    else:
        rows = [measure(case) for case in cases]
    for case in rows:
        cells = [f"{'failed':>13s}" if (g := case.gains_pct.get(law)) is None else f"{g:+12.1f}%" for law in LAWS]
        model = "exact" if not case.mismatch else "10%off"
        print(
            f"{case.damper:26s} {model:6s} {case.best_current_a:6g} {case.baseline_runs:4d} {case.rms_accel_best:8.3f} "
            f"{case.two_current_a:6g} {case.bound_gain_pct:5.1f}% " + " ".join(cells)
        )
    print(
        f"({len(cases)} cases of {duration:g} s runs in {time.perf_counter() - start:.1f} s wall, {args.jobs} processes)"
    )
    summarise("all dampers", rows)
    train = [r for r in rows if r.damper in TRAIN_DAMPERS]
    unseen = [r for r in rows if r.damper not in TRAIN_DAMPERS]
    if train and unseen:
        summarise("training dampers (the LQR laws' default weights were chosen on these)", train)
        summarise("unseen dampers", unseen)
    print()
    samples = 2_000 if args.quick else 200_000
    print(
        f"law compute per cycle ({samples} calls on varied states): median / p99 [us]   [goal <= {GOAL_CYCLE_US:g} us median]"
    )
    cycle = {}
    for law, sets in LAWS.items():
        median, p99 = law_cycle_us(law, sets, samples)
        cycle[law] = {"median_us": median, "p99_us": p99}
        print(f"  {law:18s} {median:6.2f} / {p99:6.2f}")
    print()
    compare_s = 2.5 if args.quick else 30.0
    walls = {}
    for jobs in (1, 2):
        wall = compare_wall_s(compare_s, jobs)
        walls[jobs] = wall
        print(
            f"sashil compare, 8 laws x {compare_s:g} s on sim, {jobs} process(es): {wall:.1f} s wall "
            f"(load {os.getloadavg()[0]:.2f})   [goal <= {GOAL_COMPARE_S:g} s for 30 s runs]"
        )
    path = args.json if args.json is not None else (None if args.quick else out_path("bench_compare"))
    if path is not None:
        figures = {
            "road": ROAD,
            "duration_s": duration,
            "bound_tolerance_pts": BOUND_TOLERANCE_PTS,
            "cases": [asdict(r) for r in rows],
            "law_cycle_us": cycle,
            "compare_wall_s": {f"{compare_s:g} s x 8 laws, {jobs} process(es)": w for jobs, w in walls.items()},
        }
        print(f"record: {record.write(path, figures)}")


if __name__ == "__main__":
    main()

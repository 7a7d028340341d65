#!/usr/bin/env python3
"""Benchmark: the comparison laws against the best constant current, their cost per cycle, and the
wall time of ``sashil compare``.

For the spread of dampers of ``tools/bench_drop_damping.py`` (the Bouc-Wen exponent n, the yield
torque through alpha1 and delta, the inertia J, c1 and k, varied around seed 001's set, and
combinations), each with the controller's model exact and 10 % off (``mismatch.fraction: 0.1``,
alternating signs, the coil lag 10 % slower), on ISO 8608 class C at the rig's speed (``road.speed_m_s``),
30 s per run on the simulated rig (virtual clock, 4096-count encoders):

- the best constant current, searched over [0, i_max] on a grid of 11 currents, by RMS arm
  acceleration (the ``sashil compare`` metric);
- each law's RMS arm acceleration as a gain over it (positive: better), worst and median over the
  dampers. Goal (clipped-optimal and skyhook-add): >= 10 % on every damper.
- the optimal bound (:mod:`sashil.lab.optimal_bound`, the simulated plant's viscous envelope,
  the road known in advance): how far it lies below the best constant damping, and each law's gain
  as a share of it.
- the same figures on the training dampers (every other one of the list, from the first: the set the
  LQR laws' default weights were chosen on) and on the others (unseen by that choice).
- each law's own compute per cycle (its torque/current call on recorded states), median and p99.
  Goal: <= 10 us median.
- ``sashil compare`` with 8 laws x 30 s on the simulated rig, in 1 and 2 processes. Goal: <= 30 s.

    .venv/bin/python tools/bench_compare.py [--quick] [--jobs N] [--dampers all|train|unseen] [--json PATH]

``--quick``: the same tables on a tiny problem: two dampers (one training, one unseen), the exact model,
0 A and 1 A as the constant currents, 2.5 s runs (0.5 s after the settle), 2000 calls per law and
``sashil compare`` of 2.5 s runs; the figures mean little.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_drop_damping import DAMPERS

from sashil.config.parts import StageParts
from sashil.control.law_api import LawState
from sashil.control.law_config import build_law
from sashil.control.law_registry import find_law
from sashil.drivers.mismatch import plant_sections
from sashil.engine.resolve import apply_overrides, default_config
from sashil.lab._compare import LawJob, run_job
from sashil.lab.optimal_bound import BoundResult, optimal_bound
from sashil.models.hysteresis import BoucWenParams
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


@dataclass
class Case:
    """One damper and model: the best constant current, the bound, each law's gain over it [%]."""

    damper: str
    mismatch: float
    best_current_a: float
    rms_accel_best: float
    bound_gain_pct: float
    gains_pct: dict[str, float | None]

    @property
    def label(self) -> str:
        return f"{self.damper}, {'exact' if not self.mismatch else '10 % off'}"


def config_of(params: dict[str, float], mismatch: float) -> dict[str, Any]:
    config: dict[str, Any] = default_config()
    config["model"]["params"].update(params)
    if mismatch:
        config["mismatch"]["fraction"] = mismatch
        config["mismatch"]["coil_tau"] = mismatch
    return config


def jobs_for(base: dict[str, Any], currents: list[float], duration: float) -> list[LawJob]:
    jobs = []
    for current in currents:
        config = apply_overrides(base, ["controller.law=passive", f"controller.current_a={current}"])
        jobs.append(LawJob(f"passive {current:g} A", config, "iso8608:C", duration))
    for law, sets in LAWS.items():
        jobs.append(LawJob(law, apply_overrides(base, [f"controller.law={law}", *sets]), "iso8608:C", duration))
    return jobs


def bound_of(config: dict[str, Any], duration: float) -> BoundResult:
    """The optimal bound on the simulated plant's envelope (the truth, mismatch applied) on the road."""
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    model, _ = plant_sections(config["model"], config["rig"], config["mismatch"])
    params = BoucWenParams.from_mapping(model["params"])
    i_max = float(config["rig"]["current_max_a"])
    return optimal_bound(params, i_max, road, duration, float(config["compare"]["settle_s"]))


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


def summarise(title: str, rows: list[Case]) -> None:
    """Per law: the worst and median gain over the best constant current, and as a share of the bound."""
    bounds = [r.bound_gain_pct for r in rows]
    print()
    print(f"{title}: {len(rows)} runs per law")
    print(
        f"  optimal bound below the best constant damping (plant's viscous envelope): worst {min(bounds):.1f} %, "
        f"median {statistics.median(bounds):.1f} %, best {max(bounds):.1f} %"
    )
    print("  gain in RMS arm acceleration over the best constant current (positive: better); that gain as a share")
    print("  of the bound's (100 %: all the bound allows)")
    for law in LAWS:
        done = [(r, gain) for r in rows if (gain := r.gains_pct.get(law)) is not None]
        failed = len(rows) - len(done)
        if not done:
            print(f"    {law:18s} no finished run")
            continue
        gains = [gain for _, gain in done]
        worst = min(done, key=lambda pair: pair[1])[0]
        shares = [100.0 * gain / r.bound_gain_pct for r, gain in done if r.bound_gain_pct > 0]
        share = f"; share worst {min(shares):+6.1f} %, median {statistics.median(shares):+6.1f} %" if shares else ""
        goal = ""
        if law in GOAL_LAWS:
            met = not failed and min(gains) >= GOAL_GAIN_PCT
            goal = f"   [goal >= {GOAL_GAIN_PCT:g} % on every damper: {'met' if met else 'NOT met'}]"
        print(
            f"    {law:18s} worst {min(gains):+6.1f} % ({worst.label}), median {statistics.median(gains):+6.1f} %"
            + share
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
    parser.add_argument("--json", metavar="PATH", help="also write each damper's figures to PATH")
    args = parser.parse_args()
    duration = 2.5 if args.quick else 30.0  # compare.settle_s (2 s) is left out of each run's metrics
    currents = [0.0, 1.0] if args.quick else [round(0.1 * i, 2) for i in range(11)]
    dampers = [(n, p) for n, p in DAMPERS if not args.quick or n in QUICK_DAMPERS]
    if args.dampers != "all":
        dampers = [(n, p) for n, p in dampers if (n in TRAIN_DAMPERS) == (args.dampers == "train")]
    mismatches = (0.0,) if args.quick else (0.0, 0.1)
    load = os.getloadavg()[0]
    print(
        f"ISO 8608 class C, {duration:g} s per run, {len(dampers)} dampers x {len(mismatches)} models, load {load:.2f}"
    )
    header = f"{'damper':26s} {'model':6s} {'best i':>6s} {'best θ̈2':>8s} {'bound':>6s} " + " ".join(
        f"{law[:13]:>13s}" for law in LAWS
    )
    print(header)
    start = time.perf_counter()
    cases = [(name, params, m) for name, params in dampers for m in mismatches]
    all_jobs = [jobs_for(config_of(params, m), currents, duration) for _, params, m in cases]
    flat = [job for jobs in all_jobs for job in jobs]
    configs = [config_of(params, m) for _, params, m in cases]
    if args.jobs > 1:
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=get_context("fork")) as pool:
            bounds_future = [pool.submit(bound_of, config, duration) for config in configs]
            results = list(pool.map(run_job, flat, chunksize=4))
            bounds = [future.result() for future in bounds_future]
    else:
        results = [run_job(job) for job in flat]
        bounds = [bound_of(config, duration) for config in configs]
    per_case = len(all_jobs[0])
    rows: list[Case] = []
    for index, (name, _, mismatch) in enumerate(cases):
        chunk = results[index * per_case : (index + 1) * per_case]
        passive = [r for r in chunk[: len(currents)] if r.ok]
        best = min(passive, key=lambda r: r.metrics["rms_accel_rad_s2"])
        a_best = best.metrics["rms_accel_rad_s2"]
        case = Case(name, mismatch, float(best.label.split()[1]), a_best, bounds[index].gain_pct, {})
        cells = []
        for r in chunk[len(currents) :]:
            if not r.ok:
                case.gains_pct[r.label] = None
                cells.append(f"{'failed':>13s}")
                print(f"  {name} {r.label}: {r.status}")
                continue
            gain = 100.0 * (1.0 - r.metrics["rms_accel_rad_s2"] / a_best)
            case.gains_pct[r.label] = gain
            cells.append(f"{gain:+12.1f}%")
        rows.append(case)
        model = "exact" if not mismatch else "10%off"
        print(
            f"{name:26s} {model:6s} {case.best_current_a:6g} {a_best:8.3f} {case.bound_gain_pct:5.1f}% "
            + " ".join(cells)
        )
    print(f"({len(flat)} runs of {duration:g} s in {time.perf_counter() - start:.1f} s wall, {args.jobs} processes)")
    summarise("all dampers", rows)
    train = [r for r in rows if r.damper in TRAIN_DAMPERS]
    unseen = [r for r in rows if r.damper not in TRAIN_DAMPERS]
    if train and unseen:
        summarise("training dampers (the LQR laws' default weights were chosen on these)", train)
        summarise("unseen dampers", unseen)
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(r) for r in rows], indent=1))
    print()
    samples = 2_000 if args.quick else 200_000
    print(
        f"law compute per cycle ({samples} calls on varied states): median / p99 [us]   [goal <= {GOAL_CYCLE_US:g} us median]"
    )
    for law, sets in LAWS.items():
        median, p99 = law_cycle_us(law, sets, samples)
        print(f"  {law:18s} {median:6.2f} / {p99:6.2f}")
    print()
    compare_s = 2.5 if args.quick else 30.0
    for jobs in (1, 2):
        wall = compare_wall_s(compare_s, jobs)
        print(
            f"sashil compare, 8 laws x {compare_s:g} s on sim, {jobs} process(es): {wall:.1f} s wall "
            f"(load {os.getloadavg()[0]:.2f})   [goal <= {GOAL_COMPARE_S:g} s for 30 s runs]"
        )


if __name__ == "__main__":
    main()

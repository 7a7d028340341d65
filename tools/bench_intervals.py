#!/usr/bin/env python3
"""Benchmark: do calibrate's 95 % intervals contain the true damper?

Calibrates (``sashil calibrate`` on the simulated rig, virtual clock, the default plan, --inertia
the true J) a spread of dampers drawn from a seeded generator (:func:`dampers`: n 0.1-0.8, yield
torque at 0 A 0.1-1 N m and 1.5-4x that at 1 A, J 0.8-1.2, k 90-140, c1 0.3-1, c2 0.5-2, z bound
and beta/gamma varied), each under several sensor-noise seeds (seed 0: encoder quantisation alone;
seed s > 0: Gaussian angle noise of 0.3 counts before quantisation, ``rig.noise_seed`` s), and
counts how often each quantity's interval contains the truth:

* jackknife: the delete-one-block jackknife calibrate reports (:mod:`sashil.identify.intervals`);
* bootstrap: a wild block bootstrap on the same blocks (one Gauss-Newton step per replicate);
* old: +-1.96 sigma of the Gauss-Newton covariance widened by the residual-autocorrelation
  factor (the baseline, from the same fits).

Per quantity it prints coverage (fraction of (damper, seed) cases covered), the median and worst
relative half-width, the median and worst relative error, and the worst miss in half-widths
(the jackknife's and the old interval's).

    .venv/bin/python tools/bench_intervals.py [--dampers 8] [--damper-seed 2] [--noise-seeds 0,1]
        [--block-s 2.0] [--jobs 2] [--cache DIR] [--quick]

``--cache DIR`` keeps each calibration (a pickle) so that a second run re-evaluates the intervals
without refitting. ``--quick``: one damper, one seed, the short plan of tools/bench_calibrate.py
(seconds; the figures mean little).
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import pickle
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import bench_calibrate  # the sibling script (tools/ is the script's folder on sys.path)
import numpy as np
import yaml

from sashil.calibrate import calibrate_emulated, calibrate_rig
from sashil.config import default_config
from sashil.errors import SashilError
from sashil.identify.intervals import (
    LAB,
    Intervals,
    bootstrap,
    covariance_intervals,
    interval_blocks,
    jackknife,
    lab_quantities,
    quantities,
)
from sashil.identify.rig_models import bouc_wen_rescale

#: --quick: bench_calibrate's short plan, with blocks short enough for its 1 s drops
QUICK_PLAN = {**bench_calibrate.QUICK_PLAN, "interval_block_s": 0.1}
RAW = ("c1", "c2", "alpha1", "alpha2", "n")


def dampers(count: int, seed: int) -> list[dict[str, float]]:
    """``count`` true Bouc-Wen dampers drawn from a seeded generator over the lab's range."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        n = float(math.exp(rng.uniform(math.log(0.1), math.log(0.8))))
        delta = float(math.exp(rng.uniform(math.log(100.0), math.log(800.0))))
        b = float(rng.uniform(0.5, 0.95))
        s = float(rng.uniform(0.9, 1.1))
        beta, gamma = b * delta * s, (1.0 - b) * delta * s
        zu = (delta / (beta + gamma)) ** (1.0 / n)
        yield0 = float(rng.uniform(0.1, 1.0))
        yield1 = yield0 * float(rng.uniform(1.5, 4.0))
        out.append(
            {
                "J": float(rng.uniform(0.8, 1.2)),
                "k": float(rng.uniform(90.0, 140.0)),
                "c1": float(rng.uniform(0.3, 1.0)),
                "c2": float(rng.uniform(0.5, 2.0)),
                "alpha1": yield0 / zu,
                "alpha2": (yield1 - yield0) / zu,
                "beta": beta,
                "gamma": gamma,
                "delta": delta,
                "n": n,
            }
        )
    return out


def calibrate_case(args: tuple[dict, int, dict | None, str]) -> dict:
    """One calibration on the simulated rig: the truth, the Calibration and the wall time."""
    truth, noise_seed, plan, folder = args
    config = default_config()
    config["model"]["params"].update(truth)
    config["calibrate"].update(plan or {})
    q = 2.0 * math.pi / config["rig"]["encoder_counts_per_rev"]
    config["rig"].update(angle_noise_rad=0.3 * q if noise_seed else 0.0, noise_seed=noise_seed)
    started = time.perf_counter()
    try:
        outcome = calibrate_rig(config, folder, inertia=truth["J"], profile=False)
    except SashilError as err:  # the calibration itself failed: counted apart, no interval to judge
        return {"truth": truth, "noise_seed": noise_seed, "error": str(err)}
    return {
        "truth": truth,
        "noise_seed": noise_seed,
        "calibration": outcome.calibration,
        "current_max_a": float(config["rig"]["current_max_a"]),
        "wall_s": time.perf_counter() - started,
    }


def serial_case(args: tuple[dict, int, dict | None, str]) -> dict:
    """One calibration of the emulated damper over serial (real pyserial, the wall clock): the
    intervals as params.yaml holds them."""
    truth, noise_seed, plan, folder = args
    config = default_config()
    config["model"]["params"].update(truth)
    config["calibrate"].update(plan or {})
    started = time.perf_counter()
    path = calibrate_emulated(config, folder, transport="serial", inertia=truth["J"])
    doc = yaml.safe_load(Path(path).read_text())
    return {"truth": truth, "noise_seed": noise_seed, "params_doc": doc, "wall_s": time.perf_counter() - started}


def report_serial(rows: list[dict]) -> None:
    """Coverage of params.yaml's intervals_95 over serial; the old +-1.96 sigma x inflation where
    it is a raw parameter's (k = k, c_0a = c1, yield_0a = alpha1 at a unit z bound)."""
    raw = {"k": "k", "c_0a": "c1", "yield_0a": "alpha1"}
    print(
        f"{'quantity':>10} | {'old cover':>9} | {'new cover':>9} {'med hw':>7} {'worst hw':>8} | {'med err':>7} {'worst err':>9}"
    )
    for name in [*LAB, *RAW]:
        cov, cov_old, hw, err = [], [], [], []
        for case in rows:
            doc = case["params_doc"]
            best = doc["params"]
            truth = lab_quantities("bouc-wen", bouc_wen_rescale(case["truth"], 1.0), 1.0)
            truth.update({k: v for k, v in bouc_wen_rescale(case["truth"], 1.0).items() if k not in truth})
            low, high = doc["intervals_95"][name]
            value = lab_quantities("bouc-wen", best, 1.0).get(name, best.get(name))
            cov.append(low <= truth[name] <= high)
            hw.append(0.5 * (high - low) / abs(value))
            err.append(value / truth[name] - 1.0)
            if name in raw or name in RAW:
                key = raw.get(name, name)
                half = 1.959964 * doc["calibration"]["uncertainty_inflation"] * doc["uncertainty_1sigma"][key]
                cov_old.append(abs(best[key] - truth[name]) <= half)
        old = f"{100 * np.mean(cov_old):>8.0f}%" if cov_old else f"{'-':>9}"
        print(
            f"{name:>10} | {old} | {100 * np.mean(cov):>8.0f}% {100 * np.median(hw):>6.2f}% {100 * np.max(hw):>7.2f}% "
            f"| {100 * np.median(np.abs(err)):>6.2f}% {100 * np.max(np.abs(err)):>8.2f}%"
        )
    for d, case in enumerate(rows):
        cal = case["params_doc"]["calibration"]
        suspect = " (fit suspect: no interval around a wrong optimum covers)" if cal["intervals"]["fit_suspect"] else ""
        print(f"  damper {d}: held-out NRMSE {100 * cal['held_out_nrmse_mean']:.2f} %{suspect}")
    fits = [case["params_doc"]["calibration"]["fit_s"] for case in rows]
    print(
        f"{len(rows)} calibrations over serial; fit {np.median(fits):.1f} s median, {max(fits):.1f} s worst; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )


def cases(
    truths: list[dict], seeds: list[int], plan: dict | None, tmp: Path, cache: Path | None, jobs: int
) -> list[dict]:
    todo, out = [], {}
    for d, truth in enumerate(truths):
        for s in seeds:
            digest = hashlib.sha1(repr(sorted(truth.items())).encode()).hexdigest()[:10]
            key = f"{digest}-{s}{'-quick' if plan else ''}"
            path = cache / f"{key}.pkl" if cache else None
            if path is not None and path.exists():
                out[(d, s)] = pickle.loads(path.read_bytes())
            else:
                todo.append(((d, s), path, (truth, s, plan, str(tmp / f"{d}-{s}"))))
    if todo:
        with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
            for (key, path, _), case in zip(todo, pool.map(calibrate_case, [t[2] for t in todo]), strict=True):
                if path is not None:
                    path.write_bytes(pickle.dumps(case))
                out[key] = case
    failed = [out[k] for k in sorted(out) if "error" in out[k]]
    for case in failed:
        print(f"calibration failed (left out): noise seed {case['noise_seed']}: {case['error']}")
    return [{**out[k], "damper": k[0]} for k in sorted(out) if "error" not in out[k]]


def evaluate(case: dict, block_s: float) -> tuple[dict[str, Intervals], dict, float]:
    """The intervals of every method for one calibration, the true quantities, and the time the
    chosen method took."""
    cal = case["calibration"]
    best, imax = cal.best, case["current_max_a"]
    block = interval_blocks(cal.fit_records, block_s, best.model_free)  # as calibrate does
    started = time.perf_counter()
    chosen = jackknife(best, cal.fit_records, imax, block)
    cost = time.perf_counter() - started
    methods = {
        "old": covariance_intervals(best, cal.inflation, imax),
        "bootstrap": bootstrap(best, cal.fit_records, imax, 2000, block),
        "jackknife": chosen,
    }
    truth = quantities(best, bouc_wen_rescale(case["truth"], 1.0), imax)
    return methods, truth, cost


def report(rows: list[dict], block_s: float) -> None:
    results = [evaluate(case, block_s) for case in rows]
    methods = list(results[0][0])
    print("coverage of the 95 % interval / median relative half-width, per method; then the jackknife's worst")
    print(
        f"{'quantity':>10} | "
        + " | ".join(f"{m:>17}" for m in methods)
        + f" | {'worst hw':>8} | {'med err':>7} {'worst err':>9} | {'worst miss':>10} {'(old)':>10}"
    )
    for name in [*LAB, *RAW]:
        cells, err, hw, miss = [], [], [], []
        for m in methods:
            cov = [iv[m].covers(name, truth[name]) for iv, truth, _ in results if name in truth]
            width = [iv[m].half_width(name) for iv, truth, _ in results if name in truth]
            if not cov:
                break
            cells.append(f"{100 * np.mean(cov):>4.0f}% / {100 * np.median(width):>6.2f}%")
        if len(cells) < len(methods):
            continue
        miss_old = []
        for iv, truth, _ in results:
            new, t = iv["jackknife"], truth[name]
            err.append(new.value[name] / t - 1.0)
            hw.append(new.half_width(name))
            half = 0.5 * (new.high[name] - new.low[name])
            miss.append(abs(new.value[name] - t) / half if half > 0 else math.inf)
            half_old = 0.5 * (iv["old"].high[name] - iv["old"].low[name])
            miss_old.append(abs(iv["old"].value[name] - t) / half_old if half_old > 0 else math.inf)
        print(
            f"{name:>10} | "
            + " | ".join(f"{c:>17}" for c in cells)
            + f" | {100 * np.max(hw):>7.2f}% | {100 * np.median(np.abs(err)):>6.2f}% {100 * np.max(np.abs(err)):>8.2f}% "
            f"| {np.max(miss):>9.2f}x {np.max(miss_old):>9.1f}x"
        )
    lab = [n for n in LAB if n in results[0][1]]
    for m in methods:
        per_quantity = [np.mean([iv[m].covers(n, truth[n]) for iv, truth, _ in results]) for n in lab]
        per_case = [np.mean([iv[m].covers(n, truth[n]) for n in lab]) for iv, truth, _ in results]
        print(
            f"{m:>10}: lab quantities covered {100 * np.mean(per_case):.0f} % of (case, quantity) pairs; worst quantity "
            f"{100 * min(per_quantity):.0f} %, worst case {100 * min(per_case):.0f} %"
        )
    fits = [case["calibration"].fit_s for case in rows]
    costs = [r[2] for r in results]
    blocks = [r[0]["jackknife"].blocks for r in results]
    print(
        f"{len(rows)} calibrations; fit {np.median(fits):.1f} s median, {max(fits):.1f} s worst; jackknife "
        f"{np.median(costs):.2f} s median, {max(costs):.2f} s worst ({min(blocks)}-{max(blocks)} blocks of about "
        f"{block_s:g} s); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dampers", type=int, default=8, help="dampers drawn (default 8)")
    parser.add_argument("--damper-seed", type=int, default=2, help="seed of the damper generator (default 2)")
    parser.add_argument("--noise-seeds", default="0,1", help="sensor-noise seeds (0: quantisation alone)")
    parser.add_argument(
        "--block-s", type=float, default=2.0, help="jackknife block length (calibrate.interval_block_s)"
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--cache", type=Path, help="keep each calibration here (re-evaluate without refitting)")
    parser.add_argument(
        "--transport",
        choices=("sim", "serial"),
        default="sim",
        help="sim: the simulated rig (virtual clock); serial: the emulated damper over a pty (wall clock, one at a time)",
    )
    parser.add_argument("--quick", action="store_true", help="one damper, one seed, a 1 s-drop plan (seconds)")
    args = parser.parse_args()
    count, seeds = (1, [0]) if args.quick else (args.dampers, [int(s) for s in args.noise_seeds.split(",")])
    truths = dampers(count, args.damper_seed)
    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
    if args.transport == "serial":
        with tempfile.TemporaryDirectory(prefix="bench-intervals-") as tmp:
            rows = []
            for d, truth in enumerate(truths):
                print(f".. {time.strftime('%H:%M:%S')} damper {d} over serial", flush=True)
                rows.append(serial_case((truth, 0, QUICK_PLAN if args.quick else None, str(Path(tmp) / str(d)))))
        print(
            f"sashil calibrate over serial against the emulated damper: {count} dampers (generator seed {args.damper_seed})"
        )
        report_serial(rows)
        return
    with tempfile.TemporaryDirectory(prefix="bench-intervals-") as tmp:
        rows = cases(truths, seeds, QUICK_PLAN if args.quick else None, Path(tmp), args.cache, args.jobs)
    print(
        f"sashil calibrate on the simulated rig, {'the --quick plan' if args.quick else 'the default plan'}: "
        f"{count} dampers (generator seed {args.damper_seed}) x noise seeds {seeds}"
    )
    report(rows, QUICK_PLAN["interval_block_s"] if args.quick else args.block_s)


if __name__ == "__main__":
    main()

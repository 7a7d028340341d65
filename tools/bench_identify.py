#!/usr/bin/env python3
"""Benchmark: joint Bouc-Wen identification on two 10 s simulated drop tests (0 A, 1 A; 1 kHz,
4096-count encoder) - the fast path of ``sashil identify`` beside a straightforward baseline
(scipy solve_ivp simulation inside differential_evolution, same parameter box, time-capped).

Prints wall times, evaluations, training NRMSE, and the NRMSE on a held-out 0.5 A drop test from a
different theta0 (against the recorded, quantised angle and against the noiseless angle), and the
parameter errors against the truth (normalised to a unit z bound, as identification writes them).

    python tools/bench_identify.py            # baseline capped at 10 minutes
    python tools/bench_identify.py --cap 60   # baseline capped at 60 s (development)
    python tools/bench_identify.py --quick    # 1 s drops, a tiny fit budget, baseline capped at 3 s (seconds)
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import differential_evolution

from sashil.identify.data import record_from_columns
from sashil.identify.fit import FitOptions, fit_model
from sashil.identify.rig_models import MODELS, bouc_wen_rescale
from sashil.identify.synthetic import drop_test_columns
from sashil.models.hysteresis import BoucWenParams
from sashil.stats import nrmse

TRUTH = BoucWenParams(k=95.0, c1=0.5, c2=1.2, alpha1=1.3, alpha2=0.8, beta=600.0, gamma=50.0, delta=500.0, n=0.2)
NAMES = ("k", "c1", "c2", "alpha1", "alpha2", "log10_S", "b", "n")
BOX = [(50.0, 200.0), (0.0, 3.0), (0.0, 3.0), (0.0, 2.0), (0.0, 2.0), *list(MODELS["bouc-wen"].nl_bounds)]


def params_from(x) -> dict[str, float]:
    S = 10.0 ** x[5]
    return {
        "J": 1.0,
        "k": x[0],
        "c1": x[1],
        "c2": x[2],
        "alpha1": x[3],
        "alpha2": x[4],
        "beta": S * x[6],
        "gamma": S * (1.0 - x[6]),
        "delta": S,
        "n": x[7],
    }


def ivp_simulate(p: dict[str, float], record, deadline: float) -> np.ndarray:
    """theta of a drop test by solve_ivp on (theta, theta_dot, z), z-law in time (seed 001 eq. 17)."""
    i = record.mean_current
    model = BoucWenParams.from_mapping(p)
    c, a = model.damping(i), model.hysteretic_gain(i)
    zu = (p["delta"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"])

    def rhs(t, y):
        if time.perf_counter() > deadline:
            raise TimeoutError
        th, v, z = y
        az = abs(z)
        zdot = v * (
            p["delta"] - (az ** p["n"] if az > 0 else 0.0) * (p["beta"] + p["gamma"] * math.copysign(1.0, v * z))
        )
        return [v, (-p["k"] * th - c * v - a * z) / p["J"], zdot]

    y0 = [record.theta[0], 0.0, math.copysign(zu, record.theta[0])]
    sol = solve_ivp(rhs, (record.time_s[0], record.time_s[-1]), y0, t_eval=record.time_s, rtol=1e-6, atol=1e-9)
    if not sol.success or sol.y.shape[1] != record.time_s.size:
        return np.full(record.time_s.size, np.nan)
    return sol.y[0]


def baseline(records, cap_s: float, seed: int = 0):
    started = time.perf_counter()
    deadline = started + cap_s
    evaluations = [0]
    best = [np.inf, None]

    def cost(x):
        if time.perf_counter() > deadline:
            return 1e3
        evaluations[0] += 1
        try:
            sims = [ivp_simulate(params_from(x), r, deadline) for r in records]
        except TimeoutError:
            return 1e3
        err = np.concatenate([s - r.theta for s, r in zip(sims, records, strict=True)])
        value = float(np.sqrt(np.mean(err**2))) if np.all(np.isfinite(err)) else 1e3
        if value < best[0]:
            best[0], best[1] = value, np.array(x)
        return value

    differential_evolution(
        cost,
        BOX,
        popsize=5,
        maxiter=1000,
        seed=seed,
        polish=False,
        tol=1e-8,
        callback=lambda *a, **k: time.perf_counter() > deadline,
    )
    return best[1], time.perf_counter() - started, evaluations[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="1 s drops, a tiny fit budget, baseline capped at 3 s (seconds)"
    )
    parser.add_argument("--cap", type=float, help="baseline cap in seconds (overrides --quick)")
    args = parser.parse_args()
    cap = args.cap if args.cap else (3.0 if args.quick else 600.0)
    seconds = 1.0 if args.quick else 10.0
    options = FitOptions(design=16, starts=2, refine=1, probe_nfev=3, max_nfev=5) if args.quick else FitOptions()

    records = [record_from_columns(f"drop {i:g} A", drop_test_columns(TRUTH, -5.0, i, seconds)) for i in (0.0, 1.0)]
    held = record_from_columns("held-out 0.5 A, -4 deg", drop_test_columns(TRUTH, -4.0, 0.5, seconds))
    clean = drop_test_columns(TRUTH, -4.0, 0.5, seconds, counts_per_rev=0)["theta_rad"]
    truth = bouc_wen_rescale(TRUTH.as_dict())

    def describe(label, params, wall, evals, train):
        sim = MODELS["bouc-wen"].simulate(params, held)
        errs = {k: 100.0 * (params[k] - truth[k]) / truth[k] for k in ("k", "c1", "c2", "alpha1", "alpha2")}
        fit, true = BoucWenParams.from_mapping(params), BoucWenParams.from_mapping(truth)
        at = {f"c({i:g})": 100 * (fit.damping(i) / true.damping(i) - 1) for i in (0, 1)}
        at.update({f"alpha({i:g})": 100 * (fit.hysteretic_gain(i) / true.hysteretic_gain(i) - 1) for i in (0, 1)})
        print(
            f"{label:<34} {wall:>9.2f} {evals:>7d} {100 * train:>10.3f}% {100 * nrmse(sim, held.theta):>10.3f}% "
            f"{100 * nrmse(sim, clean):>10.3f}%"
        )
        print("    parameter errors [%]: " + ", ".join(f"{k} {v:+.2f}" for k, v in {**errs, **at}.items()))

    print("truth (unit z bound):", ", ".join(f"{k}={v:.5g}" for k, v in truth.items()))
    print(f"{'method':<34} {'wall [s]':>9} {'evals':>7} {'train NRMSE':>11} {'val NRMSE':>11} {'val vs clean':>11}")
    t0 = time.perf_counter()
    result = fit_model("bouc-wen", records, options)
    wall = time.perf_counter() - t0
    describe("sashil identify (VP + DE + LS)", result.params, wall, result.evaluations, float(np.mean(result.nrmse)))
    x, bwall, bevals = baseline(records, cap)
    if x is None:
        print(f"baseline: no finite evaluation within {cap:g} s")
        return
    p = params_from(x)
    train = float(np.mean([nrmse(MODELS["bouc-wen"].simulate(p, r), r.theta) for r in records]))
    describe(f"baseline solve_ivp+DE (cap {cap:g} s)", p, bwall, bevals, train)
    print(
        "NRMSE = RMS error / std of the angle; 'val' is against the recorded (quantised) angle, "
        "'vs clean' against the noiseless one. Wall times on a shared 2-core machine are noisy."
    )


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_identify", main)

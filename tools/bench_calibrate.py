#!/usr/bin/env python3
"""Benchmark: ``sashil calibrate`` over serial against emulated dampers of a spread.

For each damper of :data:`DAMPERS` (not the seed alone: n 0.1-0.6, yield torque 0.2-2.5 N m at
1 A, J 0.8-1.2, k and c varied too) it writes the plant config, starts ``sashil emulate`` behind a
pty playing the operator at the angle each of the host's hold prompts asks, runs ``sashil
calibrate --driver serial --inertia J`` against it (:func:`sashil.lab.calibration.calibrate_emulated`: real pyserial, real clock,
the default plan) and prints:

* held-out NRMSE: the fitted model against the *true* plant's noiseless response to the same
  inputs (each held-out record's initial angle, current and road motion, simulated with the true
  parameters by :meth:`sashil.identify.rig_models.RigModel.simulate`: an independent judge of the
  prediction, free of encoder quantisation) - and, beside it, what calibrate reports against the
  recorded (quantised) angle;
* yield torque alpha(i)*z_u and c(i) errors at 0 and 1 A, k error (the fit's J is the true J);
* rig time (wall) and fit time (the identification; the n profile after it is listed apart).

Targets: held-out NRMSE <= 2 %, yield within 3 %, c(i) within 8 %, k within 1 %, fit
<= 30 s. The worst damper is printed beside the median.

    .venv/bin/python tools/bench_calibrate.py [--dampers 1,3] [--transport serial|slcan|sim] [--quick]

``--transport sim`` runs the same plan on the in-process simulated rig (virtual clock): the
identification's accuracy without the link's timing noise, as a reference.

About 2 minutes of rig time per damper (plus the fit): ~12 minutes for all five.

``--quick``: damper 0 only (unless --dampers) with :data:`QUICK_PLAN` (two 0.8 s drops to fit, one
held out, no road run: the fewest and shortest steps the plan allows); the figures mean little.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sashil.config import load_params
from sashil.engine.resolve import default_config
from sashil.identify.rig_models import MODELS
from sashil.lab.calibration import calibrate_emulated, calibrate_rig
from sashil.lab.calibration.analysis import records_of
from sashil.lab.calibration.plan import plan_from_config
from sashil.lab.calibration.rig import StepResult
from sashil.recording.data_file import read_data_csv
from sashil.stats import nrmse

# true dampers: yield torque at i A is (alpha1 + alpha2*i) * z_u with z_u = (delta/(beta+gamma))^(1/n)
DAMPERS = [
    {"J": 1.0, "k": 109.0, "c1": 0.7, "c2": 1.5, "alpha1": 1.0, "alpha2": 1.0, "beta": 873.0, "gamma": 1.0,
     "delta": 700.0, "n": 0.099},  # the seed (yield 0.21 N m at 1 A)
    {"J": 0.8, "k": 95.0, "c1": 0.5, "c2": 1.2, "alpha1": 0.30, "alpha2": 0.45, "beta": 300.0, "gamma": 60.0,
     "delta": 360.0, "n": 0.2},  # z_u = 1: yield 0.75 N m at 1 A
    {"J": 1.2, "k": 130.0, "c1": 0.9, "c2": 2.0, "alpha1": 0.4, "alpha2": 1.1, "beta": 150.0, "gamma": 50.0,
     "delta": 200.0, "n": 0.35},  # yield 1.5 N m at 1 A
    {"J": 0.9, "k": 100.0, "c1": 0.4, "c2": 0.8, "alpha1": 0.6, "alpha2": 1.9, "beta": 80.0, "gamma": 40.0,
     "delta": 120.0, "n": 0.6},  # yield 2.5 N m at 1 A
    {"J": 1.1, "k": 120.0, "c1": 0.6, "c2": 1.0, "alpha1": 0.15, "alpha2": 0.35, "beta": 500.0, "gamma": 100.0,
     "delta": 600.0, "n": 0.45},  # yield 0.5 N m at 1 A
]  # fmt: skip

#: the ``calibrate`` plan of --quick: the fewest runs the fit and the held-out check take
QUICK_PLAN = {
    "currents_a": [0.0, 1.0],
    "small_currents_a": [],
    "road_currents_a": [],
    "validate_currents_a": [0.5],
    "drop_duration_s": 0.8,
}


def yield_torque(p: dict, i: float) -> float:
    return (p["alpha1"] + p["alpha2"] * i) * (p["delta"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"])


def held_out_vs_truth(folder: Path, truth: dict, fitted: dict, config: dict) -> list[float]:
    """NRMSE of the fitted model against the true plant on each held-out record's inputs (``config``'s plan)."""
    summary = json.loads((folder / "summary.json").read_text())
    plan = {s.name: s for s in plan_from_config(config).steps}
    results = []
    for row in summary["runs"]:
        if row["role"] != "validate":
            continue
        cols = read_data_csv(folder / "runs" / row["name"] / "data.csv", required=("time_s",))
        results.append(StepResult(plan[row["name"]], cols, row["hold_angle_deg"], row["release_estimated"]))
    out = []
    for record in records_of(results, config["rig"]["encoder_counts_per_rev"]):
        true = MODELS["bouc-wen"].simulate(truth, record)
        fit = MODELS["bouc-wen"].simulate(fitted, record)
        out.append(nrmse(fit, true))
    return out


def run_damper(index: int, truth: dict, tmp: Path, transport: str, plan: dict | None = None) -> dict:
    config = default_config()
    config["model"]["params"].update(truth)
    config["calibrate"].update(plan or {})
    out = tmp / f"damper{index}"
    started = time.perf_counter()
    if transport == "sim":  # the same plan on the in-process simulated rig (virtual clock): no link
        params = calibrate_rig(config, out, inertia=truth["J"]).params_path
    else:
        params = calibrate_emulated(config, out, transport=transport, inertia=truth["J"])
    wall = time.perf_counter() - started
    fitted = load_params(params)["params"]
    summary = json.loads((out / "summary.json").read_text())
    row = {
        "damper": index,
        "n": truth["n"],
        "yield_1A": yield_torque(truth, 1.0),
        "J": truth["J"],
        "held_truth": max(held_out_vs_truth(out, truth, fitted, config)),
        "held_recorded": max(summary["held_out_nrmse"].values()),
        "k": fitted["k"] / truth["k"] - 1.0,
        "rig_s": summary["rig_time_s"],
        "fit_s": summary["fit_s"],
        "profile_s": summary["identifiability_s"],
        "wall_s": wall,
        "fitted_n": fitted["n"],
    }
    for i in (0.0, 1.0):
        row[f"yield_{i:g}"] = yield_torque(fitted, i) / yield_torque(truth, i) - 1.0
        c_true = truth["c1"] + truth["c2"] * i
        row[f"c_{i:g}"] = (fitted["c1"] + fitted["c2"] * i) / c_true - 1.0
    return row


COLUMNS = [
    ("held_truth", "held-out NRMSE", 100, ".2f", "%"),
    ("held_recorded", "(vs recorded)", 100, ".2f", "%"),
    ("yield_0", "yield 0 A", 100, "+.1f", "%"),
    ("yield_1", "yield 1 A", 100, "+.1f", "%"),
    ("c_0", "c(0 A)", 100, "+.1f", "%"),
    ("c_1", "c(1 A)", 100, "+.1f", "%"),
    ("k", "k", 100, "+.2f", "%"),
    ("rig_s", "rig time", 1, ".0f", "s"),
    ("fit_s", "fit", 1, ".1f", "s"),
]


def print_table(rows: list[dict]) -> None:
    head = f"{'damper':>6} {'n':>5} {'yield@1A':>8} {'J':>4} " + " ".join(f"{c[1]:>14}" for c in COLUMNS)
    print(head)
    for r in rows:
        cells = " ".join(f"{format(r[key] * scale, fmt) + ' ' + unit:>14}" for key, _, scale, fmt, unit in COLUMNS)
        print(f"{r['damper']:>6} {r['n']:>5.3g} {r['yield_1A']:>8.3g} {r['J']:>4.2g} {cells}")
    for label, pick in (("median", np.median), ("worst", None)):
        cells = []
        for key, _, scale, fmt, unit in COLUMNS:
            values = np.array([r[key] for r in rows])
            value = values[np.argmax(np.abs(values))] if pick is None else pick(np.abs(values))
            cells.append(f"{format(value * scale, fmt.replace('+', '')) + ' ' + unit:>14}")
        print(f"{label:>6} {'':>5} {'':>8} {'':>4} " + " ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dampers", help="comma-separated indices into DAMPERS (default: all)")
    parser.add_argument(
        "--transport",
        choices=("serial", "slcan", "sim"),
        default="serial",
        help="the emulated rig over serial or slcan, or sim: the in-process simulated rig (no link, reference)",
    )
    parser.add_argument("--quick", action="store_true", help="damper 0 only, two 0.8 s drops to fit and one held out")
    args = parser.parse_args()
    dampers = args.dampers or ("0" if args.quick else None)
    chosen = [int(x) for x in dampers.split(",")] if dampers else list(range(len(DAMPERS)))
    plan = QUICK_PLAN if args.quick else None
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-calibrate-") as tmp:
        for index in chosen:
            truth = DAMPERS[index]
            print(
                f".. {time.strftime('%H:%M:%S')} damper {index}: n {truth['n']:g}, yield at 1 A "
                f"{yield_torque(truth, 1.0):.3g} N m, J {truth['J']:g}",
                flush=True,
            )
            row = run_damper(index, truth, Path(tmp), args.transport, plan)
            print(
                f"   held-out {100 * row['held_truth']:.2f} %, fitted n {row['fitted_n']:.3g}, "
                f"wall {row['wall_s']:.0f} s",
                flush=True,
            )
            rows.append(row)
    print()
    which = "the --quick plan" if args.quick else "default plan"
    print(f"sashil calibrate over {args.transport}, {which}, --inertia J (true J), 4096 counts/rev:")
    print_table(rows)
    print(
        "targets: held-out NRMSE <= 2 %, yield within 3 %, c(i) within 8 %, k within 1 %, fit <= 30 s "
        f"(n profile after the fit: {max(r['profile_s'] for r in rows):.1f} s at most)"
    )


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_calibrate", main)

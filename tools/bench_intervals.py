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
    .venv/bin/python tools/bench_intervals.py --transport serial|slcan [--board auto|c|python] [--keep DIR]
    .venv/bin/python tools/bench_intervals.py --reanalyse DIR

``--transport serial|slcan`` calibrates the emulated damper over a link (the wall clock, one at a
time; ``--board``: the emulator's board) and reads the intervals from params.yaml; ``--keep DIR``
keeps each calibration folder there (``d<N>/``, the true damper ``d<N>.truth.json`` and the
emulator's ground truth of every sample ``d<N>.truth.csv``).
``--reanalyse DIR`` fits kept folders again, twice on the same records: with the road forcing from
the commanded speeds, and from the road the board applied (the road encoder's edges,
:mod:`sashil.identify.road`); per damper and per quantity it prints coverage, half-width, error and
the held-out NRMSE against the true plant (the baseline and the figure from the same records).
Both reports count the drops that started away from their step's angle (the hold the drop test
found more than ``drop_test.hold_tolerance_deg`` from it).

``--cache DIR`` keeps each calibration (a pickle) so that a second run re-evaluates the intervals
without refitting. ``--quick``: one damper, one seed, the short plan of tools/bench_calibrate.py
(seconds; the figures mean little).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import pickle
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import bench_calibrate  # the sibling script (tools/ is the script's folder on sys.path)
import numpy as np
import yaml

from sashil.engine.resolve import default_config, load_config
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
from sashil.identify.rig_models import MODELS, bouc_wen_rescale
from sashil.identify.road import held_speed
from sashil.lab.calibration import calibrate_emulated, calibrate_rig
from sashil.lab.calibration.analysis import APPLIED_ROAD, analyse, records_of, until_gap, with_applied_road
from sashil.lab.calibration.emulated import BOARDS
from sashil.lab.calibration.plan import plan_from_config
from sashil.lab.calibration.rig import StepResult
from sashil.recording.data_file import read_data_csv
from sashil.stats import nrmse

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


def serial_case(args: tuple[dict, int, dict | None, str, str, str, str | None]) -> dict:
    """One calibration of the emulated damper over a link (``transport`` serial or slcan, the
    emulator's ``board``; real pyserial or python-can, the wall clock): the intervals as params.yaml
    holds them. ``truth_csv``: where the emulator writes its ground truth (None: nowhere)."""
    truth, noise_seed, plan, folder, transport, board, truth_csv = args
    config = default_config()
    config["model"]["params"].update(truth)
    config["calibrate"].update(plan or {})
    started = time.perf_counter()
    path = calibrate_emulated(config, folder, transport=transport, inertia=truth["J"], board=board, truth=truth_csv)
    doc = yaml.safe_load(Path(path).read_text())
    return {
        "truth": truth,
        "noise_seed": noise_seed,
        "params_doc": doc,
        "wall_s": time.perf_counter() - started,
        "folder": Path(folder),
    }


def kept_results(folder: Path, road: str) -> tuple[dict, list[StepResult], list[StepResult]]:
    """A kept calibration folder's config and its fit and held-out runs as calibrate recorded them;
    ``road`` "commanded" leaves the road encoder's edges out (the fit takes the road from the
    commanded speeds), "applied" keeps them."""
    config = load_config(folder / "config.yaml")
    plan = {s.name: s for s in plan_from_config(config).steps}
    summary = json.loads((folder / "summary.json").read_text())
    fit: list[StepResult] = []
    held: list[StepResult] = []
    for row in summary["runs"]:
        columns = read_data_csv(folder / "runs" / row["name"] / "data.csv", required=("time_s",))
        if road == "commanded":
            columns = {k: v for k, v in columns.items() if k not in ("road_edge_s", "road_edge_dir")}
        result = StepResult(plan[row["name"]], columns, row["hold_angle_deg"], row["release_estimated"])
        (fit if row["role"] == "fit" else held).append(result)
    return config, fit, held


def reanalyse_case(args: tuple[Path, dict, str]) -> dict:
    """Fit a kept calibration again (``road``: where the fit takes the road from); its intervals,
    true quantities and held-out NRMSE against the true plant. Both fits are judged on the same
    held-out records (their road the applied one where the runs carry the edges): the fitted and
    the true damper's response to the same inputs."""
    folder, truth, road = args
    config, fit, _ = kept_results(folder, road)
    _, _, held = kept_results(folder, "applied")
    counts = int(config["rig"]["encoder_counts_per_rev"])
    current_max = float(config["rig"]["current_max_a"])
    cal = analyse(
        fit, held, "bouc-wen", truth["J"], counts, profile=False, current_max_a=current_max,
        block_s=float(config["calibrate"]["interval_block_s"]),
    )  # fmt: skip
    assert cal.intervals is not None
    model = MODELS["bouc-wen"]
    nrmses = [nrmse(model.simulate(cal.best.params, r), model.simulate(truth, r)) for r in records_of(held, counts)]
    return {
        "intervals": cal.intervals,
        "truth": quantities(cal.best, bouc_wen_rescale(truth, 1.0), current_max),
        "held_out": max(nrmses) if nrmses else math.nan,
        "uses_edges": any("road_edge_s" in r.columns for r in fit),
    }


def road_against_truth(folder: Path, truth_csv: Path) -> list[dict]:
    """Per road run of a kept calibration, how far the road each fit takes is from the road the
    emulated wheel applied (the emulator's ground truth of the same samples) [counts], over the part
    of the record the fit reads (up to its first link gap): the applied road (the edges) and the
    commanded one (the integral of the held speeds). The fit reads only
    the road's acceleration, so each error is taken about its own mean (``rms``, ``worst``); the
    applied road's mean error (``bias``) is its offset from the true angle. Samples are joined on
    the sequence number and the device time modulo 2^24 (SLCAN's wire clock; the host unwraps it)."""
    from sashil.drivers.emulator import read_truth_csv

    config = load_config(folder / "config.yaml")
    counts = int(config["rig"]["encoder_counts_per_rev"])
    q = 2.0 * math.pi / counts
    truth = read_truth_csv(truth_csv)
    wrap = 1 << 24
    row_of = {
        (int(sq) & 0xFFFF, int(dev) % wrap): k
        for k, (sq, dev) in enumerate(zip(truth["seq"], truth["device_time_us"], strict=True))
    }
    out = []
    for row in json.loads((folder / "summary.json").read_text())["runs"]:
        if row["kind"] != "road":
            continue
        run = folder / "runs" / row["name"]
        columns = read_data_csv(run / "data.csv", required=("time_s",))
        device_of: dict[int, int] = {}
        for path in sorted(run.glob("cycles*.csv")):  # the attempt the record is of (a gap repeats a step)
            cycles = read_data_csv(path, required=("seq", "device_time_us"))
            found_here = {int(sq): int(dev) for sq, dev in zip(cycles["seq"], cycles["device_time_us"], strict=True)}
            if np.isin(columns["seq"], list(found_here)).sum() > np.isin(columns["seq"], list(device_of)).sum():
                device_of = found_here
        rows = [row_of.get((int(sq) & 0xFFFF, device_of.get(int(sq), -1) % wrap)) for sq in columns["seq"]]
        found = np.array([r is not None for r in rows])
        if not found.any():
            continue
        true_road = truth["theta_road_true_rad"][[r for r in rows if r is not None]]
        applied = with_applied_road(columns, counts).get(APPLIED_ROAD)
        t = columns["time_s"]
        held = held_speed(columns["road_speed_cmd_rad_s"])
        commanded = np.concatenate(([0.0], np.cumsum(held[:-1] * np.diff(t))))
        edges = columns.get("road_edge_s")
        moving = found & (np.arange(t.size) < until_gap(columns)["time_s"].size)  # the part the fit reads
        if edges is not None and np.isfinite(edges).any():
            moving &= (t >= np.nanmin(edges)) & (t <= np.nanmax(edges))
        result = {"name": row["name"], "joined": float(found.mean())}
        for label, road in (("applied", applied), ("commanded", commanded)):
            if road is None:
                continue
            error = (road[found] - true_road)[moving[found]] / q
            centred = error - error.mean()
            result[label] = {
                "rms": float(np.sqrt(np.mean(centred**2))),
                "worst": float(np.max(np.abs(centred))),
                "bias": float(error.mean()),
            }
        out.append(result)
    return out


def samples_lost(folder: Path) -> list[float]:
    """The fraction of the board's samples each run of a kept calibration lost on the link (missed:
    a gap in the sequence numbers; skipped: the host took a newer one), from ``summary.json``."""
    out = []
    for row in json.loads((folder / "summary.json").read_text())["runs"]:
        link = row.get("link") or {}
        lost = int(link.get("samples_missed", 0)) + int(link.get("samples_skipped", 0))
        sent = int(link.get("samples", 0)) + int(link.get("samples_missed", 0))
        if sent:
            out.append(lost / sent)
    return out


def held_away(folder: Path) -> tuple[int, int]:
    """(runs whose drop started away from its step's angle, runs) of a kept calibration: the hold
    the drop test found more than ``drop_test.hold_tolerance_deg`` from the step's theta0."""
    tolerance = float(load_config(folder / "config.yaml")["drop_test"]["hold_tolerance_deg"])
    rows = json.loads((folder / "summary.json").read_text())["runs"]
    away = [r for r in rows if abs(r["hold_angle_deg"] - r["theta0_deg"]) > tolerance]
    return len(away), len(rows)


def print_held_away(folders: list[Path]) -> None:
    """How many drops started from another angle than their step's, per calibration and in all."""
    counts = [held_away(f) for f in folders]
    print(
        f"drops started away from their step's angle: {sum(a for a, _ in counts)} of {sum(n for _, n in counts)} runs; "
        + ", ".join(f"{f.name} {a}/{n}" for f, (a, n) in zip(folders, counts, strict=True))
    )


def report_reanalysis(base: Path, jobs: int) -> None:
    """The paired comparison of kept calibrations (``--reanalyse``)."""
    folders = sorted(p for p in base.glob("d*") if p.is_dir() and (p / "params.yaml").exists())
    if not folders:
        raise SystemExit(f"--reanalyse {base}: no kept calibration (d<N>/params.yaml) there")
    roads = ("commanded", "applied")
    todo = [(f, json.loads((base / f"{f.name}.truth.json").read_text()), road) for f in folders for road in roads]
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        done = list(pool.map(reanalyse_case, todo))
    rows = {road: [d for (_, _, r), d in zip(todo, done, strict=True) if r == road] for road in roads}
    if not any(d["uses_edges"] for d in rows["applied"]):
        print(f"{base}: the kept runs carry no road encoder edges (road_edge_s): both fits take the commanded road")
    print(f"{len(folders)} kept calibrations in {base}, each fitted twice on the same records")
    print(
        f"{'road from':>10} {'quantity':>9} | {'coverage':>8} {'med hw':>7} {'worst hw':>8} | {'med err':>7} {'worst err':>9}"
    )
    for road in roads:
        for name in LAB:
            cov = [d["intervals"].covers(name, d["truth"][name]) for d in rows[road]]
            hw = [d["intervals"].half_width(name) for d in rows[road]]
            err = [abs(d["intervals"].value[name] / d["truth"][name] - 1.0) for d in rows[road]]
            print(
                f"{road:>10} {name:>9} | {100 * np.mean(cov):>7.0f}% {100 * np.median(hw):>6.2f}% {100 * max(hw):>7.2f}% "
                f"| {100 * np.median(err):>6.2f}% {100 * max(err):>8.2f}%"
            )
        held = [d["held_out"] for d in rows[road]]
        print(
            f"{road:>10} held-out NRMSE against the true plant (worst run of each damper, the same held-out "
            f"records): median {100 * np.median(held):.2f} %, worst {100 * max(held):.2f} %"
        )
    for f, c, a in zip(folders, rows["commanded"], rows["applied"], strict=True):
        cells = "  ".join(
            f"{n} {100 * c['intervals'].half_width(n):.1f}->{100 * a['intervals'].half_width(n):.1f}%"
            f"{'' if a['intervals'].covers(n, a['truth'][n]) else ' (missed)'}"
            for n in LAB
        )
        print(
            f"  {f.name}: half-widths commanded->applied: {cells}; held-out {100 * c['held_out']:.2f}->{100 * a['held_out']:.2f} %"
        )
    judged = [
        (f, road_against_truth(f, base / f"{f.name}.truth.csv"))
        for f in folders
        if (base / f"{f.name}.truth.csv").exists()
    ]
    runs = [r for _, rs in judged for r in rs if "applied" in r]
    if runs:
        print(
            f"the road against the emulated wheel's true angle, {len(runs)} road runs [counts, each error about its mean; "
            "bias: the applied road's mean error]"
        )
        for label in ("commanded", "applied"):
            rms = [r[label]["rms"] for r in runs]
            worst = [r[label]["worst"] for r in runs]
            bias = [r[label]["bias"] for r in runs]
            print(
                f"{label:>10}: RMS median {np.median(rms):.3f}, worst {max(rms):.3f}; largest error {max(worst):.3f}"
                + (
                    f"; bias median {np.median(bias):+.3f}, worst {max(bias, key=abs):+.3f}"
                    if label == "applied"
                    else ""
                )
            )
    print_held_away(folders)
    lost = [samples_lost(f) for f in folders]
    every = [x for runs in lost for x in runs]
    if every:
        print(
            f"samples lost on the link per run: median {100 * np.median(every):.2f} %, worst {100 * max(every):.2f} % "
            f"({len(every)} runs); per calibration worst: "
            + ", ".join(f"{f.name} {100 * max(runs, default=0.0):.2f} %" for f, runs in zip(folders, lost, strict=True))
        )
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


def report_serial(rows: list[dict], transport: str) -> None:
    """Coverage of params.yaml's intervals_95 over ``transport``; the old +-1.96 sigma x inflation where
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
    print_held_away([case["folder"] for case in rows])
    fits = [case["params_doc"]["calibration"]["fit_s"] for case in rows]
    print(
        f"{len(rows)} calibrations over {transport}; fit {np.median(fits):.1f} s median, {max(fits):.1f} s worst; "
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
        choices=("sim", "serial", "slcan"),
        default="sim",
        help="sim: the simulated rig (virtual clock); serial, slcan: the emulated damper over that link "
        "(wall clock, one at a time)",
    )
    parser.add_argument("--board", choices=BOARDS, default="auto", help="the emulator's board on a link (default auto)")
    parser.add_argument("--keep", type=Path, help="on a link: keep each calibration folder here")
    parser.add_argument(
        "--reanalyse",
        type=Path,
        metavar="DIR",
        help="fit the calibrations kept in DIR again: the road commanded, then applied",
    )
    parser.add_argument("--quick", action="store_true", help="one damper, one seed, a 1 s-drop plan (seconds)")
    args = parser.parse_args()
    if args.reanalyse is not None:
        report_reanalysis(args.reanalyse, args.jobs)
        return
    count, seeds = (1, [0]) if args.quick else (args.dampers, [int(s) for s in args.noise_seeds.split(",")])
    truths = dampers(count, args.damper_seed)
    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
    if args.transport != "sim":
        with tempfile.TemporaryDirectory(prefix="bench-intervals-") as tmp:
            where = args.keep or Path(tmp)
            where.mkdir(parents=True, exist_ok=True)
            rows = []
            for d, truth in enumerate(truths):
                print(f".. {time.strftime('%H:%M:%S')} damper {d} over {args.transport}", flush=True)
                (where / f"d{d}.truth.json").write_text(json.dumps(truth))
                plan = QUICK_PLAN if args.quick else None
                truth_csv = str(where / f"d{d}.truth.csv") if args.keep else None
                try:
                    rows.append(
                        serial_case((truth, 0, plan, str(where / f"d{d}"), args.transport, args.board, truth_csv))
                    )
                except SashilError as err:  # a lossy run on a loaded host: counted apart, no interval to judge
                    print(f"calibration failed (left out): damper {d}: {err}", flush=True)
        if not rows:
            raise SystemExit(f"no calibration over {args.transport} finished")
        print(
            f"sashil calibrate over {args.transport} against the emulated damper ({args.board} board): {count} dampers "
            f"(generator seed {args.damper_seed})"
        )
        report_serial(rows, args.transport)
        return
    with tempfile.TemporaryDirectory(prefix="bench-intervals-") as tmp:
        rows = cases(truths, seeds, QUICK_PLAN if args.quick else None, Path(tmp), args.cache, args.jobs)
    print(
        f"sashil calibrate on the simulated rig, {'the --quick plan' if args.quick else 'the default plan'}: "
        f"{count} dampers (generator seed {args.damper_seed}) x noise seeds {seeds}"
    )
    report(rows, QUICK_PLAN["interval_block_s"] if args.quick else args.block_s)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_intervals", main)

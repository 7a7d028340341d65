#!/usr/bin/env python3
"""The truth chain: identify each damper of a spread, then track torque on the identified model.

For every damper of :data:`truth_chain_sim.DAMPERS` (the seed and four others: n 0.1-0.6, yield
torque at 1 A 0.2-2.5 N m, J 0.8-1.2):

1. identify the Bouc-Wen model from two simulated 10 s drop tests from -5 deg at 0 A and 1 A
   (4096-count encoder, 1 kHz, J given) with ``sashil identify``'s fit (``fit_model``);
2. run the torque-tracking law (T* a band-limited random 0.1-0.9 fraction of the feasible band) on
   the simulated rig (the true damper) over the condition set of :mod:`truth_chain_sim` — a drop
   from -5 deg, the road sine at 1.2 Hz, a chirp 0.5-5 Hz, sines at 1, 2 and 3 Hz (road 1 deg) —
   with the controller on the identified model (and, for reference, on the exact one), 4096-count
   encoders and 16-bit (65536-count) encoders;
3. (``--link``) the 1.2 Hz sine over the serial link: ``sashil emulate`` with the true damper, the
   host running ``sashil sweep --controller torque-tracking --f-start 1.2 --f-stop 1.2 --params
   identified.yaml`` over pyserial; the host's data.csv joined with the emulator's ``--truth`` on
   ``seq``.

Rows per damper: the controller on the exact model; on the identified model (4096 counts/rev, also
with two 34 ms host stalls as this shared machine makes over the link, and 65536 counts/rev); on a
model 10 % off in every parameter (a stress case); each with the encoders' edge times fused
(``controller.edge_timing``, the default) and, beside it, without them (the counts alone); the Kalman
filter's cell reading of a count (an option of the counts-alone filter); and the previous controller
as the baseline.

Printed per damper and condition: tracking NRMSE = RMS(T_true,k+1 - T*_k)/RMS(T*_k) [%], the same
RMS as a fraction of the torque authority T(i_max) - T(0) [%], observer NRMSE = RMS(T_hat - T_true) /
RMS(T_true) [%]; the worst and the median over the spread; the previous controller (fixed-bandwidth
tracking filters, the "0 A when T*·v <= 0" inverse) from the same run as the baseline; the static
resolution k*q/sqrt(12) / RMS(T*) of each run (one count of the relative angle as spring torque,
quantisation taken as noise, over the torque asked for); the median compute time of one controller
cycle (Kalman with and without edge events, tracking filters).

    .venv/bin/python tools/bench_truth_chain.py [--link] [--calibrate] [--dampers seed,A,...] [--quick]

``--calibrate`` calibrates each damper with ``sashil calibrate`` over serial (the emulator playing the
operator) instead of fitting two simulated drops. Wall time: about 6 min in-process (2 cores,
shared), plus about 3 min with --link, plus about 3 min per damper with --calibrate.

``--quick``: the seed damper only (unless --dampers), identified from two 2 s drops with a tiny fit
budget, every condition cut to about 1 s (``truth_chain_sim.quick_conditions``) with one host stall
inside it: seconds; the figures mean little.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from truth_chain_sim import (
    CONDITIONS,
    DAMPERS,
    Condition,
    damper_config,
    figures,
    mismatched,
    quick_conditions,
    run_condition,
)

from sashil.identify.data import record_from_columns
from sashil.identify.fit import FitOptions, fit_model, initial_angle_tolerance
from sashil.identify.synthetic import drop_test_columns
from sashil.models.hysteresis import BoucWenParams

BASELINE = {"estimator": "tracking", "inverse": "rule", "edge_timing": False}
EDGES_OFF = {"edge_timing": False}
STALLS = (4.0, 6.6)  # two host stalls of truth_chain_sim.STALL_S (34 ms), as seen over the link here
QUICK_STALLS = (0.6,)  # one stall inside the cut conditions of --quick


def identify(true: dict[str, float], quick: bool = False) -> tuple[dict[str, float], float]:
    """Bouc-Wen parameters fitted to drop tests at 0 A and 1 A of the damper ``true`` (J given);
    ``quick``: 2 s drops and a tiny fit budget."""
    params = BoucWenParams.from_mapping(true)
    seconds = 2.0 if quick else 10.0
    records = [record_from_columns(f"drop {i:g} A", drop_test_columns(params, -5.0, i, seconds)) for i in (0.0, 1.0)]
    tolerance = initial_angle_tolerance(records)  # as sashil identify does
    options = FitOptions(J=true["J"], initial_angle_tolerance_rad=tolerance)
    if quick:
        options = FitOptions(
            J=true["J"], design=16, starts=2, refine=1, probe_nfev=3, max_nfev=5, initial_angle_tolerance_rad=tolerance
        )
    started = time.perf_counter()
    result = fit_model("bouc-wen", records, options)
    return dict(result.params), time.perf_counter() - started


def calibrate_over_serial(name: str, true: dict[str, float], tmp: Path) -> tuple[dict[str, float], float]:
    """``sashil calibrate`` against ``sashil emulate`` with the damper ``true`` over serial (J given)."""
    import yaml

    from sashil.lab.calibration.emulated import calibrate_emulated

    started = time.perf_counter()
    for attempt in (1, 2):  # a shared machine's stall can end a link run: one retry, reported
        try:
            path = calibrate_emulated(
                damper_config(true, 4096), tmp / f"{name.split()[0]}-cal{attempt}", inertia=true["J"]
            )
            break
        except Exception as err:
            print(f"  calibration attempt {attempt} failed: {err}")
            if attempt == 2:
                raise
    return dict(yaml.safe_load(path.read_text())["params"]), time.perf_counter() - started


def condition_table(
    model: dict[str, float],
    true: dict[str, float],
    counts: int,
    stalls: tuple[float, ...] = (),
    conditions: tuple[Condition, ...] = CONDITIONS,
    **controller,
) -> list[dict]:
    """Figures per condition; also the static resolution k*q/sqrt(12) / RMS(T*) (module docstring)."""
    cfg = damper_config(model, counts, **controller)
    rows = []
    q = 2.0 * math.pi / counts
    for cond in conditions:
        cols = run_condition(cfg, true, cond, stalls_s=stalls)
        row = figures(cols, cond.keep_after_s)
        keep = cols["time_s"] >= cond.keep_after_s
        row["floor"] = true["k"] * q / math.sqrt(12.0) / float(np.sqrt(np.mean(cols["cmd"][keep] ** 2)))
        rows.append(row)
    return rows


def passive_observer(
    model: dict[str, float], true: dict[str, float], counts: int, conditions: tuple[Condition, ...] = CONDITIONS
) -> list[float]:
    """Observer NRMSE at constant 0 A and 1 A on the chirp (both currents)."""
    out = []
    chirp = conditions[2]
    for current in (0.0, 1.0):
        cfg = damper_config(model, counts, current_a=current)
        out.append(figures(run_condition(cfg, true, chirp, law="passive"), chirp.keep_after_s)["observer"])
    return out


def compute_time_us(
    model: dict[str, float], counts: int, conditions: tuple[Condition, ...] = CONDITIONS, **controller
) -> float:
    """Median wall time of one Controller.step over the 1.2 Hz sine [us] (shared machine: noisy)."""
    from sashil.control import registry

    made = []
    original = registry.make_controller

    def timed(*args, **kwargs):
        ctl = original(*args, **kwargs)
        inner = ctl.step
        times = []

        def step(sample, t_ns, dt_ns):
            t0 = time.perf_counter_ns()
            cmd = inner(sample, t_ns, dt_ns)
            times.append(time.perf_counter_ns() - t0)
            return cmd

        ctl.step = step  # type: ignore[method-assign]
        made.append(times)
        return ctl

    import truth_chain_sim

    truth_chain_sim.make_controller = timed
    try:
        run_condition(damper_config(model, counts, **controller), model, conditions[1])
    finally:
        truth_chain_sim.make_controller = original
    return statistics.median(made[0]) / 1000.0


def fmt(rows: list[dict], key: str) -> str:
    return " ".join(f"{100 * r[key]:6.1f}" for r in rows)


def link_sine(name: str, true: dict[str, float], fitted: dict[str, float], tmp: Path) -> dict | None:
    """The 1.2 Hz sine over serial against ``sashil emulate`` with the true damper (module docstring)."""
    import yaml
    from bench_control_link import Bench

    config = damper_config(true, 4096)
    config["driver"].update(sample_timeout_ms=20.0, link_lost_ms=500.0)
    config["controller"]["law"] = "torque-tracking"
    params_path = tmp / f"{name.split()[0]}-params.yaml"  # the identified model, as `identify` writes it
    params_path.write_text(yaml.safe_dump({"model": "bouc-wen", "params": fitted}))
    folder = tmp / name.split()[0]
    folder.mkdir()
    for attempt in (1, 2):  # a shared machine's stall can end a link run: one retry, reported
        result = _link_sine_once(Bench("serial", folder / f"try{attempt}"), config, params_path)
        if result is not None:
            return result
    return None


STALL_MS = 5.0  # a host cycle this much longer than the period is a stall of this shared machine
AFTER_STALL_S = 0.3  # rows within this time after a stall are left out of the "stall-free" figure


def stall_free_tracking(out: Path, truth: dict) -> tuple[float, int]:
    """NRMSE(T_true,k+1 - T*_k) / RMS(T*) without the rows up to AFTER_STALL_S after a host stall,
    and the number of stalls (host period > STALL_MS): the link figure of the estimator, not of the
    machine's pauses."""
    from bench_control_link import KEEP_AFTER_S, join_on_seq

    data = np.genfromtxt(out / "data.csv", delimiter=",", names=True)
    t = data["time_s"]
    index = join_on_seq(data["seq"].astype(np.int64), truth["seq"])
    stalls = t[1:][np.diff(t) > STALL_MS * 1e-3]
    calm = np.ones(t.size, dtype=bool)
    for when in stalls:
        calm &= ~((t >= when - 0.002) & (t <= when + AFTER_STALL_S))
    nxt = index + 1
    pair = (t >= KEEP_AFTER_S) & (index >= 0) & (nxt < truth["torque_true_nm"].size) & calm
    target = data["torque_cmd_nm"][pair]
    err = truth["torque_true_nm"][nxt[pair]] - target
    return float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(target**2))), int(stalls.size)


def _link_sine_once(bench, config: dict, params_path: Path) -> dict | None:
    from bench_control_link import tracking_figures

    bench.tmp.mkdir()
    out, truth = bench.cli(
        config,
        "sweep",
        "--controller",
        "torque-tracking",
        "--f-start",
        "1.2",
        "--f-stop",
        "1.2",
        "--amplitude-deg",
        "1",
        "--duration",
        "12",
        "--params",
        str(params_path),
    )
    if out is None:
        return None
    figures_ = tracking_figures(out, truth)
    figures_["stall_free"], figures_["stalls"] = stall_free_tracking(out, truth)
    return figures_


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--link", action="store_true", help="also the 1.2 Hz sine over the serial link")
    parser.add_argument("--dampers", help="comma-separated name prefixes (default: all)")
    parser.add_argument(
        "--calibrate", action="store_true", help="calibrate each damper with `sashil calibrate` over serial first"
    )
    parser.add_argument(
        "--quick", action="store_true", help="the seed damper, a tiny fit, conditions cut to about 1 s (seconds)"
    )
    args = parser.parse_args()
    dampers = args.dampers or ("seed" if args.quick else None)
    chosen = {k: v for k, v in DAMPERS.items() if not dampers or any(k.startswith(p) for p in dampers.split(","))}
    conditions = quick_conditions() if args.quick else CONDITIONS
    stall_times = QUICK_STALLS if args.quick else STALLS
    names = [c.name for c in conditions]
    print(f"conditions: {', '.join(names)}; road 1 deg; 1 kHz; figures in % (tracking / authority / observer)")
    worst: dict[str, list[tuple[float, str]]] = {}
    sine: dict[str, list[float]] = {}
    timing: list[tuple[float, float]] = []
    links: dict[str, dict | None] = {}
    with tempfile.TemporaryDirectory() as tmp_dir:
        for name, true in chosen.items():
            if args.calibrate:
                fitted, fit_s = calibrate_over_serial(name, true, Path(tmp_dir))
                how = "calibrated over serial (sashil calibrate, J given)"
            else:
                fitted, fit_s = identify(true, args.quick)
                how = "identified from two simulated drops (0 A, 1 A)"
            p_true, p_fit = BoucWenParams.from_mapping(true), BoucWenParams.from_mapping(fitted)
            yield_err = [
                100 * (p_fit.hysteretic_gain(i) * p_fit.z_bound / (p_true.hysteretic_gain(i) * p_true.z_bound) - 1)
                for i in (0.0, 1.0)
            ]
            print(
                f"\n{name}: {how} in {fit_s:.1f} s; yield torque error at 0/1 A {yield_err[0]:+.1f}/{yield_err[1]:+.1f} %, "
                f"c(0)/c(1) {100 * (p_fit.damping(0) / p_true.damping(0) - 1):+.1f}/{100 * (p_fit.damping(1) / p_true.damping(1) - 1):+.1f} %, "
                f"k {100 * (p_fit.k / p_true.k - 1):+.2f} %"
            )
            print(f"  {'':34s} " + " ".join(f"{n[:6]:>6s}" for n in names))
            cell = {"kalman_quantisation": "cell", **EDGES_OFF}
            for label, model, counts, stalls, controller in (
                ("exact model, 4096 counts", true, 4096, (), {}),
                ("exact model, 4096, edges off", true, 4096, (), EDGES_OFF),
                ("identified, 4096 counts", fitted, 4096, (), {}),
                ("identified, 4096, edges off", fitted, 4096, (), EDGES_OFF),
                ("identified, 4096, two host stalls", fitted, 4096, stall_times, {}),
                ("identified, 4096, stalls, edges off", fitted, 4096, stall_times, EDGES_OFF),
                ("identified, 65536 counts", fitted, 65536, (), {}),
                ("model 10 % off, 4096 counts", mismatched(true), 4096, (), {}),
                ("model 10 % off, 4096, edges off", mismatched(true), 4096, (), EDGES_OFF),
                ("cell reading, edges off, 4096", fitted, 4096, (), cell),
                ("baseline (tracking+rule), 4096", fitted, 4096, (), BASELINE),
                ("baseline (tracking+rule), 65536", fitted, 65536, (), BASELINE),
            ):
                rows = condition_table(model, true, counts, stalls, conditions, **controller)
                print(f"  {label:34s} {fmt(rows, 'tracking')}   tracking")
                if label in ("exact model, 4096 counts", "identified, 4096 counts", "identified, 4096, edges off"):
                    print(f"  {'':34s} {fmt(rows, 'authority')}   of authority")
                    print(f"  {'':34s} {fmt(rows, 'observer')}   observer")
                    print(f"  {'':34s} {fmt(rows, 'floor')}   static resolution k*q/sqrt(12)/RMS(T*)")
                for row, cond in zip(rows, names, strict=True):
                    worst.setdefault(label, []).append((row["tracking"], f"{name}, {cond}"))
                    worst.setdefault(label + " observer", []).append((row["observer"], f"{name}, {cond}"))
                    worst.setdefault(label + " floor", []).append((row["floor"], f"{name}, {cond}"))
                sine.setdefault(label, []).append(rows[1]["tracking"])
            obs = passive_observer(fitted, true, 4096, conditions)
            print(
                f"  observer NRMSE on the chirp at constant 0 A / 1 A (identified, 4096): {100 * obs[0]:.1f} / {100 * obs[1]:.1f} %"
            )
            for current, value in zip((0, 1), obs, strict=True):
                worst.setdefault("identified, 4096 counts observer", []).append(
                    (value, f"{name}, chirp at {current} A")
                )
            timing.append(
                (
                    compute_time_us(fitted, 4096, conditions),
                    compute_time_us(fitted, 4096, conditions, **EDGES_OFF),
                    compute_time_us(fitted, 4096, conditions, **BASELINE),
                )
            )
            if args.link:
                r = link_sine(name, true, fitted, Path(tmp_dir))
                links[name] = r
                if r is None:
                    print("  serial link, 1.2 Hz sine: run failed")
                else:
                    print(
                        f"  serial link, 1.2 Hz sine ({how.split()[0]}, 4096): tracking {100 * r['nrmse_rms']:.1f} %, "
                        f"observer {100 * r['observer_nrmse']:.1f} % ({r['joined']} of {r['rows']} rows joined); "
                        f"{r['stalls']} host stalls > {STALL_MS:g} ms, tracking without {AFTER_STALL_S:g} s after "
                        f"each: {100 * r['stall_free']:.1f} %"
                    )
    print("\nover the spread (worst / median) [%]:")
    for label, pairs in worst.items():
        if label.endswith(" floor") and not label.startswith(("exact model, 4096 counts", "identified, 4096 counts")):
            continue
        v = 100 * np.asarray([value for value, _ in pairs])
        where = max(pairs)[1]
        extra = ""
        if label in sine:
            s = 100 * np.asarray(sine[label])
            extra = f";  1.2 Hz sine worst {s.max():.1f}, median {np.median(s):.1f}"
        print(f"  {label:42s} worst {v.max():6.1f} ({where}), median {np.median(v):5.1f}{extra}")
    if links:
        ok = [r for r in links.values() if r]
        if ok:
            whole = [r["nrmse_rms"] for r in ok]
            calm = [r["stall_free"] for r in ok]
            print(
                f"  serial link 1.2 Hz sine tracking: worst {100 * max(whole):.1f}, median {100 * statistics.median(whole):.1f}; "
                f"without the host stalls: worst {100 * max(calm):.1f}, median {100 * statistics.median(calm):.1f} "
                f"({sum(r['stalls'] for r in ok)} stalls in {len(ok)} runs; {len(links) - len(ok)} runs failed)"
            )
    print("\ntargets (identified model, 4096 counts, edge events on; the same with them off):")
    for on, off in (("identified, 4096 counts", "identified, 4096, edges off"),):
        if on not in sine:
            continue
        for tag, label in (("on ", on), ("off", off)):
            s_worst = 100 * max(sine[label])
            whole = 100 * max(v for v, _ in worst[label])
            obs = 100 * max(v for v, _ in worst[label + " observer"])
            print(
                f"  edges {tag}: 1.2 Hz sine worst {s_worst:.1f} % (target <= 10), whole set worst {whole:.1f} % "
                f"(<= 15), observer worst {obs:.1f} % (<= 8)"
            )
    kal = statistics.median(t[0] for t in timing)
    counts_only = statistics.median(t[1] for t in timing)
    base = statistics.median(t[2] for t in timing)
    print(
        f"controller cycle compute, median: Kalman with edge events + band inverse {kal:.1f} us; the counts alone "
        f"{counts_only:.1f} us; baseline tracking filters {base:.1f} us"
    )
    print(f"(measured {time.strftime('%Y-%m-%d %H:%M')} on a shared 2-core machine)")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_truth_chain", main)

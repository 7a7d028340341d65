#!/usr/bin/env python3
"""Controller acceptance figures on the simulated rig with plant mismatch (printed, not asserted).

Mismatch used throughout (config ``mismatch``): every Bouc-Wen parameter of the plant off by 10 %
(sign pattern given by --pattern, default alternate: J+ k- c1+ c2- alpha1+ alpha2- beta+ gamma-
delta+ n-), plant coil lag +10 %, encoder 4096 counts/rev (quantisation). The controller uses the
seed parameters.

    .venv/bin/python tools/bench_control.py [--pattern alternate|plus|minus|random] [--quick]

``--quick`` runs every check on a tiny problem (4 s tracking runs, 2 s drops, 2 sweep frequencies
with 0.5 s settle and measure, a 3 s chirp, 500 timed cycles): seconds; the figures mean little.

Timing numbers are wall-clock on a shared 2-core machine: noisy.
"""

from __future__ import annotations

import argparse
import copy
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.drivers import open_rig, rig_parts
from sashil.drivers.interface import RigCommand
from sashil.engine.resolve import default_config
from sashil.lab._drop_test import run_drop_test
from sashil.lab._sweep import chirp_profile, frequencies, run_profile, sine_profile, stepped_sine
from sashil.runtime.clock import VirtualClock
from sashil.stats import nrmse


def mismatched_config(pattern: str) -> dict:
    config = default_config()
    config["mismatch"].update(fraction=0.10, pattern=pattern, coil_tau=0.10)
    return config


def torque_tracking(config: dict, inverse: str, f_hz: float, amplitude_deg: float, duration_s: float) -> dict:
    """Random T* inside the band while the road shakes the rig; T (true plant) vs T*."""
    cfg = copy.deepcopy(config)
    cfg["controller"]["inverse"] = inverse
    ctl = make_controller("torque-tracking", StageParts.read(cfg))
    cols = run_profile(cfg, ctl, sine_profile(math.radians(amplitude_deg), f_hz, 1.0), duration_s)
    keep = cols["time_s"] >= 3.0
    # the command of cycle k acts over the next period: compare T*_k with the true torque at k+1
    target = cols["torque_cmd_nm"][keep][:-1]
    true = cols["torque_true_nm"][keep][1:]
    err = true - target
    rmse = float(np.sqrt(np.nanmean(err**2)))
    return {
        "nrmse_rms": rmse / float(np.sqrt(np.nanmean(target**2))),
        "nrmse_range": rmse / float(np.nanmax(target) - np.nanmin(target)),
        "observer_nrmse": nrmse(cols["torque_hat_nm"][keep], cols["torque_true_nm"][keep]),
        "clipped": ctl.clip_count,
    }


def drop(config: dict, law: str | None, current_a: float, duration_s: float):
    rig = open_rig(rig_parts(config))
    ctl = make_controller(law, StageParts.read(config)) if law else None
    probe_rows: list[tuple[float, float]] = []
    if ctl is not None:
        inner = ctl.step

        def step(sample, t_ns, dt_ns):  # record T-hat vs the true torque at the same instant
            true = rig.plant.damper_torque()
            cmd = inner(sample, t_ns, dt_ns)
            if not rig.plant.held:
                probe_rows.append((ctl.torque_hat_nm, true))
            return cmd

        ctl.step = step  # type: ignore[method-assign]
    record = run_drop_test(config, -5.0, current_a, duration_s, rig=rig, clock=VirtualClock(), controller=ctl)
    return record, ctl, np.asarray(probe_rows)


def zeta_of(decrement: float) -> float:
    return decrement / math.sqrt(4 * math.pi**2 + decrement**2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pattern", default="alternate", choices=("alternate", "plus", "minus", "random"))
    parser.add_argument("--quick", action="store_true", help="every check on a tiny problem (seconds)")
    parser.add_argument(
        "--estimator", default="kalman", choices=("kalman", "tracking"), help="controller.estimator (default kalman)"
    )
    args = parser.parse_args()
    config = mismatched_config(args.pattern)
    config["controller"]["estimator"] = args.estimator
    if args.quick:
        config["sweep"].update(ramp_s=0.2, settle_s=0.5, measure_s=0.5)
    tracking_s = 4.0 if args.quick else 30.0  # the figures keep t >= 3 s
    drop_s = 2.0 if args.quick else 8.0
    chirp_s = 3.0 if args.quick else 20.0
    print(
        f"plant mismatch: 10 % per parameter, pattern {args.pattern}; coil lag +10 %; 4096 counts/rev; "
        f"estimator {args.estimator}"
    )

    # 1. torque tracking -------------------------------------------------------------------------
    print("\n[1] torque tracking (road 1.2 Hz, 1 deg; T* = band-limited 2 Hz random fraction 0.1-0.9 of the band)")
    for inverse in ("full", "viscous"):
        r = torque_tracking(config, inverse, 1.2, 1.0, tracking_s)
        print(
            f"  {inverse:8s} inverse: NRMSE(T - T*) = {100 * r['nrmse_rms']:.1f} % of RMS(T*), "
            f"{100 * r['nrmse_range']:.1f} % of range(T*); observer NRMSE {100 * r['observer_nrmse']:.1f} %; clipped {r['clipped']}"
        )

    fine = 1 << 24  # an encoder fine enough that quantisation no longer matters
    references = (
        ("no plant mismatch", {"fraction": 0.0, "coil_tau": 0.0}),
        ("65536 counts/rev", {"encoder_counts_per_rev": 65536}),
        ("no plant mismatch, 2^24 counts/rev", {"fraction": 0.0, "coil_tau": 0.0, "encoder_counts_per_rev": fine}),
        (
            "only n off by -10 % (z_u -22 %), 2^24 counts/rev",
            {"fraction": 0.0, "coil_tau": 0.0, "params": {"n": -0.1}, "encoder_counts_per_rev": fine},
        ),
    )
    for label, update in references:
        cfg = copy.deepcopy(config)
        cfg["mismatch"].update(update)
        r = torque_tracking(cfg, "full", 1.2, 1.0, tracking_s)
        print(
            f"  (reference) full inverse, {label}: NRMSE {100 * r['nrmse_rms']:.1f} % of RMS(T*), "
            f"{100 * r['nrmse_range']:.1f} % of range(T*)"
        )

    # 2. target damping drop test ---------------------------------------------------------------
    print("\n[2] drop test from -5 deg: target damping zeta = 0.07 vs constant 0.5 A")
    cfg = copy.deepcopy(config)
    cfg["controller"]["zeta"] = 0.07
    record, ctl, rows = drop(cfg, "target-damping", 0.5, drop_s)
    m = record.metrics
    print("  target-damping peaks [deg]:", " ".join(f"{p:.3f}" for p in m.peaks_deg))
    print(
        "     successive zeta:",
        " ".join(f"{zeta_of(d):.4f}" for d in m.log_decrements),
        f"(within 10 % of 0.07: {all(abs(zeta_of(d) / 0.07 - 1) <= 0.10 for d in m.log_decrements)})",
    )
    print(
        f"     clipped cycles {ctl.clip_count} of {ctl.cycles}; observer NRMSE on the drop: {100 * nrmse(rows[:, 0], rows[:, 1]):.1f} %"
    )
    record05, _, _ = drop(cfg, None, 0.5, drop_s)
    m5 = record05.metrics
    print("  constant 0.5 A peaks [deg]:  ", " ".join(f"{p:.3f}" for p in m5.peaks_deg))
    print("     successive zeta:", " ".join(f"{zeta_of(d):.4f}" for d in m5.log_decrements))

    # 3. stepped sweep --------------------------------------------------------------------------
    steps = 2 if args.quick else 10
    print(
        f"\n[3] stepped sine 0.5-5 Hz ({steps} frequencies, road amplitude {config['sweep']['amplitude_deg']} deg): body RMS [deg]"
    )
    freqs = frequencies(0.5, 5.0, steps)
    laws = [
        ("passive 0 A", "passive", 0.0),
        ("passive 1 A", "passive", 1.0),
        ("skyhook-onoff", "skyhook-onoff", None),
        ("skyhook c=10", "skyhook", None),
        ("skyhook-add 3.5", "skyhook-add", None),
    ]
    table = {}
    for label, name, current in laws:
        cfg = copy.deepcopy(config)
        if current is not None:
            cfg["controller"]["current_a"] = current
        cfg["controller"].update(c_sky=10.0, crossover_hz=3.5)  # tuned on this simulation (see README)
        table[label] = stepped_sine(cfg, lambda cfg=cfg, name=name: make_controller(name, StageParts.read(cfg)), freqs)
    print("  f [Hz]  " + "".join(f"{label:>15s}" for label, _, _ in laws) + "   best/min(passive)")
    for index, f in enumerate(freqs):
        best_passive = min(table["passive 0 A"][index].body_rms_rad, table["passive 1 A"][index].body_rms_rad)
        ratios = {label: table[label][index].body_rms_rad / best_passive for label, _, _ in laws[2:]}
        print(
            f"  {f:6.2f}  "
            + "".join(f"{math.degrees(table[label][index].body_rms_rad):15.4f}" for label, _, _ in laws)
            + "   "
            + " ".join(f"{k}={v:.3f}" for k, v in ratios.items())
        )
    print(
        "  integrated RMS over the frequencies [deg]: "
        + ", ".join(
            f"{label} {math.degrees(math.sqrt(statistics.fmean(p.body_rms_rad**2 for p in table[label]))):.4f}"
            for label, _, _ in laws
        )
    )
    for label, _, _ in laws[2:]:
        worst = max(
            table[label][i].body_rms_rad
            / min(table["passive 0 A"][i].body_rms_rad, table["passive 1 A"][i].body_rms_rad)
            for i in range(len(freqs))
        )
        print(f"  {label}: worst ratio to min(passive 0 A, 1 A) = {worst:.3f} (acceptance <= 1.03)")

    # 4. observer on a chirp --------------------------------------------------------------------
    cfg = copy.deepcopy(config)
    ctl = make_controller("skyhook-add", StageParts.read(cfg))
    cols = run_profile(cfg, ctl, chirp_profile(math.radians(0.5), 0.5, 5.0, chirp_s), chirp_s)
    keep = cols["time_s"] >= 2.0
    print(
        f"\n[4] observer T-hat vs true plant torque on a 0.5-5 Hz chirp (skyhook-add): NRMSE "
        f"{100 * nrmse(cols['torque_hat_nm'][keep], cols['torque_true_nm'][keep]):.1f} %"
    )

    # 5. cycle time -----------------------------------------------------------------------------
    print("\n[5] one controller cycle (estimator + observer + law + inverse + lead + safety clamp), wall clock")
    rig = open_rig(rig_parts(config))
    road = chirp_profile(math.radians(1.0), 0.5, 5.0, 10.0)
    rig.configure()
    rig.activate()
    samples = []
    for k in range(1, 501 if args.quick else 5001):  # the road wheel follows the chirp's speed
        samples.append(rig.read(k * 1_000_000, 1_000_000))
        rig.write(RigCommand(0.0, road(k * 1e-3)[1]), k * 1_000_000, 1_000_000)
    for name in ("target-damping", "skyhook-add", "torque-tracking"):
        cfg = copy.deepcopy(config)
        cfg["controller"]["zeta"] = 0.07
        ctl = make_controller(name, StageParts.read(cfg))
        times = []
        perf = time.perf_counter_ns
        for k, sample in enumerate(samples):
            t0 = perf()
            ctl.step(sample, (k + 1) * 1_000_000, 1_000_000)
            times.append(perf() - t0)
        times.sort()
        print(
            f"  {name:16s} median {times[len(times) // 2] / 1000:.1f} us, p99 {times[int(0.99 * len(times))] / 1000:.1f} us, "
            f"max {times[-1] / 1000:.1f} us"
        )


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_control", main)

#!/usr/bin/env python3
"""Benchmark of the simulated rig.

Prints:
- a simulated 10 s drop test (hold + release + 10 s record, sim backend on the virtual clock,
  through the same loop, plan and driver interface as a real run; no file writing) as a multiple of
  real time: wall time and CPU time, best and median of several repetitions;
- the damper model's real-time step (BoucWenZ.advance over one 1 kHz sample's angle increment of a
  recorded drop test, plus the torque), median / p99 / max per sample.

Goals: drop test >= 200x real time; damper step <= 20 us median.

    .venv/bin/python tools/bench_sim.py [--repeats 6] [--quick]

``--quick``: one repetition of a 1 s drop test (seconds; the figures mean little at that size).
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time

from sashil.config import default_config
from sashil.experiments.drop_test import run_drop_test
from sashil.models.hysteresis import BoucWenParams, BoucWenZ


def bench_drop_test(repeats: int, record_s: float = 10.0) -> None:
    config = default_config()
    run_drop_test(config, -5.0, 0.0, 1.0)  # warm-up (imports, caches)
    wall_ratios, cpu_ratios = [], []
    for repeat in range(repeats):
        current = 1.0 if repeat % 2 else 0.0
        wall0, cpu0 = time.perf_counter(), time.process_time()
        record = run_drop_test(config, -5.0, current, record_s)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        simulated = record.loop.cycles / config["loop"]["rate_hz"]
        wall_ratios.append(simulated / wall)
        cpu_ratios.append(simulated / cpu)
    print(
        f"simulated drop test: {simulated:.2f} s of rig time per run ({record_s:g} s record + hold), {repeats} runs at 0 A / 1 A"
    )
    print(
        f"  speed (wall): best {max(wall_ratios):7.0f}x  median {statistics.median(wall_ratios):7.0f}x real time   [goal >= 200x]"
    )
    print(f"  speed (CPU):  best {max(cpu_ratios):7.0f}x  median {statistics.median(cpu_ratios):7.0f}x real time")


def bench_damper_step(record_s: float = 10.0) -> None:
    params = BoucWenParams()
    config = default_config()
    record = run_drop_test(config, -5.0, 0.0, record_s)
    angles = record.columns["theta_rad"].tolist()
    currents = record.columns["current_a"].tolist()
    increments = [b - a for a, b in itertools.pairwise(angles)]
    law = BoucWenZ.from_params(params)
    torque = params.torque
    clock = time.perf_counter_ns
    # timer overhead, to subtract
    overhead = []
    for _ in range(len(increments)):
        t0 = clock()
        overhead.append(clock() - t0)
    base = statistics.median(overhead)
    samples = []
    for _ in range(3):
        z = 0.0
        for dtheta, current in zip(increments, currents[1:], strict=True):  # the current at the end of each step
            t0 = clock()
            z = law.advance(z, dtheta)
            torque(z, dtheta * 1000.0, current)
            samples.append(clock() - t0 - base)
    samples.sort()
    n = len(samples)
    print(f"damper model step (z over one 1 kHz sample of a drop test + torque), {n} samples:")
    print(
        f"  median {samples[n // 2] / 1000:.2f} us   p99 {samples[int(n * 0.99)] / 1000:.2f} us   "
        f"max {samples[-1] / 1000:.1f} us   [goal median <= 20 us]"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=6)
    parser.add_argument("--quick", action="store_true", help="one repetition of a 1 s drop test (seconds)")
    args = parser.parse_args()
    record_s = 1.0 if args.quick else 10.0
    bench_drop_test(1 if args.quick else args.repeats, record_s)
    bench_damper_step(record_s)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Benchmark of the law API's cost: a plain-Python law loaded from a file against the built-in
skyhook, in the same process, the same controller and the same samples.

Two controllers (estimator, observer, inverse, coil lead: everything but the law is the same
code) are stepped alternately on one recorded sequence of samples from the simulated rig under a
road sine, so both see the same machine state. The figure is the added time per cycle of the
plug-in law (its call through :class:`~sashil.control.law_api.LawState`, the output check) over
the built-in: median and p99 of the per-cycle difference, with each controller's own median and
p99 as the baseline. Targets: <= 15 us median, <= 40 us p99 added.

    python tools/bench_law_api.py            # 60 000 cycles each
    python tools/bench_law_api.py --quick    # 2 000 cycles (seconds; the code path only)
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.drivers import rig_parts
from sashil.drivers.interface import RigCommand
from sashil.drivers.sim import SimulatedRig
from sashil.engine.resolve import default_config
from sashil.roads.option import RoadParts, parse_road
from sashil.runtime.warmup import warm_kernels

#: a plain-Python skyhook of about ten lines, as a lab would write it (no numba)
PLAIN_LAW = '''
from sashil.control import Law, Param


class PlainSkyhook(Law):
    """T* = c_sky * theta2_dot, a lab's first law."""

    name = "plain-skyhook"
    c_sky = Param(2.0, unit="N m s/rad", low=0.0, doc="sky damping")

    def torque(self, state):
        return self.c_sky * state.body_dot_rad_s
'''


def record_samples(cycles: int) -> list:
    """The samples of ``cycles`` cycles of the simulated rig at 1 kHz under a 1.6 Hz road sine."""
    config = default_config()
    road, _ = parse_road("sine:1.6:1.0", RoadParts.read(config))
    assert road is not None
    rig = SimulatedRig.from_parts(rig_parts(config, "sim"))
    rig.configure()
    rig.activate()
    samples = []
    for k in range(cycles):
        t = k * 1_000_000
        samples.append(rig.read(t, 1_000_000))
        rig.write(RigCommand(0.5, road(k * 1e-3)[1]), t, 1_000_000)  # the road wheel follows the sine
    rig.deactivate()
    rig.close()
    return samples


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=60_000)
    parser.add_argument("--quick", action="store_true", help="2 000 cycles: the code path, not a measurement")
    args = parser.parse_args()
    cycles = 2_000 if args.quick else args.cycles
    warm_kernels()
    samples = record_samples(cycles)
    with tempfile.TemporaryDirectory() as tmp:
        law_file = Path(tmp) / "plain_skyhook.py"
        law_file.write_text(textwrap.dedent(PLAIN_LAW))
        config = default_config()
        config["controller"]["c_sky"] = 2.0
        built_in = make_controller("skyhook", StageParts.read(config))
        plug_in = make_controller(f"{law_file}:PlainSkyhook", StageParts.read(config))
        t_built, t_plug = np.empty(cycles, np.int64), np.empty(cycles, np.int64)
        clock = time.perf_counter_ns
        gc.disable()
        try:
            for k, sample in enumerate(samples):
                t = k * 1_000_000
                # alternate which runs first, so neither always meets a warm cache
                (first, t_first), (second, t_second) = (
                    ((plug_in, t_plug), (built_in, t_built)) if k & 1 else ((built_in, t_built), (plug_in, t_plug))
                )
                a = clock()
                first.step(sample, t, 1_000_000)
                b = clock()
                second.step(sample, t, 1_000_000)
                t_first[k], t_second[k] = b - a, clock() - b
        finally:
            gc.enable()
    assert built_in.current_cmd_a == plug_in.current_cmd_a  # the same law, so the same command
    skip = min(1000, cycles // 4)  # the first cycles settle the estimator and warm the caches
    built_us, plug_us = t_built[skip:] / 1e3, t_plug[skip:] / 1e3
    added = plug_us - built_us
    print(f"law API cost over {cycles - skip} cycles at 1 kHz (simulated rig, 1.6 Hz road sine, same samples)")
    print(
        f"  built-in skyhook controller cycle:  median {np.median(built_us):6.2f} us   p99 {np.percentile(built_us, 99):6.2f} us"
    )
    print(
        f"  plain-Python law controller cycle:  median {np.median(plug_us):6.2f} us   p99 {np.percentile(plug_us, 99):6.2f} us"
    )
    med, p99 = float(np.median(added)), float(np.percentile(added, 99))
    print(f"  added by the plug-in law:           median {med:6.2f} us   p99 {p99:6.2f} us   (targets <= 15 / <= 40)")
    if args.quick:
        print("  (--quick: too few cycles for a measurement)")
        return 0
    return 0 if med <= 15.0 and p99 <= 40.0 else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_law_api", main))

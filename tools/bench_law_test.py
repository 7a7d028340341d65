#!/usr/bin/env python3
"""Benchmark of a lab's law test on sashil.testing: 10 s of rig time through ``SimRig.run``.

What a lab's test of its law costs (docs/how-to/test-your-law-in-ci.md): the skyhook law on an
ISO 8608 class C road for 10 s of rig time on the simulated rig on the virtual clock, with the
fixture's seeded noise, into a run folder that ``sashil.load_run`` reads. It prints the one-off
warm-up a test session pays (``sashil.testing.rig.warm_up``: scipy's signal tools, numba's kernels),
then the wall and CPU time of each run (best and median of five). CPU time is what the run costs an
idle core; on a shared machine the wall time is longer by the others' share. Goal: <= 1 s a run.

    python tools/bench_law_test.py            # 10 s of rig time, five runs
    python tools/bench_law_test.py --quick    # 2.5 s, one run (seconds; the code path only)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from sashil.testing.rig import SimRig, warm_up


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2.5 s of rig time, one run")
    args = parser.parse_args()
    duration, runs = (2.5, 1) if args.quick else (10.0, 5)
    start = time.perf_counter()
    warm_up()
    print(f"warm-up (once per test session): {time.perf_counter() - start:.2f} s")
    walls, cpus = [], []
    with tempfile.TemporaryDirectory(prefix="bench-law-test-") as folder:
        rig = SimRig(out=Path(folder))
        for _ in range(runs):
            wall, cpu = time.perf_counter(), time.process_time()
            run = rig.run("skyhook", road="iso8608:C", duration_s=duration, c_sky=2.0)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
            assert run.summary["exit_status"] == "ok", run.summary
    print(
        f"{duration:g} s of rig time, {runs} run(s): wall best {min(walls):.3f} s, median {statistics.median(walls):.3f} s; "
        f"CPU best {min(cpus):.3f} s, median {statistics.median(cpus):.3f} s "
        f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_law_test", main)

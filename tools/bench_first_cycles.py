#!/usr/bin/env python3
"""Benchmark of a real-time run's first cycles: is the first second on time once the warm-up ran?

Runs ``sashil run --controller skyhook --duration 2`` on the real clock (the simulated rig, so no
hardware) as a user would, and reads the lateness of every cycle of its first second back from the
run's data.csv (each row's ``time_s`` is the cycle's measured wake-up; its deadline follows the
loop's own rule: one period after the last, whole missed periods skipped). Beside it, in the same
minute, the bare loop: a Python loop that only sleeps to the same 1 kHz deadlines with the same
clock (sleep, then spin ``loop.spin_margin_us``) for one second, run just before and just after;
its worst cycle is the floor this machine gives any loop at that moment.

Then each built-in law (``sashil laws``; required parameters set to 1) runs the same way with
``--set loop.overrun_policy=fail``: a run passes when it exits 0 (no deadline missed by a whole
period, the first cycle included).

    .venv/bin/python tools/bench_first_cycles.py [--duration 2] [--quick]

``--quick``: skyhook alone for 0.5 s, and only it under ``overrun_policy=fail`` (seconds). The
machine may be shared: a busy neighbour delays the bare loop and the run alike, so read the two
together.
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sashil.engine.resolve import default_config
from sashil.runtime.clock import RealClock

SASHIL = [sys.executable, "-m", "sashil"]


def bare_loop_worst_us(seconds: float, rate_hz: float, spin_margin_us: float) -> float:
    """The worst lateness [us] of a bare loop sleeping to absolute deadlines for ``seconds``."""
    clock = RealClock.for_rate(spin_margin_us, rate_hz)
    period = round(1e9 / rate_hz)
    worst = 0
    deadline = clock.now_ns()
    for _ in range(round(seconds * rate_hz)):
        clock.sleep_until(deadline)
        late = clock.now_ns() - deadline
        worst = max(worst, late)
        if late >= period:
            deadline += (late // period) * period
        deadline += period
    return worst / 1000


def first_second_lateness_us(data_csv: Path, rate_hz: float) -> tuple[float, int]:
    """(worst lateness [us], cycles) of the first second of a run, from its data.csv wake-up times."""
    period = 1.0 / rate_hz
    with data_csv.open(newline="") as handle:
        times = [float(row["time_s"]) for row in csv.DictReader(handle)]
    times = times[:-1]  # the last row is the shutdown's safe-state row, dated one period on
    worst, deadline, cycles = 0.0, 0.0, 0
    for t in times:
        if t >= 1.0:
            break
        late = t - deadline
        worst = max(worst, late)
        if late >= period:
            deadline += (late // period) * period
        deadline += period
        cycles += 1
    return worst * 1e6, cycles


def required_parameters() -> dict[str, list[str]]:
    """Each built-in law listed by ``sashil laws``, with the parameters it requires."""
    text = subprocess.run([*SASHIL, "laws"], capture_output=True, text=True, check=True).stdout
    laws: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        head = re.match(r"^(\S+)\s+\((\w+); built-in:", line)
        if head:
            current = head.group(1)
            laws[current] = []
        elif not line.startswith(" "):
            current = None  # a plug-in law: not built in
        elif current is not None:
            param = re.match(r"^\s+controller\.(\w+)\b.*= required", line)
            if param:
                laws[current].append(param.group(1))
    return laws


#: laws that need one of two parameters (neither is marked required on its own): the one set here
ONE_OF = {"target-damping": ["zeta"]}


def run(law: str, params: list[str], duration: float, out: Path, fail: bool) -> subprocess.CompletedProcess:
    argv = [*SASHIL, "run", "--controller", law, "--duration", f"{duration:g}", "--out", str(out), "-q"]
    for name in params or ONE_OF.get(law, []):
        argv += ["--set", f"controller.{name}={0.05 if name == 'zeta' else 1.0}"]
    if fail:
        argv += ["--set", "loop.overrun_policy=fail"]
    return subprocess.run(argv, capture_output=True, text=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--quick", action="store_true", help="skyhook alone, 0.5 s (seconds)")
    args = parser.parse_args()
    duration = 0.5 if args.quick else args.duration
    loop = default_config()["loop"]
    rate, spin = loop["rate_hz"], loop["spin_margin_us"]
    laws = required_parameters()
    with tempfile.TemporaryDirectory(prefix="sashil-first-cycles-") as tmp:
        bare_before = bare_loop_worst_us(min(1.0, duration), rate, spin)
        start = time.perf_counter()
        done = run("skyhook", laws.get("skyhook", ["c_sky"]), duration, Path(tmp) / "skyhook", fail=False)
        wall = time.perf_counter() - start
        bare_after = bare_loop_worst_us(min(1.0, duration), rate, spin)
        if done.returncode != 0:
            print(f"sashil run --controller skyhook failed (exit {done.returncode}): {done.stderr.strip()}")
            sys.exit(1)
        worst, cycles = first_second_lateness_us(Path(tmp) / "skyhook" / "data.csv", rate)
        print(
            f"sashil run --controller skyhook --duration {duration:g} (sim rig, real clock, {rate:g} Hz; "
            f"{wall:.1f} s wall with start-up and warm-up; load average {os.getloadavg()[0]:.1f} on "
            f"{os.cpu_count()} CPUs):"
        )
        print(f"  first second ({cycles} cycles): worst lateness {worst:9.1f} us")
        print(
            f"  bare loop, same clock, 1 s just before / after: worst {bare_before:9.1f} / {bare_after:.1f} us"
            f"   [goal: the run's first second no later than the bare loop's worst]"
        )
        print(
            f"  first second within the bare loop's worst: {'yes' if worst <= max(bare_before, bare_after) else 'no'}"
        )
        print(f"loop.overrun_policy=fail, {duration:g} s per law (exit 0 = no deadline missed):")
        chosen = {"skyhook": laws.get("skyhook", ["c_sky"])} if args.quick else laws
        for law, params in chosen.items():
            done = run(law, params, duration, Path(tmp) / f"fail-{law}", fail=True)
            verdict = "pass" if done.returncode == 0 else f"FAIL (exit {done.returncode})"
            reason = "" if done.returncode == 0 else "  " + (done.stderr.strip().splitlines() or [""])[-1][:110]
            print(f"  {law:<18s} {verdict}{reason}")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_first_cycles", main)

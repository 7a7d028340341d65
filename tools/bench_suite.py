#!/usr/bin/env python3
"""Benchmark of the test suite as a contributor waits for it: the README's test command, timed.

Runs the two tiers of the README quick start's second command (the tests on every core with
pytest-xdist, then the ``alone`` tests one at a time) in this checkout's ``.venv`` and prints:

- the wall time of each tier and of the whole command, and the CPU time (user + sys) of every
  process the command waited for;
- beside them, the baseline from the same run: the floor the tests' own durations set (the
  parallel tier's durations summed over its workers, plus the alone tier's), which no scheduling
  can beat without shorter tests;
- the slowest tests (``--durations``), and the outcome counts (a failure fails the benchmark).

``--busy`` keeps one core busy beside the command (a process spinning in Python), as a loaded CI
host would: the suite must pass beside it.

    .venv/bin/python tools/bench_suite.py [--busy] [--slowest 25] [--quick]

``--quick``: the same two tiers on one small test file (seconds; the figures mean little).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = str(ROOT / ".venv" / "bin" / "python") if (ROOT / ".venv" / "bin" / "python").exists() else sys.executable
#: the README's two tiers: (name, pytest arguments)
TIERS = (
    ("parallel", ["-m", "not alone", "-n", "auto", "--dist", "loadscope"]),
    ("alone", ["-m", "alone"]),
)
#: --quick: one small file (the alone tier finds no test in it: pytest's exit 5)
QUICK_FILES = ["tests/test_serial_codec.py"]


def _durations(junit: Path) -> list[tuple[float, str]]:
    root = ET.parse(junit).getroot()
    return [
        (float(case.get("time") or 0.0), f"{case.get('classname')}::{case.get('name')}")
        for case in root.iter("testcase")
    ]


def _failures(junit: Path) -> list[str]:
    """Each failed or erred test with the first line of its message."""
    out = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        for outcome in (*case.iter("failure"), *case.iter("error")):
            message = (outcome.get("message") or "").strip().splitlines()[:1] or [""]
            out.append(f"{case.get('classname')}::{case.get('name')}: {message[0][:300]}")
    return out


def _workers(args: list[str]) -> int:
    """The workers a tier runs on: pytest-xdist's ``-n auto`` is one per CPU this process may use."""
    if "-n" not in args:
        return 1
    count = args[args.index("-n") + 1]
    return len(os.sched_getaffinity(0)) if count == "auto" else int(count)


def run_tier(name: str, args: list[str], files: list[str], out: Path) -> dict:
    junit = out / f"{name}.xml"
    started = time.perf_counter()
    done = subprocess.run(
        [PYTHON, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={junit}", *args, *files],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - started
    tail = done.stdout.strip().splitlines()[-1:] or [""]
    return {
        "name": name,
        "wall_s": wall,
        "code": done.returncode,
        "summary": tail[0],
        "durations": _durations(junit) if junit.exists() else [],
        "failures": _failures(junit) if junit.exists() else [],
        "workers": _workers(args),
    }


def _cpu_of(pid: int) -> float:
    """The CPU time [s] (user + sys) process ``pid`` has used so far (``/proc/PID/stat``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--busy", action="store_true", help="one core kept busy beside the command")
    parser.add_argument("--slowest", type=int, default=25, metavar="N", help="the N slowest tests (default 25)")
    parser.add_argument("--quick", action="store_true", help="one small test file (seconds)")
    args = parser.parse_args(argv)
    files = QUICK_FILES if args.quick else []
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy else None
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        with tempfile.TemporaryDirectory(prefix="bench-suite-") as tmp:
            tiers = [run_tier(name, tier_args, files, Path(tmp)) for name, tier_args in TIERS]
    finally:
        spun = _cpu_of(spinner.pid) if spinner is not None else 0.0
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    # the spinner's CPU is among the children's too: not the suite's
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime) - spun
    load = os.getloadavg()
    print(f"the README's test command{' beside a busy core' if args.busy else ''} (load average {load[0]:.1f})")
    floor = 0.0
    for tier in tiers:
        summed = sum(d for d, _ in tier["durations"])
        tier_floor = summed / max(tier["workers"], 1)
        floor += tier_floor
        print(
            f"  {tier['name']:9} {tier['wall_s'] / 60:5.1f} min wall; its tests' durations {summed:7.1f} s over "
            f"{tier['workers']} worker(s): floor {tier_floor / 60:.1f} min; {tier['summary']}"
        )
    whole = sum(tier["wall_s"] for tier in tiers)
    print(
        f"  whole     {whole / 60:5.1f} min wall (goal <= 8 min)   baseline: the tests' own floor {floor / 60:.1f} min"
    )
    print(f"  CPU of the command's processes: {cpu:.0f} s (user + sys)")
    slowest = sorted((d for tier in tiers for d in tier["durations"]), reverse=True)[: args.slowest]
    print(f"the {len(slowest)} slowest tests [s]:")
    for seconds, name in slowest:
        print(f"  {seconds:7.2f}  {name}")
    failed = [tier for tier in tiers if tier["code"] not in (0, 5)]
    for tier in failed:
        print(f"{tier['name']} tier failed (exit {tier['code']}): {tier['summary']}", file=sys.stderr)
        for line in tier["failures"]:
            print(f"  FAILED {line}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_suite", main))

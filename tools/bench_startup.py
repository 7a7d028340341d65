#!/usr/bin/env python3
"""Benchmark of what a user waits for before sashil does anything: ``sashil --version``,
``sashil --help``, every ``sashil VERB --help``, and the quick start's job (a simulated drop test
at 0 A and 1 A, its plot and its folder), each as a whole process, median of several runs.

Beside each figure, from the same run:
- the interpreter's floor (``python -c pass``, with this venv's ``site``: the editable install's
  finder included), which no command can beat;
- with ``--baseline REV`` (default: none), the same command from the git revision ``REV`` of this
  checkout (checked out into a temporary worktree and run from its ``src``), so a change is
  measured against what it replaced in the same minutes.

Goals: ``--version`` and each ``VERB --help`` <= 0.2 s; the quick start's job <= 1.0 s.

    .venv/bin/python tools/bench_startup.py [--runs 5] [--baseline b1ff483] [--quick]

``--quick``: one run of ``--version``, ``--help``, ``drop-test --help`` and a 1 s drop test (seconds).
The machine is shared: say what else ran when you quote a figure.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))  # sashil.cli.VERBS from this checkout, not only the installed one

from sashil.cli import VERBS  # noqa: E402

#: runs the sashil command of the tree whose ``src`` is argv[1] (the rest of argv is the command line)
LAUNCH = "import sys; src = sys.argv.pop(1); sys.path.insert(0, src); from sashil.cli import main; sys.exit(main())"


def timed(command: Callable[[], Sequence[str]], cwd: Path, runs: int) -> float:
    """Median wall time [s] of the process ``command()`` gives (anew for each of ``runs`` runs), after
    one untimed run that fills the bytecode and numba caches of a fresh tree."""
    times = []
    for index in range(runs + 1):
        argv = command()
        start = time.perf_counter()
        done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True)
        if index:
            times.append(time.perf_counter() - start)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(argv)}: exit {done.returncode}\n{done.stderr[-2000:]}")
    return statistics.median(times)


@contextlib.contextmanager
def baseline_tree(revision: str | None) -> Iterator[Path | None]:
    """A temporary worktree of ``revision`` (None: no baseline)."""
    if revision is None:
        yield None
        return
    with tempfile.TemporaryDirectory(prefix="sashil-baseline-") as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), revision], cwd=ROOT, check=True)
        try:
            yield tree
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)


def launcher(python: str, tree: Path, out: Path, argv: Sequence[str]) -> Callable[[], list[str]]:
    """The command line of ``sashil ARGV`` from ``tree``, with ``{out}`` a fresh folder each call."""
    counter = iter(range(1_000_000))

    def line() -> list[str]:
        folder = f"{out}-{next(counter)}"
        return [python, "-c", LAUNCH, str(tree / "src"), *(arg.replace("{out}", folder) for arg in argv)]

    return line


def commands(quick: bool, drop_s: float) -> list[tuple[str, list[str], float | None]]:
    """``(label, sashil arguments, goal [s])`` of each figure; ``{out}`` is a fresh folder."""
    verbs = ["drop-test"] if quick else list(VERBS)
    rows: list[tuple[str, list[str], float | None]] = [("--version", ["--version"], 0.2), ("--help", ["--help"], 0.2)]
    rows += [(f"{verb} --help", [verb, "--help"], 0.2) for verb in verbs]
    drop = ["drop-test", "--current", "0", "--current", "1", "--duration", f"{drop_s:g}", "-q", "--out", "{out}"]
    rows.append((f"quick start's job (drop test 0 A and 1 A, {drop_s:g} s)", drop, 1.0 if drop_s == 10 else None))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="runs per command (median)")
    parser.add_argument("--baseline", metavar="REV", help="also time the git revision REV of this checkout")
    parser.add_argument("--quick", action="store_true", help="one run of a few commands (seconds)")
    args = parser.parse_args()
    runs = 1 if args.quick else args.runs
    drop_s = 1.0 if args.quick else 10.0
    python = sys.executable
    env_note = f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start"
    with tempfile.TemporaryDirectory(prefix="sashil-startup-") as tmp, baseline_tree(args.baseline) as base:
        work = Path(tmp)
        floor = timed(lambda: [python, "-c", "pass"], work, runs)
        print(f"sashil start-up, median of {runs} run(s) ({env_note})")
        print(f"  interpreter floor (python -c pass): {floor:.3f} s")
        header = f"  {'command':<48} {'this tree':>10}" + (f" {'baseline':>10}" if base else "") + "  goal"
        print(header)
        for index, (label, argv, goal) in enumerate(commands(args.quick, drop_s)):
            results = []
            for name, tree in (("this", ROOT), ("base", base)):
                if tree is None:
                    continue
                results.append(timed(launcher(python, tree, work / f"{name}-{index}", argv), work, runs))
            cells = " ".join(f"{value:>9.3f}s" for value in results)
            mark = "" if goal is None else f"  <= {goal:g} s {'ok' if results[0] <= goal else 'MISSED'}"
            print(f"  {label:<48} {cells}{mark}")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_startup", main)

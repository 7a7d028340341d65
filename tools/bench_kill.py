#!/usr/bin/env python3
"""Benchmark of a session's death: from ``kill -9`` of ``sashil run`` to the coil at rest.

On the real clock, as a lab runs it: ``sashil run --current A --duration 30`` in a subprocess (the
session), its loop in a loop process forked from the session's loop server. One second into the
loop the session gets SIGKILL; its loop process, alone, must stop at 0 A, read on until the coil's
current has decayed and end the run itself (:mod:`sashil.runtime.orphan`). The baseline is the
same run stopped cleanly: SIGINT to the session, which writes it into the stream's stop word. The
loop runs with the default real-time set-up (``loop.rt``: SCHED_FIFO where the process may), as at
the bench.

Each run is timed on CLOCK_MONOTONIC from the signal: the loop's record (``data.csv``, its
``time_s`` counting from the loop's start, ``summary.json``'s ``loop_process.start_ns``) gives when
the loop commanded 0 A (its first row at 0 A after the signal) and when the coil was at rest (its
first row from then on whose measured current is at most 0.05 A, the loop's own settle bound); the
loop server's and the loop process's ends are polled in /proc. Backends: the simulated rig, and
serial against ``sashil emulate --board c`` (the firmware's C logic, when a C compiler is found),
where the coil's true current comes from the emulator's ``--truth`` log, its device time put on
the host's clock through the samples both hold (joined on ``seq``).

    python tools/bench_kill.py                      # 5 runs of each backend and signal
    python tools/bench_kill.py --runs 3 --save tools/bench_kill.out
    python tools/bench_kill.py --quick              # 1 run each (seconds)
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sashil.drivers.firmware import compiler
from sashil.recording.data_file import read_data_csv

SASHIL = [sys.executable, "-m", "sashil"]
#: the coil's current at rest [A] (the loop's settle bound, sashil.runtime.loop.SAFE_CURRENT_A)
REST_A = 0.05
#: the current the run holds before the signal [A]
CURRENT_A = 0.8
#: how long the loop runs before the signal [s]
BEFORE_S = 1.0
#: the goal: the coil at rest this soon after the session's death [s]
GOAL_S = 0.1
#: how often the ends of the server and the loop are looked for [s]
POLL_S = 0.001


def _children(pid: int) -> list[int]:
    try:
        return [int(child) for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except FileNotFoundError:
        return []


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended and not yet reaped, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


class Emulator:
    """``sashil emulate --transport serial --board c`` with a truth log, for one run."""

    def __init__(self, folder: Path):
        self.link = str(folder / "rig")
        self.truth = folder / "truth.csv"
        self.proc = subprocess.Popen(
            [*SASHIL, "emulate", "--transport", "serial", "--board", "c", "--link", self.link, "--duration", "120",
             "--truth", str(self.truth)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        line = self.proc.stdout.readline()  # type: ignore[union-attr]
        if "rig on /dev/" not in line or "(c board)" not in line:
            self.stop()
            raise RuntimeError(f"sashil emulate did not start: {line}")

    def stop(self) -> dict[str, np.ndarray]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.communicate(timeout=60)
        return read_data_csv(self.truth, required=(), min_rows=0) if self.truth.exists() else {}


def _relaxed(folder: Path) -> str:
    """The link's timeouts and loss budgets relaxed (a loaded machine may starve the emulator): the
    run must last until the signal whatever the machine does."""
    path = folder / "link.yaml"
    path.write_text(
        "driver:\n  sample_timeout_ms: 250.0\n  link_lost_ms: 500.0\n  max_lost_fraction: 1.0\n"
        "loop:\n  max_missed_fraction: 1.0\n"
    )
    return str(path)


def one_run(backend: str, signum: int, folder: Path) -> dict[str, float | None]:
    """One run on ``backend`` ("sim" or "serial-c") ended by ``signum`` to its session: the seconds
    from the signal to 0 A commanded, to the coil at rest (the record's measured current; over
    serial also the emulator's true current), to the loop server's end and to the loop process's."""
    out = folder / "run"
    emulator = Emulator(folder) if backend == "serial-c" else None
    link = ["--driver", "serial", "--port", emulator.link, "--config", _relaxed(folder)] if emulator else []
    session = subprocess.Popen(
        [*SASHIL, "run", "--duration", "30", "--current", str(CURRENT_A), "--out", str(out), "-v", *link],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        for line in session.stderr:  # type: ignore[union-attr]
            if line.startswith("loop: running"):
                break
        else:
            raise RuntimeError(f"the loop never ran (exit {session.wait()})")
        (server,) = _children(session.pid)
        (loop,) = _children(server)
        time.sleep(BEFORE_S)
        signalled = time.monotonic_ns()
        session.send_signal(signum)
        ends: dict[str, int] = {}
        while len(ends) < 2 and time.monotonic_ns() - signalled < 60e9:
            for name, pid in (("server", server), ("loop", loop)):
                if name not in ends and not _running(pid):
                    ends[name] = time.monotonic_ns()
            time.sleep(POLL_S)
        session.wait(timeout=60)
        deadline = time.monotonic() + 30
        while not (out / "summary.json").exists() and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()
        session.stderr.close()  # type: ignore[union-attr]
        truth = emulator.stop() if emulator is not None else {}
    summary = json.loads((out / "summary.json").read_text())
    data = read_data_csv(out / "data.csv", required=(), min_rows=0)
    row_ns = int(summary["loop_process"]["start_ns"]) + np.round(data["time_s"] * 1e9).astype(np.int64)
    after = row_ns >= signalled
    stopped = after & (data["current_cmd_a"] == 0.0)
    first_zero = int(np.argmax(stopped)) if stopped.any() else None
    result: dict[str, float | None] = {
        "zero_s": None if first_zero is None else (row_ns[first_zero] - signalled) * 1e-9,
        "rest_s": _rest_s(row_ns, signalled, first_zero, np.abs(data["current_a"])),
        "server_s": (ends["server"] - signalled) * 1e-9 if "server" in ends else None,
        "loop_s": (ends["loop"] - signalled) * 1e-9 if "loop" in ends else None,
    }
    if truth:
        truth_ns = _on_the_host_s_clock(truth, data["seq"], row_ns)
        above = np.flatnonzero(np.abs(truth["current_true_a"]) > REST_A)
        rest = int(above[-1]) + 1 if above.size else 0
        result["true_rest_s"] = (truth_ns[rest] - signalled) * 1e-9 if rest < len(truth_ns) else None
    return result


def _on_the_host_s_clock(truth: dict[str, np.ndarray], seqs: np.ndarray, row_ns: np.ndarray) -> np.ndarray:
    """The truth log's samples on the host's CLOCK_MONOTONIC [ns]: the board's clock shifted by the
    median of (host row time - device time) over the samples both hold (joined on ``seq``)."""
    device_ns = {int(seq): int(us) * 1000 for seq, us in zip(truth["seq"], truth["device_time_us"], strict=True)}
    shifts = [host - device_ns[int(seq)] for seq, host in zip(seqs, row_ns, strict=True) if int(seq) in device_ns]
    return truth["device_time_us"] * 1000 + np.median(shifts)


def _rest_s(row_ns: np.ndarray, signalled: int, first_zero: int | None, current: np.ndarray) -> float | None:
    """Seconds from the signal to the first row, at 0 A commanded or after, from which on every
    row's ``current`` (NaN: not known) is at most :data:`REST_A`."""
    if first_zero is None:
        return None
    tail = current[first_zero:]
    known = ~np.isnan(tail)
    above = np.flatnonzero(known & (tail > REST_A))
    start = first_zero + (int(above[-1]) + 1 if above.size else 0)
    if start >= len(current):
        return None
    return (int(row_ns[start]) - signalled) * 1e-9


def _line(label: str, values: list[float | None]) -> str:
    known = [value for value in values if value is not None]
    if not known:
        return f"  {label:<26} n/a"
    missing = f" ({len(values) - len(known)} n/a)" if len(known) < len(values) else ""
    text = ", ".join(f"{value * 1000:.0f}" for value in values if value is not None)
    return (
        f"  {label:<26} min {min(known) * 1000:6.1f}  median {statistics.median(known) * 1000:6.1f}  "
        f"max {max(known) * 1000:6.1f} ms   [{text}]{missing}"
    )


def _commit() -> str:
    try:
        done = subprocess.run(
            ["git", "-C", str(Path(__file__).parent), "describe", "--always", "--dirty"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        return done.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="runs of each backend and signal (default 5)")
    parser.add_argument("--quick", action="store_true", help="one run of each (seconds)")
    parser.add_argument("--save", type=Path, metavar="FILE", help="also write the report to FILE")
    parser.add_argument("--backend", choices=("sim", "serial-c"), action="append", help="only these (default both)")
    parser.add_argument("--kill-only", action="store_true", help="no baseline runs")
    args = parser.parse_args(argv)
    runs = 1 if args.quick else args.runs
    backends = [b for b in args.backend or ("sim", "serial-c") if b == "sim" or compiler() is not None]
    ways = (
        (("kill -9", signal.SIGKILL),)
        if args.kill_only
        else (("kill -9", signal.SIGKILL), ("SIGINT (baseline)", signal.SIGINT))
    )
    lines = [
        f"bench_kill: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, commit {_commit()}, "
        f"{os.cpu_count()} CPUs, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (start)",
        f"`sashil run --current {CURRENT_A:g}` on the real clock, the signal to the session {BEFORE_S:g} s into "
        f"the loop; times from the signal, {runs} run(s) each; goal: kill -9 to rest <= {GOAL_S * 1000:.0f} ms",
    ]
    print("\n".join(lines), flush=True)
    for backend in backends:
        for name, signum in ways:
            results = []
            for _ in range(runs):
                with tempfile.TemporaryDirectory(prefix="bench-kill-") as folder:
                    results.append(one_run(backend, signum, Path(folder)))
            block = [f"{backend}, {name}:"]
            block.append(_line("0 A commanded", [r["zero_s"] for r in results]))
            block.append(_line("coil at rest (record)", [r["rest_s"] for r in results]))
            if backend == "serial-c":
                block.append(_line("coil at rest (truth)", [r.get("true_rest_s") for r in results]))
            block.append(_line("loop process ended", [r["loop_s"] for r in results]))
            if signum == signal.SIGKILL:
                block.append(_line("loop server ended", [r["server_s"] for r in results]))
            print("\n".join(block), flush=True)
            lines += block
    if "serial-c" not in backends and compiler() is None:
        lines.append("serial-c: skipped (no C compiler)")
    lines.append(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (end)")
    print(lines[-1])
    if args.save is not None:
        args.save.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_kill", main))

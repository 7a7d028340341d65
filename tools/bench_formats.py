"""Benchmark of the run record formats (prints figures; not a test).

1. Loop overhead: ``sashil run`` at 1 kHz over the emulated rig (SLCAN on a pty, ``sashil
   emulate`` in its own process) for ``--duration`` s each, without ``--format`` and with each
   format; p50/p99/max wake-up lateness and missed deadlines from summary.json. The runs
   alternate (none, parquet, blf, ...) ``--repeat`` times so a drift of the machine's load hits
   every format alike; the median over the repeats is printed.
2. Size: one ``--sizes`` s run (default 60) writing every format at once; the size of each file.

    .venv/bin/python tools/bench_formats.py --duration 20 --repeat 3 --sizes 60
    .venv/bin/python tools/bench_formats.py --quick    # one 0.5 s overhead run (csv), then the size run
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: how the benchmark runs sashil: this interpreter, or the command in the environment variable
#: SASHIL_COMMAND (words split at spaces: another install, or the tests' warm interpreter)
SASHIL = os.environ.get("SASHIL_COMMAND", "").split() or [
    sys.executable,
    "-c",
    "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))",
]
#: the benchmark reports the misses and losses it measures rather than failing on a loss budget
CONFIG = "driver:\n  link_lost_ms: 500.0\n  max_lost_fraction: 1.0\nloop:\n  max_missed_fraction: 1.0\n"


def start_emulator(tmp: Path) -> tuple[subprocess.Popen, str]:
    link = str(tmp / "rig")
    proc = subprocess.Popen(
        [*SASHIL, "emulate", "--transport", "slcan", "--link", link],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    line = proc.stdout.readline() if proc.stdout else ""
    if "rig on /dev/" not in line:
        proc.kill()
        raise SystemExit(f"emulator did not start: {line!r}")
    return proc, link


def run(tmp: Path, link: str, duration: float, formats: list[str], name: str) -> dict:
    out = tmp / name
    cfg = tmp / "bench.yaml"
    cfg.write_text(CONFIG)
    argv = [*SASHIL, "run", "--driver", "can", "--port", link, "--config", str(cfg), "--duration", str(duration)]
    argv += ["--current", "0.3", "--road", "none", "-q", "--out", str(out)]
    for fmt in formats:
        argv += ["--format", fmt]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=duration * 4 + 60)
    if done.returncode != 0:
        raise SystemExit(f"sashil run {formats} failed: {done.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    timing = summary["timing"]
    return {
        "folder": out,
        "p50": timing["lateness_us"]["p50"],
        "p99": timing["lateness_us"]["p99"],
        "max": timing["lateness_us"]["max"],
        "missed": timing["missed_deadlines"],
        "cycles": timing["cycles"],
    }


def frame_costs(n: int = 20000) -> None:
    """What a CAN frame costs: in the cycle (stamp + queue) and in the writer thread (per format)."""
    import time

    import can

    from sashil.recording.can_trace import CanTrace

    frames = [
        can.Message(timestamp=1.7e9 + k * 1e-3, arbitration_id=0x111, data=bytes(8), is_extended_id=False)
        for k in range(n)
    ]
    trace = CanTrace([], interval_s=3600)
    t0 = time.perf_counter()
    for msg in frames:
        msg.timestamp, msg.is_rx = time.time(), False
        trace.put(msg)
    print(f"in the cycle: {(time.perf_counter() - t0) / n * 1e6:.2f} us per frame (stamp + queue)")
    for fmt in ["blf", "asc", "log"] + (["mf4"] if importlib.util.find_spec("asammdf") else []):
        with tempfile.TemporaryDirectory() as name:
            trace = CanTrace([Path(name) / f"can.{fmt}"], interval_s=3600).start()
            for msg in frames:
                trace.put(msg)
            t0 = time.perf_counter()
            trace._drain()
            drain = (time.perf_counter() - t0) / n * 1e6
            t0 = time.perf_counter()
            trace.close()
            after = time.perf_counter() - t0
        print(f"writer thread, {fmt}: {drain:.2f} us per frame; closing {n} frames: {after:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=20.0, help="length of each overhead run [s]")
    parser.add_argument("--repeat", type=int, default=3, help="rounds of the overhead runs")
    parser.add_argument("--sizes", type=float, default=60.0, help="length of the size run [s] (0: skip)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="500 frames; one 0.5 s overhead run without --format; a 0.5 s size run of every format (seconds)",
    )
    args = parser.parse_args()
    if args.quick:
        args.duration, args.repeat, args.sizes = 0.5, 1, 0.5
    frame_costs(500 if args.quick else 20000)
    print()
    traces = ["blf", "asc", "log"] + (["mf4"] if importlib.util.find_spec("asammdf") else [])
    cases = [[], ["parquet"], *([fmt] for fmt in traces)]
    if args.quick:
        cases = cases[:1]  # the size run writes every format
    with tempfile.TemporaryDirectory(prefix="sashil-bench-formats-") as name:
        tmp = Path(name)
        emulator, link = start_emulator(tmp)
        try:
            results: dict[str, list[dict]] = {}
            for k in range(args.repeat):
                for case in cases:
                    label = "+".join(case) or "csv only"
                    results.setdefault(label, []).append(run(tmp, link, args.duration, case, f"{label}-{k}"))
            print(f"loop lateness at 1 kHz over slcan, {args.duration:g} s runs, median of {args.repeat}:")
            print(f"{'format':>10} {'p50 [us]':>9} {'p99 [us]':>9} {'max [us]':>9} {'missed':>7}")
            for label, rows in results.items():
                med = {key: float(np.median([r[key] for r in rows])) for key in ("p50", "p99", "max", "missed")}
                print(f"{label:>10} {med['p50']:9.1f} {med['p99']:9.1f} {med['max']:9.0f} {med['missed']:7.0f}")
            if args.sizes > 0:
                every = run(tmp, link, args.sizes, ["parquet", "mat", *traces], "sizes")
                print(f"\nfiles of one {args.sizes:g} s run at 1 kHz ({every['cycles']} cycles):")
                for path in sorted(every["folder"].iterdir()):
                    if path.suffix in (".csv", ".parquet", ".mat", ".blf", ".asc", ".log", ".mf4", ".npz"):
                        print(f"{path.name:>14} {path.stat().st_size / 1e6:8.2f} MB")
        finally:
            emulator.send_signal(signal.SIGTERM)
            emulator.wait(timeout=30)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_formats", main)

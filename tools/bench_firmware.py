"""Benchmark of the board's C logic: per-sample work on the host, an estimate for the
Cortex-M4, and the firmware's flash and RAM. Prints figures; not a test.

1. host: ``tools/firmware_bench.c`` built with the system C compiler (-O2), a 1 kHz device-paced
   session on the serial link where each period the board decodes one Command frame and encodes
   one Sample frame: nanoseconds per sample, median of ``--repeats`` runs. Baseline, same run: the
   same protocol work done by the Python board's codec (StreamDecoder.feed of the Command frame and
   encode_frame of the Sample) per sample.
   The frame encode on the host side is inside the loop (it is the host's, not the board's, so this
   slightly overstates the board's share).
2. Cortex-M4 estimate: instructions per sample counted by valgrind (callgrind, x86-64: the difference
   of two run lengths, so start-up cancels) times a CPI of 1.5 (ARMv7-M: most instructions 1 cycle,
   loads 2, taken branches 2-4; 0 flash wait states assumed from the ART accelerator) at 168 MHz,
   against the 200 us period of 5 kHz. Without valgrind this part is skipped.
3. ``make -C drivers/firmware cortex-m4``: flash and RAM (needs the ziglang package).

    .venv/bin/python tools/bench_firmware.py
    .venv/bin/python tools/bench_firmware.py --quick   # 10000 samples, once: the code path only (seconds)

Without a C compiler the full run stops with an error; ``--quick`` says so in one line and exits 0.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sashil.drivers import firmware
from sashil.drivers.messages import Command, Sample
from sashil.drivers.serial_codec import StreamDecoder, encode_frame

HERE = Path(__file__).resolve().parent
CPI = 1.5
M4_MHZ = 168.0


def build(tmp: Path) -> Path:
    cc = firmware.compiler()
    if cc is None:
        sys.exit("bench_firmware: no C compiler (install gcc or set CC)")
    exe = tmp / "firmware_bench"
    sources = [str(firmware.HERE / s) for s in firmware.SOURCES]
    subprocess.run(
        [cc, "-std=c99", "-O2", f"-I{firmware.HERE}", "-o", str(exe), str(HERE / "firmware_bench.c"), *sources],
        check=True,
    )
    return exe


def c_ns_per_sample(exe: Path, samples: int) -> float:
    out = subprocess.run([str(exe), str(samples)], capture_output=True, text=True, check=True).stdout
    return float(out.split()[0])


def python_ns_per_sample(samples: int) -> float:
    decoder = StreamDecoder()
    command = encode_frame(Command(1.0, 1), 7)
    sample = Sample(1000, 100, -33, 0.617, 0)
    start = time.perf_counter_ns()
    for k in range(samples):
        decoder.feed(command)
        encode_frame(sample, k & 0xFFFF)
    return (time.perf_counter_ns() - start) / samples


def instructions(exe: Path, samples: int) -> int | None:
    if shutil.which("valgrind") is None:
        return None
    done = subprocess.run(
        ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", str(exe), str(samples)],
        capture_output=True,
        text=True,
    )
    found = re.search(r"Collected\s*:\s*(\d+)", done.stderr)
    return int(found.group(1)) if found else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--quick", action="store_true", help="10000 samples once, short callgrind runs, build in a temporary folder"
    )
    args = parser.parse_args()
    if args.quick:
        if firmware.compiler() is None:
            print("bench_firmware: skipped, no C compiler (install gcc or set CC)")
            return 0
        args.samples, args.repeats = 10_000, 1
    short_n, long_n = (1_000, 2_000) if args.quick else (10_000, 110_000)  # callgrind run lengths
    with tempfile.TemporaryDirectory() as tmp:
        exe = build(Path(tmp))
        c_runs = [c_ns_per_sample(exe, args.samples) for _ in range(args.repeats)]
        py_runs = [python_ns_per_sample(max(args.samples // 20, 1000)) for _ in range(args.repeats)]
        c_ns, py_ns = statistics.median(c_runs), statistics.median(py_runs)
        print(f"host, per sample (decode a Command frame, encode a Sample frame), median of {args.repeats}:")
        print(f"  C board      {c_ns / 1e3:8.3f} us  (runs {', '.join(f'{v / 1e3:.3f}' for v in c_runs)})")
        print(f"  Python codec {py_ns / 1e3:8.3f} us  (baseline, same run; x{py_ns / c_ns:.0f})")
        short, long = instructions(exe, short_n), instructions(exe, long_n)
        if short is not None and long is not None:
            per_sample = (long - short) / (long_n - short_n)
            cycles = per_sample * CPI
            print(
                f"Cortex-M4 estimate: {per_sample:.0f} instructions per sample (x86-64, callgrind) x CPI {CPI} = "
                f"{cycles:.0f} cycles = {cycles / M4_MHZ:.1f} us at {M4_MHZ:.0f} MHz, "
                f"{100 * cycles / M4_MHZ / 200:.1f} % of the 200 us period of 5 kHz"
            )
        else:
            print("Cortex-M4 estimate: skipped (no valgrind)")
        build_dir = f"{tmp}/m4" if args.quick else f"{tempfile.gettempdir()}/sashil-m4"
        make = subprocess.run(
            ["make", "-s", "-C", str(firmware.HERE), "cortex-m4", f"PYTHON={sys.executable}", f"BUILD={build_dir}"],
            capture_output=True,
            text=True,
        )
    last = (make.stdout.strip().splitlines() or make.stderr.strip().splitlines() or ["?"])[-1]
    print(f"Cortex-M4 build: {last}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

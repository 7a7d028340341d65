"""Benchmark of the board's C logic: per-sample work on the host, an estimate for the
Cortex-M4, and the firmware's flash and RAM. Prints figures; not a test.

1. host: ``tools/firmware_bench.c`` built with the system C compiler (-O2), a 1 kHz device-paced
   session on the serial link where each period the board decodes one Command frame and encodes
   one Sample frame: nanoseconds per sample, median of ``--repeats`` runs. Baseline, same run: the
   same protocol work done by the Python board's codec (StreamDecoder.feed of the Command frame and
   encode_frame of the Sample) per sample.
   The frame encode on the host side is inside the loop (it is the host's, not the board's, so this
   slightly overstates the board's share).
2. Cortex-M4: instructions per sample of the ARM image itself, run in QEMU (netduinoplus2) with
   ``-icount shift=0``: ``make cortex-m4-bench`` links ``cortex-m4/bench_main.c`` (the same session
   as 1, on the reference HAL's callbacks) in place of ``main.c``; with ``-icount shift=0`` QEMU's
   virtual time advances 1 ns per instruction and SysTick counts it, so the board's clock measures
   instructions. Two session lengths, so start-up cancels in the difference. QEMU counts
   instructions, not cycles: the time at 168 MHz printed beside it takes 1 cycle per instruction, a
   floor (loads, taken branches and flash wait states take more). Without qemu-system-arm (or make
   and ziglang) this part is skipped and says why.
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
import threading
import time
from pathlib import Path

from sashil.drivers import firmware
from sashil.drivers.messages import Command, Sample
from sashil.drivers.serial_codec import StreamDecoder, encode_frame

HERE = Path(__file__).resolve().parent
M4_MHZ = 168.0
QEMU = "qemu-system-arm"
_BENCH_LINE = re.compile(r"bench samples (\d+) us (\d+) samples (\d+) us (\d+)")


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


def qemu_instructions(build_dir: str, timeout_s: float = 60.0) -> float | str:
    """Instructions per sample of the Cortex-M4 image in QEMU (-icount shift=0), or why there is none."""
    if shutil.which(QEMU) is None:
        return f"skipped, {QEMU} is not installed (Debian: apt-get install qemu-system-arm)"
    made = subprocess.run(
        ["make", "-s", "-C", str(firmware.HERE), "cortex-m4-bench", f"PYTHON={sys.executable}", f"BUILD={build_dir}"],
        capture_output=True,
        text=True,
    )
    if made.returncode != 0:
        return f"skipped, make cortex-m4-bench failed: {(made.stderr.strip().splitlines() or ['?'])[-1]}"
    command = [QEMU, "-M", "netduinoplus2", "-display", "none", "-monitor", "none", "-serial", "stdio"]
    command += ["-icount", "shift=0", "-kernel", f"{build_dir}/cortex-m4/sashil-board-bench.elf"]
    qemu = subprocess.Popen(
        command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    found: list[re.Match[str]] = []

    def read() -> None:  # the image prints one line, then idles until killed
        assert qemu.stdout is not None
        for line in qemu.stdout:
            match = _BENCH_LINE.search(line)
            if match:
                found.append(match)
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout_s)
    qemu.kill()
    qemu.wait()
    reader.join()
    if qemu.stdout is not None:
        qemu.stdout.close()
    if not found:
        return f"no result from {QEMU} within {timeout_s:g} s"
    short_n, short_us, long_n, long_us = (int(v) for v in found[0].groups())
    return (long_us - short_us) * 1000.0 / (long_n - short_n)  # 1 ns of virtual time per instruction


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="10000 samples once, build in a temporary folder")
    args = parser.parse_args()
    if args.quick:
        if firmware.compiler() is None:
            print("bench_firmware: skipped, no C compiler (install gcc or set CC)")
            return 0
        args.samples, args.repeats = 10_000, 1
    with tempfile.TemporaryDirectory() as tmp:
        exe = build(Path(tmp))
        c_runs = [c_ns_per_sample(exe, args.samples) for _ in range(args.repeats)]
        py_runs = [python_ns_per_sample(max(args.samples // 20, 1000)) for _ in range(args.repeats)]
        c_ns, py_ns = statistics.median(c_runs), statistics.median(py_runs)
        print(f"host, per sample (decode a Command frame, encode a Sample frame), median of {args.repeats}:")
        print(f"  C board      {c_ns / 1e3:8.3f} us  (runs {', '.join(f'{v / 1e3:.3f}' for v in c_runs)})")
        print(f"  Python codec {py_ns / 1e3:8.3f} us  (baseline, same run; x{py_ns / c_ns:.0f})")
        per_sample = qemu_instructions(f"{tmp}/bench")
        if isinstance(per_sample, float):
            floor_us = per_sample / M4_MHZ
            print(
                f"Cortex-M4 image in QEMU (-icount shift=0): {per_sample:.0f} instructions per sample; "
                f"instructions, not cycles: at {M4_MHZ:.0f} MHz and 1 cycle each (the floor) {floor_us:.1f} us, "
                f"{100 * floor_us / 200:.1f} % of the 200 us period of 5 kHz"
            )
        else:
            print(f"Cortex-M4 image in QEMU: {per_sample}")
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
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_firmware", main))

"""The rtdac backend's cost per loop cycle, against the bare exchange it rides on.

One loop cycle over the RT-DAC/USB2 is one exchange: a write frame, a read request, a read frame,
each a bulk transfer through pyusb. This measures, interleaved in the same run:

* **the exchange through pyusb** against the emulated board served by ``sashil emulate --transport
  rtdac`` in its own process (the socket stands in for the USB wire): the three transfers as bare
  pyusb calls, median and p99;
* **the backend's cycle**: ``RtdacRig.read`` + ``RtdacRig.write`` on the same board (the same three
  transfers, plus decoding the frame, the coil's map and current loop, the road's loop and the
  write frame's patching);
* the same two against a board in this process (:class:`DirectPort`), where the wire costs nothing;
* **the backend's own work**: the cycle with its link replaced by one that hands back a recorded
  frame and drops the write, so nothing but the backend's own code runs (the headline figure; the
  median difference of the two above checks it from the other side).

    python tools/bench_rtdac.py            # 20000 cycles each
    python tools/bench_rtdac.py --quick    # 300 cycles each (seconds; the figures are not meaningful)
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from sashil.config.frozen import freeze_config  # noqa: E402
from sashil.config.rtdac_section import WIRING_KEYS  # noqa: E402
from sashil.drivers import rig_parts  # noqa: E402
from sashil.drivers.emulator.rtdac_board import build_board  # noqa: E402
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend, SocketPort  # noqa: E402
from sashil.drivers.interface import RigCommand  # noqa: E402
from sashil.drivers.rtdac_codec import ENDPOINT_IN, ENDPOINT_OUT, FRAME_BYTES, READ_REQUEST  # noqa: E402
from sashil.drivers.rtdac_rig import RtdacRig  # noqa: E402
from sashil.engine.resolve import default_config  # noqa: E402


def quantiles_us(times: list[float]) -> tuple[float, float, float]:
    """Median, p99 and max [us]."""
    ordered = sorted(times)
    p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
    return statistics.median(ordered) * 1e6, p99 * 1e6, ordered[-1] * 1e6


def bench_config() -> object:
    """The default config with a transfer timeout that rides through a shared VM's pauses (the
    emulated board answers within microseconds; the VM stops a process for tens of milliseconds now
    and then), so the run measures the exchange rather than ending at the first pause."""
    raw = default_config()
    raw["rtdac"]["transfer_timeout_ms"] = 500.0
    if "confirmed" in raw["rtdac"]:  # the bench as the walk confirms it: the coil's current sensed on A/D 0
        raw["rtdac"]["confirmed"] = list(WIRING_KEYS)
        raw["rtdac"]["coil_sense_ad"] = 0
    return freeze_config(raw)


def measure(backend: object, cycles: int) -> tuple[list[float], list[float]]:
    """(bare exchanges, backend cycles) [s], interleaved in blocks of 100 so that both see the same load."""
    config = bench_config()
    rig = RtdacRig.from_parts(rig_parts(config, "rtdac"), backend=backend)  # type: ignore[arg-type]
    rig.configure()
    rig.activate()
    dev = rig.link.dev
    bare: list[float] = []
    full: list[float] = []
    command = RigCommand(0.5, 1.0)
    t_ns = time.monotonic_ns()
    for _ in range(10):  # the bare exchange sends what the backend's cycle sends: coil on, road turning
        t_ns += 1_000_000
        rig.read(t_ns, 1_000_000)
        rig.write(command, t_ns, 1_000_000)
    frame = rig.exchange_frame()
    clock = time.perf_counter
    try:
        while len(bare) < cycles:
            for _ in range(100):
                start = clock()
                dev.write(ENDPOINT_OUT, frame, 500)
                dev.write(ENDPOINT_OUT, READ_REQUEST, 500)
                dev.read(ENDPOINT_IN, FRAME_BYTES, 500)
                bare.append(clock() - start)
            for _ in range(100):
                t_ns += 1_000_000
                start = clock()
                rig.read(t_ns, 1_000_000)
                rig.write(command, t_ns, 1_000_000)
                full.append(clock() - start)
    finally:
        rig.close()
    return bare, full


class RecordedLink:
    """A link that answers every read with the last frame written (a board that takes every word, as
    a read frame shows them), first one recorded read: the backend's own work with no transfer under it."""

    def __init__(self, real: object):
        self.dev = getattr(real, "dev", None)
        self.where = "recorded"
        self.frame = real.read_frame()  # type: ignore[attr-defined]

    def read_frame(self) -> object:
        return self.frame

    def write_frame(self, frame: bytes | bytearray) -> None:
        self.frame = frame  # the backend builds a new frame each cycle: no copy needed

    def facts(self) -> dict[str, object]:
        return {}


def own_work(backend: object, cycles: int) -> list[float]:
    """The backend's cycle [s] over a :class:`RecordedLink`."""
    rig = RtdacRig.from_parts(rig_parts(bench_config(), "rtdac"), backend=backend)  # type: ignore[arg-type]
    rig.configure()
    rig.activate()
    real = rig.link
    rig.link = RecordedLink(real)  # type: ignore[assignment]
    command = RigCommand(0.5, 1.0)
    times = []
    t_ns = time.monotonic_ns()
    clock = time.perf_counter
    try:
        for _ in range(cycles):
            t_ns += 1_000_000
            start = clock()
            rig.read(t_ns, 1_000_000)
            rig.write(command, t_ns, 1_000_000)
            times.append(clock() - start)
    finally:
        rig.link = real
        rig.close()
    return times


def report(where: str, bare: list[float], full: list[float]) -> float:
    b50, b99, bmax = quantiles_us(bare)
    f50, f99, fmax = quantiles_us(full)
    print(f"{where}: bare exchange median {b50:.1f} us, p99 {b99:.1f} us, max {bmax:.0f} us (baseline)")
    print(f"{where}: backend cycle  median {f50:.1f} us, p99 {f99:.1f} us, max {fmax:.0f} us")
    print(f"{where}: the backend's own work: {f50 - b50:.1f} us a cycle (median difference)")
    return f50 - b50


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="300 cycles each (seconds)")
    args = parser.parse_args()
    cycles = 300 if args.quick else 20_000
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; {cycles} cycles each")
    board = build_board(freeze_config(default_config()))
    own50, own99, _ = quantiles_us(own_work(EmulatedUsbBackend(DirectPort(board)), cycles))
    print(f"the backend's own work (no transfer under it): median {own50:.1f} us, p99 {own99:.1f} us a cycle")
    report("in-process board", *measure(EmulatedUsbBackend(DirectPort(board)), cycles))
    with tempfile.TemporaryDirectory(prefix="sashil-bench-rtdac-") as tmp:
        link = str(Path(tmp) / "rtdac.sock")
        command = [
            sys.executable,
            "-m",
            "sashil",
            "emulate",
            "--transport",
            "rtdac",
            "--link",
            link,
            "--duration",
            "600",
        ]
        emulator = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            line = emulator.stdout.readline() if emulator.stdout else ""
            if "rtdac board on" not in line:
                print(f"bench_rtdac: the emulator did not start: {line.strip() or 'no output'}", file=sys.stderr)
                return 1
            report("emulated board over its socket", *measure(EmulatedUsbBackend(SocketPort(link)), cycles))
        finally:
            emulator.send_signal(signal.SIGTERM)
            emulator.communicate(timeout=30)
    verdict = "met" if own50 <= 20.0 else "NOT met"
    print(f"target: the backend's own work <= 20 us a cycle beyond the exchange: {verdict} (median {own50:.1f} us)")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_rtdac", main))

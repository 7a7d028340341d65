"""Benchmark of the serial and CAN links against the emulator (prints figures; not a test).

1. codec cost per frame: serial (COBS + CRC-16) and CAN (cantools through the DBC);
2. CAN bus load of the protocol's frames at the loop rate on a 1 Mbit/s bus (computed);
3. round trip command -> sample over a pty, p50/p99, for serial and slcan (host pacing, each command
   answered by one sample), beside the raw pty echo round trip of a command-sized frame measured
   in the same run (a child process echoing bytes);
4. ``sashil run`` at 1 kHz over each link and pacing for ``--duration`` s (default 60): cycles,
   missed deadlines, lateness and read time from its summary.json, and the link's counters.

    .venv/bin/python tools/bench_link.py --duration 60
    .venv/bin/python tools/bench_link.py --quick    # 50 round trips, 0.5 s runs: the code path only (seconds)

``--quick`` runs ``sashil run`` twice, serial paced by the device and slcan paced by the host (each
link and each pacing once), instead of all four pairs.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import serial

from sashil.drivers import can_codec, open_rig, rig_parts
from sashil.drivers.interface import RigCommand
from sashil.drivers.messages import Command, Sample
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.engine.resolve import default_config

#: how the benchmark runs sashil: this interpreter, or the command in the environment variable
#: SASHIL_COMMAND (words split at spaces: another install, or the tests' warm interpreter)
SASHIL = os.environ.get("SASHIL_COMMAND", "").split() or [
    sys.executable,
    "-c",
    "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))",
]
ECHO = """
import os, select, sys, tty
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
except OSError:
    pass
master, slave = os.openpty()
tty.setraw(slave)
print(os.ttyname(slave), flush=True)
while True:
    r, _, _ = select.select([master], [], [], 1.0)
    if r:
        os.write(master, os.read(master, 4096))
"""


def percentiles(values_ns: list[int]) -> str:
    x = np.asarray(values_ns) / 1e3
    return f"p50 {np.percentile(x, 50):7.1f}  p99 {np.percentile(x, 99):7.1f}  max {x.max():7.1f} us  (n={len(x)})"


def codec_cost(n: int = 20000) -> None:
    sample, command = Sample(123456, -57, 4097, 0.25, 2, 300, 1, 12, -1), Command(0.5)
    frame = encode_frame(sample, 1)
    decoder = StreamDecoder()
    t0 = time.perf_counter_ns()
    for _ in range(n):
        encode_frame(sample, 1)
    t1 = time.perf_counter_ns()
    for _ in range(n):
        decoder.feed(frame)
    t2 = time.perf_counter_ns()
    frames = can_codec.encode(sample, 1)
    can_decoder = can_codec.CanDecoder()
    t3 = time.perf_counter_ns()
    for _ in range(n):
        can_codec.encode(command, 1)
    t4 = time.perf_counter_ns()
    for _ in range(n):
        for frame_id, data in frames:
            can_decoder.feed(frame_id, data)
    t5 = time.perf_counter_ns()
    print("codec cost per message (this machine, shared, noisy):")
    print(
        f"  serial encode Sample {(t1 - t0) / n / 1e3:6.2f} us   decode Sample {(t2 - t1) / n / 1e3:6.2f} us   ({len(frame)} bytes on the wire)"
    )
    print(
        f"  CAN    encode Command {(t4 - t3) / n / 1e3:5.2f} us   decode Sample (3 frames) {(t5 - t4) / n / 1e3:6.2f} us  (cantools via sashil.dbc)"
    )


def bus_load(rate_hz: float = 1000.0, bitrate: int = 1_000_000) -> None:
    per_cycle = {"SampleA": 8, "SampleEdges": 5, "SampleB": 8, "Command": 5}
    nominal = sum(can_codec.frame_bits(n, worst_case_stuffing=False) for n in per_cycle.values())
    worst = sum(can_codec.frame_bits(n) for n in per_cycle.values())
    print(
        f"CAN bus load at {rate_hz:g} Hz on {bitrate / 1e6:g} Mbit/s (frames per cycle: {', '.join(f'{k} {v} B' for k, v in per_cycle.items())}):"
    )
    print(
        f"  {nominal} bits/cycle without stuffing -> {100 * nominal * rate_hz / bitrate:.1f} %;"
        f" worst-case stuffing {worst} bits/cycle -> {100 * worst * rate_hz / bitrate:.1f} %"
        f"; time on the bus per cycle {worst / bitrate * 1e6:.0f} us worst case"
    )
    sample_bits = worst - can_codec.frame_bits(per_cycle["Command"])
    serial_bits = 10 * len(encode_frame(Sample(123456, -57, 4097, 0.25, 2, 300, 1, 12, -1), 1))  # 8N1
    print(
        f"  highest device-paced rate: CAN {bitrate / sample_bits:.0f} Hz (samples alone, worst-case stuffing), "
        f"{bitrate / worst:.0f} Hz with a Command each cycle; serial at {bitrate / 1e6:g} Mbit/s "
        f"{bitrate / serial_bits:.0f} Hz ({serial_bits // 10} bytes per Sample)"
    )


def echo_round_trip(n: int) -> list[int]:
    proc = subprocess.Popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
    try:
        path = proc.stdout.readline().strip()
        port = serial.Serial(path, timeout=0)
        fd = port.fileno()
        frame = encode_frame(Command(0.5), 1)
        times = []
        next_t = time.perf_counter_ns()
        for _ in range(n):
            next_t += 1_000_000
            t0 = time.perf_counter_ns()
            port.write(frame)
            got = 0
            while got < len(frame):
                select.select([fd], [], [], 0.1)
                got += len(port.read(port.in_waiting or 1))
            times.append(time.perf_counter_ns() - t0)
            _sleep_until(next_t)
        port.close()
        return times
    finally:
        proc.kill()
        proc.wait()


def _sleep_until(t_ns: int) -> None:
    remaining = t_ns - time.perf_counter_ns()
    if remaining > 0:
        time.sleep(remaining * 1e-9)


class EmulatorProcess:
    """``sashil emulate --transport TRANSPORT --link LINK [FLAGS...]`` in a child process."""

    def __init__(self, transport: str, link: str, *flags: str):
        self.proc = subprocess.Popen(
            [*SASHIL, "emulate", "--transport", transport, "--link", link, *flags],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()
        if "rig on" not in line:
            raise SystemExit(f"emulator did not start: {line}{self.proc.stderr.read()}")

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGTERM)
        return self.proc.communicate(timeout=30)[1].strip()


def link_config(driver: str, port: str, pacing: str, timeout_ms: float = 50.0) -> dict:
    config = default_config()
    config["driver"].update(name=driver, port=port, pacing=pacing, sample_timeout_ms=timeout_ms)
    return config


def command_round_trip(driver: str, port: str, n: int) -> list[int]:
    rig = open_rig(rig_parts(link_config(driver, port, "host")))
    rig.configure()
    rig.activate()
    rig.read(0, 0)
    times = []
    next_t = time.perf_counter_ns()
    for _ in range(n):
        next_t += 1_000_000
        t0 = time.perf_counter_ns()
        rig.write(RigCommand(0.0), 0, 0)
        rig.read(0, 0)
        times.append(time.perf_counter_ns() - t0)
        _sleep_until(next_t)
    rig.close()
    return times


def _us(value: float | None) -> str:
    """A timing figure in whole microseconds, or "-" where the run has none (it ended before it had any)."""
    return "-" if value is None else f"{value:.0f}"


def run_over_link(
    driver: str, transport: str, pacing: str, duration: float, tmp: Path, timeout_ms: float | None
) -> None:
    link = str(tmp / f"rig-{transport}-{pacing}")
    emu = EmulatorProcess(transport, link)
    config = tmp / f"{transport}-{pacing}.yaml"
    extra = "" if timeout_ms is None else f"  sample_timeout_ms: {timeout_ms:g}\n"
    config.write_text(f"driver:\n  pacing: {pacing}\n{extra}")
    out = tmp / f"run-{transport}-{pacing}"
    done = subprocess.run(
        [
            *SASHIL,
            "run",
            "--driver",
            driver,
            "--port",
            link,
            "--duration",
            str(duration),
            "--config",
            str(config),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    emu_line = emu.stop()
    summary = json.loads((out / "summary.json").read_text())
    timing = summary["timing"]
    link_lines = [line for line in done.stderr.splitlines() if "link:" in line]
    lateness, read = timing["lateness_us"], timing["read_us"]
    print(
        f"  {transport:6s} pacing {pacing:6s}: exit {done.returncode}, cycles {timing['cycles']}, "
        f"missed deadlines {timing['missed_deadlines']}, lateness p99 {_us(lateness['p99'])} "
        f"max {_us(lateness['max'])} us, read p50 {_us(read['p50'])} p99 {_us(read['p99'])} us"
    )
    link_stats = summary.get("link") or {}
    print(
        f"    link gaps ridden through at 0 A: {link_stats.get('gaps', 0)} (longest {link_stats.get('gap_max_ms', 0.0):.1f} ms)"
    )
    if done.returncode:
        errors = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.splitlines()[-1:]
        print("    " + (errors[-1] if errors else "?"))
    for line in link_lines:
        print("    host " + line.split(": ", 1)[-1].strip())
    print("    " + emu_line.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds of each sashil run (default 60)")
    parser.add_argument("--round-trips", type=int, default=3000, help="round trips per link (default 3000)")
    parser.add_argument(
        "--sample-timeout-ms",
        type=float,
        help="driver.sample_timeout_ms of the runs (default: the config default, 2.5)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="2000 codec calls, 50 round trips, two 0.5 s runs (seconds)"
    )
    args = parser.parse_args()
    if args.quick:
        args.duration, args.round_trips = 0.5, 50
    print(f"bench_link: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} (shared machine: timing is noisy)")
    codec_cost(2000 if args.quick else 20000)
    bus_load()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        print("round trip over a pty, paced at 1 kHz (echo: raw bytes; serial/slcan: Command -> Sample, host pacing):")
        echo = echo_round_trip(args.round_trips)
        results = {"echo": echo}
        for transport, driver in (("serial", "serial"), ("slcan", "can")):
            emu = EmulatorProcess(transport, str(tmp / f"rt-{transport}"))
            try:
                results[transport] = command_round_trip(driver, str(tmp / f"rt-{transport}"), args.round_trips)
            finally:
                emu.stop()
        echo_p50 = np.percentile(echo, 50)
        for name, times in results.items():
            ratio = "" if name == "echo" else f"   p50 = {np.percentile(times, 50) / echo_p50:.1f} x echo"
            print(f"  {name:6s} {percentiles(times)}{ratio}")
        timeout = "default" if args.sample_timeout_ms is None else f"{args.sample_timeout_ms:g} ms"
        print(
            f"sashil run at 1 kHz for {args.duration:g} s over each link (emulator process SCHED_FIFO 60, loop FIFO 50, "
            f"sample timeout {timeout}, link lost 25 ms):"
        )
        pairs = [(link, pacing) for link in (("serial", "serial"), ("slcan", "can")) for pacing in ("device", "host")]
        if args.quick:  # each link and each pacing once
            pairs = [pairs[0], pairs[3]]
        for (transport, driver), pacing in pairs:
            run_over_link(driver, transport, pacing, args.duration, tmp, args.sample_timeout_ms)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_link", main)

"""Run the Cortex-M4 firmware on QEMU's ``netduinoplus2`` (an STM32F405) and hold a short session with it.

Build the QEMU variant first (``-DSASHIL_QEMU``: no PLL start-up, polled transmit, encoders at rest,
since QEMU 7.2 models no RCC, raises no USART TXE interrupt and has no encoder mode; see
``drivers/firmware/cortex-m4/hal_stm32f4.c``):

    make -C drivers/firmware cortex-m4-qemu PYTHON=.venv/bin/python
    .venv/bin/python tools/qemu_smoke.py drivers/firmware/build/cortex-m4/sashil-board-qemu.elf

USART1 is QEMU's first serial port, here a Unix socket. Over it, with the project's serial codec:
Command(0 A) and Hello -> Version (protocol 1, 4096 counts per revolution, 2 A); Configure in host
pacing -> Status with no fault; Command(0.5 A, enabled) -> Sample. So the vector table, the reset
handler, the receive interrupt and ring, the frame codec and the board's session logic run on an
emulated Cortex-M4. Whole sessions (``sashil run`` in both pacings, the watchdog) run against the same
image in ``tests/test_firmware_qemu.py`` (``make -C drivers/firmware qemu``). Needs ``qemu-system-arm``
(Debian: ``apt-get install qemu-system-arm``). Prints one line per step; exit 0 when all passed.

``--quick`` without an ELF builds the QEMU variant into a temporary folder first (needs make and the
ziglang package); without qemu-system-arm, make or ziglang it says what is missing and exits 0:

    .venv/bin/python tools/qemu_smoke.py --quick
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections import deque
from pathlib import Path

from sashil.drivers.messages import PACING_HOST, Command, Configure, Hello, Message, Sample, Status, Version
from sashil.drivers.serial_codec import StreamDecoder, encode_frame

QEMU = "qemu-system-arm"


class SmokeError(RuntimeError):
    """A step of the session did not get the answer it expected."""


def _connect(path: Path, qemu: subprocess.Popen[bytes], deadline: float) -> socket.socket:
    while time.monotonic() < deadline:
        if qemu.poll() is not None:
            raise SmokeError(f"{QEMU} exited with {qemu.returncode} before its serial port opened")
        try:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.connect(str(path))
            return sock
        except OSError:
            sock.close()
            time.sleep(0.02)
    raise SmokeError(f"{QEMU}'s serial socket did not open")


def _answer(
    sock: socket.socket,
    decoder: StreamDecoder,
    unread: deque[Message],
    kind: type[Message],
    timeout_s: float,
    resend: bytes = b"",
) -> Message:
    """The next ``kind`` from the board; ``resend`` goes out again every 50 ms until it comes.

    ``unread`` holds what earlier reads decoded and no answer consumed yet: one read can bring the
    answer and the messages after it, which the next call finds there before it reads again."""
    deadline = time.monotonic() + timeout_s
    while True:
        while unread:
            msg = unread.popleft()
            if isinstance(msg, kind):
                return msg
        if time.monotonic() >= deadline:
            raise SmokeError(f"no {kind.__name__} within {timeout_s} s")
        sock.settimeout(min(0.05, max(0.001, deadline - time.monotonic())))
        try:
            data = sock.recv(4096)
        except TimeoutError:
            if resend:
                sock.sendall(resend)
            continue
        if not data:
            raise SmokeError("the serial socket closed")
        unread.extend(msg for _seq, msg in decoder.feed(data))


def smoke(elf: Path, timeout_s: float = 1.0) -> list[str]:
    """Boot ``elf`` on netduinoplus2, hold the session; the steps that passed, or SmokeError."""
    if shutil.which(QEMU) is None:
        raise SmokeError(f"{QEMU} is not installed (Debian: apt-get install qemu-system-arm)")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "usart1"
        command = [QEMU, "-M", "netduinoplus2", "-nographic", "-monitor", "none", "-kernel", str(elf)]
        qemu = subprocess.Popen(
            [*command, "-serial", f"unix:{path},server=on,wait=on"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        try:
            with _connect(path, qemu, time.monotonic() + 10.0) as sock:
                decoder, unread, steps = StreamDecoder(), deque[Message](), []
                t0 = time.monotonic()
                # QEMU's USART drops what arrives before the firmware has enabled it: the host
                # says Hello again every 50 ms until the board answers (the first one may be lost)
                hello = encode_frame(Command(0.0, flags=0), 1) + encode_frame(Hello(), 2)
                sock.sendall(hello)
                version = _answer(sock, decoder, unread, Version, timeout_s, resend=hello)
                if version != Version(protocol_version=2, counts_per_rev=4096, current_max_a=2.0):
                    raise SmokeError(f"unexpected {version}")
                steps.append(f"Hello -> {version} in {1e3 * (time.monotonic() - t0):.0f} ms")
                sock.sendall(encode_frame(Configure(rate_hz=1000, watchdog_ms=50, pacing=PACING_HOST), 3))
                status = _answer(sock, decoder, unread, Status, timeout_s)
                if not isinstance(status, Status) or status.fault_code != 0:
                    raise SmokeError(f"Configure refused: {status}")
                steps.append(f"Configure -> {status}")
                sock.sendall(encode_frame(Command(0.5), 4))
                steps.append(f"Command -> {_answer(sock, decoder, unread, Sample, timeout_s)}")
                counters = decoder.counters.as_dict()
                if any(counters[k] for k in ("crc", "cobs", "length", "unknown_type", "overflow")):
                    raise SmokeError(f"bad frames from the board: {counters}")
                return steps
        finally:
            qemu.kill()
            qemu.wait()
            if qemu.stderr is not None:
                qemu.stderr.close()


def run(elf: Path, timeout_s: float) -> int:
    try:
        for step in smoke(elf, timeout_s):
            print(step)
    except SmokeError as err:
        print(f"qemu_smoke: {err}", file=sys.stderr)
        return 1
    print("qemu_smoke: passed")
    return 0


def quick(elf: Path | None, timeout_s: float) -> int:
    """The session on ``elf``, or on a fresh ``make cortex-m4-qemu`` build; exit 0 when a tool is missing."""
    if shutil.which(QEMU) is None:
        print(f"qemu_smoke: --quick skipped, {QEMU} is not installed (Debian: apt-get install qemu-system-arm)")
        return 0
    if elf is not None:
        return run(elf, timeout_s)
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        print("qemu_smoke: --quick skipped, the build needs make and the ziglang package (pip install ziglang)")
        return 0
    firmware = Path(__file__).resolve().parents[1] / "drivers" / "firmware"
    with tempfile.TemporaryDirectory(prefix="qemu_smoke-") as tmp:
        subprocess.run(
            ["make", "-s", "-C", str(firmware), "cortex-m4-qemu", f"PYTHON={sys.executable}", f"BUILD={tmp}"],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        return run(Path(tmp) / "cortex-m4" / "sashil-board-qemu.elf", timeout_s)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("elf", type=Path, nargs="?", help="the SASHIL_QEMU build (make cortex-m4-qemu)")
    parser.add_argument("--timeout", type=float, help="seconds to wait for each answer (default 1, 5 with --quick)")
    parser.add_argument(
        "--quick", action="store_true", help="build the ELF when none is given; exit 0 when qemu or zig is missing"
    )
    args = parser.parse_args(argv)
    if args.quick:
        return quick(args.elf, args.timeout or 5.0)
    if args.elf is None:
        parser.error("the following arguments are required: elf")
    return run(args.elf, args.timeout or 1.0)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("qemu_smoke", main))

"""The firmware's QEMU image (``make cortex-m4-qemu``) on QEMU's netduinoplus2, its USART1 on a pty.

    make -C drivers/firmware qemu LINK=/tmp/sashil-board [PYTHON=.venv/bin/python]
    sashil run --config configs/qemu.yaml --port /tmp/sashil-board --duration 10

``make qemu`` builds the image and runs this file as a script (standard library only, so it needs no
installed package): it starts ``qemu-system-arm`` with the first serial port (USART1) on a
pseudo-terminal, makes ``LINK`` a symlink to that pty, prints one line and stays in the foreground
until Ctrl-C or SIGTERM, then stops QEMU and removes the symlink. Tests use :class:`QemuBoard`, a
context manager doing the same.

QEMU runs the image's instructions, not the rig: the encoders read 0 under ``SASHIL_QEMU`` and the
board's clock is SysTick on QEMU's virtual clock (the host's real time unless ``-icount`` is given).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path
from types import TracebackType

QEMU = "qemu-system-arm"
MACHINE = "netduinoplus2"  # an STM32F405, as the reference HAL's part
_PTY = re.compile(r"char device redirected to (\S+) \(label serial0\)")


class QemuError(RuntimeError):
    """QEMU is missing, did not start, or did not open its serial port."""


def available() -> bool:
    """qemu-system-arm is on the PATH."""
    return shutil.which(QEMU) is not None


class QemuBoard:
    """``qemu-system-arm`` running ``elf``; ``pty`` is USART1's pseudo-terminal (and ``link`` a symlink
    to it when given). A context manager: leaving it kills QEMU and removes the symlink.

    ``extra`` are more QEMU arguments (e.g. ``["-icount", "shift=0"]``)."""

    def __init__(self, elf: Path, link: Path | None = None, extra: list[str] | None = None, timeout_s: float = 10.0):
        self.elf, self.link, self.extra, self.timeout_s = Path(elf), link, list(extra or []), timeout_s
        self.pty: str | None = None
        self.process: subprocess.Popen[str] | None = None
        self._log: list[str] = []

    def command(self) -> list[str]:
        serial = ["-serial", "pty", "-kernel", str(self.elf)]
        return [QEMU, "-M", MACHINE, "-nographic", "-monitor", "none", *serial, *self.extra]

    def start(self) -> str:
        """Start QEMU and return the pty's path once QEMU has named it."""
        if not available():
            raise QemuError(f"{QEMU} is not installed (Debian: apt-get install qemu-system-arm)")
        if not self.elf.is_file():
            raise QemuError(f"{self.elf}: no such image (make -C drivers/firmware cortex-m4-qemu)")
        self.process = subprocess.Popen(
            self.command(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        found = threading.Event()
        threading.Thread(target=self._read_output, args=(found,), daemon=True).start()
        if not found.wait(self.timeout_s) or self.pty is None:
            self.stop()
            raise QemuError(f"{QEMU} named no pty within {self.timeout_s:g} s: {' '.join(self._log)[-300:]}")
        if self.link is not None:
            if self.link.exists() and not self.link.is_symlink():
                self.stop()
                raise QemuError(f"{self.link} exists and is not a symlink: not replacing it")
            if self.link.is_symlink():
                self.link.unlink()  # a stale link from an earlier run
            self.link.symlink_to(self.pty)
        return self.pty

    def _read_output(self, found: threading.Event) -> None:
        """QEMU's console: the line naming the pty, then whatever else it says (kept for errors)."""
        assert self.process is not None and self.process.stdout is not None
        for line in self.process.stdout:
            self._log.append(line.strip())
            match = _PTY.search(line)
            if match and self.pty is None:
                self.pty = match.group(1)
                found.set()
        found.set()  # QEMU exited without naming one

    def stop(self) -> None:
        """Kill QEMU (once) and remove the symlink if it still points to this pty."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
        if self.process is not None:
            self.process.wait()
            if self.process.stdout is not None:
                self.process.stdout.close()
        if self.link is not None and self.link.is_symlink() and os.readlink(self.link) == self.pty:
            self.link.unlink()

    def __enter__(self) -> QemuBoard:
        self.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="run the firmware's QEMU image with USART1 on a pty")
    parser.add_argument("elf", type=Path, help="the SASHIL_QEMU build (make cortex-m4-qemu)")
    parser.add_argument("--link", type=Path, required=True, help="make this path a symlink to USART1's pty")
    args = parser.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, lambda *_: stop.set())
    board = QemuBoard(args.elf, link=args.link)
    try:
        pty = board.start()
    except QemuError as err:
        print(f"qemu: {err}", file=sys.stderr)
        return 2
    try:
        print(
            f"qemu: {MACHINE} running {args.elf}; USART1 on {pty}, linked as {args.link}; Ctrl-C stops it", flush=True
        )
        while not stop.wait(0.2):
            if board.process is not None and board.process.poll() is not None:
                print(f"qemu: {QEMU} exited with {board.process.returncode}", file=sys.stderr)
                return 1
        return 0
    finally:
        board.stop()


if __name__ == "__main__":
    sys.exit(main())

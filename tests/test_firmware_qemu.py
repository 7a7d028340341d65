"""The firmware's own ARM image through whole sessions: ``sashil run`` over USART1's pty of QEMU's
netduinoplus2 (an STM32F405) running the ``SASHIL_QEMU`` build, in host and device pacing, and the
board's watchdog resting coil and road when the host goes quiet.

On the wall clock (QEMU's SysTick follows the host's time), so e2e. Needs qemu-system-arm (``.ci/run``
installs it where it can), make and the ziglang package; skipped without them."""

from __future__ import annotations

import importlib.util
import itertools
import json
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from board_port import Port
from tool_module import load_tool

from sashil.drivers.firmware import qemu
from sashil.drivers.interface import FLAG_WATCHDOG
from sashil.drivers.messages import (
    CMD_ENABLE,
    PACING_DEVICE,
    PACING_HOST,
    STATUS_CLOCK_FALLBACK,
    Command,
    Configure,
    Hello,
    RoadSpeed,
    Sample,
    Status,
    Version,
)

# the image's SysTick and the host's deadlines on the wall clock: by itself (pyproject's markers)
pytestmark = [pytest.mark.e2e, pytest.mark.alone]

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "drivers" / "firmware"
SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]


@pytest.fixture(scope="module")
def board(tmp_path_factory) -> Iterator[Path]:
    """The QEMU image running, its USART1 behind a symlink; QEMU killed at the end."""
    if not qemu.available():
        pytest.skip("needs qemu-system-arm (Debian: apt-get install qemu-system-arm)")
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        pytest.skip("needs make and the ziglang package (pip install ziglang)")
    build = tmp_path_factory.mktemp("qemu-build")
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE), "cortex-m4-qemu", f"PYTHON={sys.executable}", f"BUILD={build}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    link = build / "board"
    # -icount: QEMU's virtual clock counts the image's instructions (8 ns each) and, while the image
    # waits for its next tick, the host's time (sleep=on): the board's SysTick then runs on a clock of
    # its own, not on the moments a busy host happens to schedule QEMU's vCPU
    with qemu.QemuBoard(
        build / "cortex-m4" / "sashil-board-qemu.elf", link=link, extra=["-icount", "shift=3,sleep=on"]
    ):
        port = Port(link)  # the image enables its USART within microseconds; wait until it answers
        try:
            port.wait(Version, 10.0, resend=(Hello(),))
        finally:
            port.close()
        yield link
    assert not link.exists()  # the symlink goes with QEMU


def run(board: Path, out: Path, *options: str) -> dict:
    done = subprocess.run(
        [
            *SASHIL,
            "run",
            "--config",
            str(ROOT / "configs" / "qemu.yaml"),
            "--port",
            str(board),
            "--out",
            str(out),
            *options,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads((out / "summary.json").read_text())


def test_a_host_paced_run_on_the_image_answers_every_sample_with_no_bad_frame(board, tmp_path):
    summary = run(board, tmp_path / "host", "--duration", "3")
    link, cycles = summary["link"], summary["timing"]["cycles"]
    assert summary["exit_status"] == "ok" and summary["trips"] == []
    assert cycles >= 290  # 3 s at 100 Hz
    assert link["bad_frames"] == 0 and link["samples_missed"] == 0 and link["timeouts"] == 0
    assert link["samples"] >= cycles  # every Command answered (and the shutdown's 0 A ones)
    assert link["safe_state_confirmed"]
    # QEMU models no RCC: the image's clock start-up meets what a dead crystal looks like, times out and
    # runs on the internal oscillator, and the host reports it
    assert link["clock_fallback"] == 1


def test_a_device_paced_run_on_the_image_streams_the_samples_on_the_boards_clock(board, tmp_path):
    summary = run(board, tmp_path / "device", "--duration", "2", "--set", "driver.pacing=device")
    link = summary["link"]
    assert summary["exit_status"] == "ok" and summary["trips"] == []
    assert link["bad_frames"] == 0 and link["samples_missed"] == 0 and link["timeouts"] == 0
    rows = (tmp_path / "device" / "data.csv").read_text().splitlines()
    column = rows[0].split(",").index("device_time_us")
    times = sorted({int(float(row.split(",")[column])) for row in rows[1:]})  # a cycle may reuse a sample
    # the board's clock paces: the typical step is exactly 10 ms of SysTick time. A sample QEMU sends
    # late (a busy host starved its vCPU, for up to 130 ms seen on this shared machine) is followed by
    # the next one on the grid, or, a whole period behind, by a new grid: the board does not burst
    steps = [b - a for a, b in itertools.pairwise(times)]
    assert len(steps) > 100 and min(steps) > 0 and statistics.median(steps) == 10_000


def test_a_quiet_host_gets_coil_and_road_rested_by_the_boards_watchdog(board):
    port = Port(board)
    try:
        port.send(Hello())
        port.wait(Version, 5.0)
        port.send(Configure(rate_hz=100, watchdog_ms=50, pacing=PACING_DEVICE))
        before = port.wait(Status, 5.0)
        assert isinstance(before, Status) and before.fault_code == 0
        assert before.flags == STATUS_CLOCK_FALLBACK  # the crystal's timeout (QEMU has no RCC), nothing else
        port.send(RoadSpeed(0.5), Command(0.5, CMD_ENABLE))
        driven = port.wait(Sample, 5.0)
        while isinstance(driven, Sample) and driven.current_a == 0.0:  # the sample after the Command
            driven = port.wait(Sample, 5.0)
        assert isinstance(driven, Sample) and driven.current_a == pytest.approx(0.5)
        started = time.monotonic()
        trip = port.wait(Status, 5.0)  # then nothing more from the host
        assert isinstance(trip, Status)
        assert trip.flags & FLAG_WATCHDOG and trip.watchdog_trips == before.watchdog_trips + 1
        assert time.monotonic() - started < 1.0  # 50 ms on the board's clock, whatever the host's delays
        rested = port.wait(Sample, 5.0)
        assert isinstance(rested, Sample) and rested.current_a == 0.0 and rested.flags & FLAG_WATCHDOG
        port.send(Configure(rate_hz=100, watchdog_ms=50, pacing=PACING_HOST))  # the next session clears it
        again = port.wait(Status, 5.0)
        assert isinstance(again, Status) and not again.flags & FLAG_WATCHDOG
    finally:
        port.close()


def test_the_images_instructions_per_sample_under_icount_are_counted_the_same_each_run(tmp_path):
    """tools/bench_firmware.py's QEMU part: -icount shift=0 makes virtual time count instructions, so
    the ARM image's cost per sample is the same number run after run, whatever the host's load."""
    if not qemu.available() or importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        pytest.skip("needs qemu-system-arm, make and the ziglang package")
    bench = load_tool("bench_firmware")
    first, second = bench.qemu_instructions(str(tmp_path)), bench.qemu_instructions(str(tmp_path))
    assert isinstance(first, float) and first == second
    assert 1000 < first < 6000  # decode a Command frame, encode a Sample frame: thousands, not more

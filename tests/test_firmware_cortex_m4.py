"""``make -C drivers/firmware cortex-m4``: the board's firmware for an STM32F4-class Cortex-M4F, built
with the zig C compiler of the ``ziglang`` package, checked in the ELF it produces."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from tool_module import load_tool

from sashil.drivers.firmware import elf

pytestmark = pytest.mark.e2e  # a cross build (seconds on a cold zig cache)

FIRMWARE = Path(elf.__file__).resolve().parent


@pytest.fixture(scope="module")
def firmware(tmp_path_factory) -> tuple[elf.Elf, str]:
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        pytest.skip("needs make and the ziglang package (pip install ziglang)")
    build = tmp_path_factory.mktemp("m4")
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE), "cortex-m4", f"PYTHON={sys.executable}", f"BUILD={build}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    return elf.read_elf(build / "cortex-m4" / "sashil-board.elf"), done.stdout


def test_the_elf_is_arm_with_its_vector_table_at_the_start_of_flash(firmware):
    image, _ = firmware
    flash_start, flash_size = elf.FLASH
    sram_start, sram_size = elf.SRAM
    assert image.data[:6] == b"\x7fELF\x01\x01"  # ELF32 (class 1), little-endian (data 1)
    assert image.machine == elf.EM_ARM
    initial_sp, reset = image.word_at(flash_start), image.word_at(flash_start + 4)
    assert sram_start < initial_sp <= sram_start + sram_size and initial_sp % 8 == 0
    assert reset == image.symbols["Reset_Handler"] | 1 or reset == image.symbols["Reset_Handler"]
    assert reset & 1 and flash_start <= reset < flash_start + flash_size  # Thumb code in flash
    assert image.entry == reset
    assert initial_sp == image.symbols["_estack"]
    usart1 = image.word_at(flash_start + 4 * (16 + 37))  # RM0090 table 61: USART1 is IRQ 37
    assert usart1 & ~1 == image.symbols["USART1_IRQHandler"] & ~1


def test_data_is_loaded_from_flash_into_sram_by_the_symbols_the_reset_handler_uses(firmware):
    image, _ = firmware
    flash_start, flash_size = elf.FLASH
    sram_start, sram_size = elf.SRAM
    s = image.symbols
    assert flash_start <= s["_sidata"] < flash_start + flash_size  # .data's initial values, in flash
    assert sram_start <= s["_sdata"] <= s["_edata"] <= s["_sbss"] <= s["_ebss"] < s["_estack"]
    assert s["_estack"] <= sram_start + sram_size
    assert all(s[k] % 4 == 0 for k in ("_sidata", "_sdata", "_edata", "_sbss", "_ebss"))  # word loops


def test_the_real_board_logic_is_linked_and_it_fits_the_part_with_room(firmware):
    image, printed = firmware
    for name in ("sashil_board_receive", "sashil_board_tick", "sashil_stream_feed", "main"):
        assert name in image.symbols, name
    assert image.flash_bytes() < 32 * 1024 and image.ram_bytes() < 8 * 1024  # the budget
    assert f"flash {image.flash_bytes()} B" in printed and f"RAM {image.ram_bytes()} B" in printed


def test_without_ziglang_make_says_so_in_one_line(tmp_path):
    if shutil.which("make") is None:
        pytest.skip("no make")
    bare = tmp_path / "python3"
    bare.write_text('#!/bin/sh\nexec /usr/bin/env python3 -I -S "$@"\n')  # no site-packages: no ziglang
    bare.chmod(0o755)
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE), "cortex-m4", f"PYTHON={bare}", f"BUILD={tmp_path / 'b'}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0
    assert "pip install ziglang" in done.stderr
    assert not (tmp_path / "b" / "cortex-m4" / "sashil-board.elf").exists()


def test_tools_elf_size_prints_what_make_printed(firmware, tmp_path):
    image, printed = firmware
    elf_file = tmp_path / "board.elf"
    elf_file.write_bytes(image.data)
    tool = Path(__file__).resolve().parents[1] / "tools" / "elf_size.py"
    env = {**os.environ, "SASHIL_KEEP_OUTPUT": "0"}  # a test's run keeps no record in tools/out/
    done = subprocess.run(
        [sys.executable, str(tool), str(elf_file)], capture_output=True, text=True, timeout=60, env=env
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split(": ", 1)[1] in printed


def test_the_firmware_answers_a_session_on_qemus_stm32f405(tmp_path):
    """tools/qemu_smoke.py on the SASHIL_QEMU build: Hello -> Version, Configure -> Status, Command ->
    Sample over USART1 (measured 60/60 runs passing with four runs in parallel, about 0.2 s each)."""
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        pytest.skip("needs make and the ziglang package (pip install ziglang)")
    if shutil.which("qemu-system-arm") is None:
        pytest.skip("needs qemu-system-arm (Debian: apt-get install qemu-system-arm)")
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE), "cortex-m4-qemu", f"PYTHON={sys.executable}", f"BUILD={tmp_path}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    qemu_smoke = load_tool("qemu_smoke")
    steps = qemu_smoke.smoke(tmp_path / "cortex-m4" / "sashil-board-qemu.elf", timeout_s=5.0)
    assert steps[0].startswith("Hello -> Version(protocol_version=2, counts_per_rev=4096, current_max_a=2.0)")
    assert len(steps) == 3


def test_the_can_build_links_the_bxcan_driver_into_its_vector_table(tmp_path):
    """make cortex-m4-can: CAN1's transmit and receive interrupts in the vector table, within budget."""
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        pytest.skip("needs make and the ziglang package (pip install ziglang)")
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE), "cortex-m4-can", f"PYTHON={sys.executable}", f"BUILD={tmp_path}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    image = elf.read_elf(tmp_path / "cortex-m4" / "sashil-board-can.elf")
    flash_start, _ = elf.FLASH
    for irq, name in ((19, "CAN1_TX_IRQHandler"), (20, "CAN1_RX0_IRQHandler")):  # RM0090 table 61
        assert image.word_at(flash_start + 4 * (16 + irq)) & ~1 == image.symbols[name] & ~1
    assert "hal_can_send" in image.symbols and "bxcan_pack" in image.symbols
    assert image.flash_bytes() < 32 * 1024 and image.ram_bytes() < 8 * 1024
    assert f"flash {image.flash_bytes()} B" in done.stdout

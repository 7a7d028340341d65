"""The C firmware under AddressSanitizer and UndefinedBehaviorSanitizer: malformed input never escapes.

``firmware_fuzz.c`` drives garbage of every length up to 2047 bytes through the COBS decoder, the
frame decoder, the byte stream decoder and the board behind a stub hardware interface (with a live
session between the garbage), and a good frame corrupted at every byte with every xor value; the
sanitizers abort on any out-of-bounds access or undefined behaviour, and the harness checks that every
bad frame was counted. Built as a separate executable (an ASan library cannot be loaded into an
uninstrumented Python). Skipped with the reason when there is no C compiler or no sanitizer runtime.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from sashil.drivers import firmware


def test_malformed_input_under_sanitizers(tmp_path: Path) -> None:
    cc = firmware.compiler()
    if cc is None:
        pytest.skip("no C compiler on this machine")
    exe = tmp_path / "fuzz"
    flags = ["-std=c99", "-g", "-O1", "-Wall", "-Wextra", "-pedantic", "-Werror"]
    flags += ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
    sources = [str(Path(__file__).with_name("firmware_fuzz.c"))] + [str(firmware.HERE / s) for s in firmware.SOURCES]
    built = subprocess.run(
        [cc, *flags, "-I", str(firmware.HERE), "-o", str(exe), *sources], capture_output=True, text=True, check=False
    )
    if built.returncode != 0 and "sanitize" in built.stderr:
        pytest.skip(f"{cc} has no sanitizer runtime here: {built.stderr.strip().splitlines()[-1]}")
    assert built.returncode == 0, built.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.startswith("ok frames=0 ")  # nothing good ever came out of garbage or corruption

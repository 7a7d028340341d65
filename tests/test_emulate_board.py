"""``sashil emulate --board``: the firmware's C logic or the Python board."""

from __future__ import annotations

import pytest

from sashil.cli import main
from sashil.drivers import firmware


def test_board_c_without_a_compiler_is_one_line_exit_2_and_no_link(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(firmware, "compiler", lambda: None)
    link = tmp_path / "rig"
    assert main(["emulate", "--board", "c", "--link", str(link), "--duration", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--board c: firmware: no C compiler found" in err[0] and "--board python" in err[0]
    assert not link.exists()


def test_board_c_whose_sources_do_not_build_says_what_the_compiler_said(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SASHIL_CACHE", str(tmp_path / "cache"))  # no cached library
    monkeypatch.setattr(firmware, "CFLAGS", (*firmware.CFLAGS, "-DSASHIL_BROKEN=", "-include", "/nonexistent.h"))
    assert main(["emulate", "--board", "c", "--duration", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "could not build the board's C code" in err[0] and "nonexistent.h" in err[0]


@pytest.mark.e2e  # the emulator runs for 0.1 s of wall clock
@pytest.mark.parametrize("has_cc, board", [(True, "c"), (False, "python")])
def test_board_auto_is_c_where_a_compiler_is_found(has_cc, board, capsys, monkeypatch):
    if has_cc and firmware.compiler() is None:  # pragma: no cover - the machine has no C compiler
        pytest.skip("no C compiler on this machine")
    if not has_cc:
        monkeypatch.setattr(firmware, "compiler", lambda: None)
    assert main(["emulate", "--duration", "0.1"]) == 0
    assert f"({board} board)" in capsys.readouterr().out

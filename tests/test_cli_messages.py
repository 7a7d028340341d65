"""One-line messages that name the cause: a sweep on a port that cannot be opened, simulate on a run
folder, a config section left empty by an indentation slip."""

from __future__ import annotations

import pytest

from sashil.cli import main


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    return err


@pytest.mark.parametrize("verb", [["sweep"], ["sweep", "--stepped"], ["run", "--duration", "1"]])
def test_a_port_that_cannot_be_opened_writes_nothing_and_says_only_why(tmp_path, capsys, verb):
    out = tmp_path / "S"
    assert main([*verb, "--driver", "serial", "--port", str(tmp_path / "no-port"), "--out", str(out), "-q"]) == 2
    err = _error(capsys)
    assert err.startswith(f"sashil {verb[0]}: error: serial port {tmp_path / 'no-port'}: cannot open (")
    assert "ended early" not in err and "run folder" not in err
    assert not out.exists()


def test_simulate_takes_a_run_folder(tmp_path, capsys):
    drop = tmp_path / "D"
    assert main(["drop-test", "--duration", "2", "--out", str(drop), "-q"]) == 0
    capsys.readouterr()
    assert main(["simulate", "--input", str(drop), "--out", str(tmp_path / "S")]) == 0
    assert f"on {drop / 'data.csv'}" in capsys.readouterr().out


def test_simulate_on_a_folder_of_runs_names_them(tmp_path, capsys):
    drop = tmp_path / "D"
    assert main(["drop-test", "--current", "0", "--current", "1", "--duration", "1", "--out", str(drop), "-q"]) == 0
    capsys.readouterr()
    out = tmp_path / "S"
    assert main(["simulate", "--input", str(drop), "--out", str(out)]) == 2
    assert _error(capsys) == (
        f"sashil simulate: error: --input {drop}: a folder of 2 runs (i0.000A, i1.000A); simulate takes one, "
        f"e.g. --input {drop / 'i0.000A'}"
    )
    assert main(["simulate", "--input", str(tmp_path), "--out", str(out)]) == 2  # no data.csv in it
    assert not out.exists()


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "controller:\nlaw: skyhook\nc_sky: 2\n",
            "controller: expected a mapping, got nothing (law, c_sky follow it at its level: indent them under controller:)",
        ),
        ("loop:\nrate_hz: 500\n", "loop: expected a mapping, got nothing (rate_hz follows it at its level"),
        ("model:\n  params:\n  k: 100\n", "model.params: expected a mapping, got nothing (k follows it at its level"),
        ("loop:\nfoo: 1\n", "foo: unknown key (known keys here:"),  # not a loop key: not the empty section's
        ("controller:\nloop:\n  rate_hz: 500\nlaw: skyhook\n", "law: unknown key (known keys here:"),
    ],
)
def test_an_empty_section_with_its_keys_unindented_says_so(tmp_path, capsys, text, message):
    config = tmp_path / "c.yaml"
    config.write_text(text)
    out = tmp_path / "R"
    assert main(["drop-test", "--config", str(config), "--out", str(out)]) == 2
    assert f"{config}: {message}" in _error(capsys)
    assert not out.exists()

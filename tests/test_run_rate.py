"""--rate reaches the device (Configure) and the controller, and is checked before anything runs."""

from __future__ import annotations

import json

import pytest

from sashil.cli import main
from sashil.drivers.emulator import EmulatorThread
from sashil.engine.resolve import default_config


def test_an_impossible_rate_is_one_line_exit_2_and_no_folder(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "--driver", "serial", "--port", "/dev/null", "--rate", "1e9", "--duration", "0.1", "--out", str(out)]
    assert main(argv) == 2  # refused before the port is opened
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(errors) == 1 and "--rate: loop.rate_hz: expected a number > 0 and <= 20000, got 1000000000" in errors[0]
    assert not out.exists()


@pytest.mark.e2e
def test_the_rate_is_configured_on_the_device(tmp_path):
    with EmulatorThread(default_config(), "serial", channel="t-rate") as emu:
        out = tmp_path / "run"
        code = main(
            [
                "run", "--driver", "serial", "--port", emu.port, "--rate", "500", "--duration", "0.4",
                "--set", "driver.sample_timeout_ms=200", "--set", "driver.link_lost_ms=2000",
                "--set", "driver.max_lost_fraction=1", "--set", "loop.max_missed_fraction=1",  # the emulator shares this process
                "--out", str(out), "-q",
            ]
        )  # fmt: skip
        assert code == 0
        assert emu.device.rate_hz == 500  # Configure carried --rate
    summary = json.loads((out / "summary.json").read_text())
    assert summary["timing"]["rate_hz"] == 500.0

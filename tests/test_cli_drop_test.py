"""``sashil drop-test`` end to end on the simulated rig, and its bad-input handling."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from sashil.cli import main
from sashil.drivers import rig_parts
from sashil.recording.data_file import REQUIRED_COLUMNS, read_data_csv


def test_single_current_run_folder(tmp_path, capsys):
    out = tmp_path / "D"
    assert main(["drop-test", "--current", "0", "--out", str(out)]) == 0
    names = ["config.yaml", "cycles.csv", "data.csv", "drop_test.png", "summary.json"]
    assert sorted(p.name for p in out.iterdir()) == names
    data = read_data_csv(out / "data.csv", required=REQUIRED_COLUMNS)
    assert data["time_s"][0] == 0.0
    assert data["time_s"][-1] == pytest.approx(10.0)
    assert data["theta_rad"][0] == pytest.approx(math.radians(-5.0), abs=2 * math.pi / 4096)
    # the runner's stream of every cycle: the hold before the release, then the same drop
    cycles = read_data_csv(out / "cycles.csv", required=REQUIRED_COLUMNS)
    held = int(np.argmax(np.abs(cycles["theta_rad"] - cycles["theta_rad"][0]) > 1e-9))
    assert held > 100 and cycles["time_s"][held] > 0.3  # held still for the hold time first
    assert cycles["time_s"].size > data["time_s"].size + 250  # the record from the release, plus the hold
    moving = cycles["theta_rad"][held:]
    assert np.max(moving) == pytest.approx(np.max(data["theta_rad"]), abs=1e-12)  # the same first peak
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "ok"
    (run,) = summary["runs"]
    assert run["current_a"] == 0.0
    for key in ("timing", "link", "realtime", "can_trace"):  # one run: its loop's keys at the top too
        assert key in summary and summary[key] == run[key], key
    assert run["period_s"] == pytest.approx(0.600, rel=0.01)
    assert run["frequency_hz"] == pytest.approx(1 / run["period_s"])
    assert len(run["peaks_deg"]) >= 5 and run["peaks_deg"][0] == pytest.approx(4.40, abs=0.05)
    assert 0 < run["settling_time_s"] < 10
    assert (out / "drop_test.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    err = capsys.readouterr().err
    assert "period 0.60" in err or "period 0.59" in err
    assert f"run folder: {out}" in err


def test_several_currents_have_one_subfolder_each(tmp_path):
    out = tmp_path / "D"
    assert main(["drop-test", "--current", "0", "--current", "1", "--duration", "3", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [r["folder"] for r in summary["runs"]] == ["i0.000A", "i1.000A"]
    for folder in ("i0.000A", "i1.000A"):
        assert (out / folder / "data.csv").exists() and (out / folder / "summary.json").exists()
    zero, one = summary["runs"]
    assert one["peaks_deg"][0] < zero["peaks_deg"][0]
    assert summary["timing"] is None and summary["can_trace"] is None  # each sub-run has its own
    sub = json.loads((out / "i1.000A" / "summary.json").read_text())
    assert sub["timing"] == one["timing"] and "can_trace" in sub


@pytest.mark.parametrize(
    "args,message",
    [
        (["--duration", "-1"], "--duration: drop_test.duration_s: expected a number > 0, got -1"),
        (["--theta0-deg", "31"], "--theta0-deg: drop_test.theta0_deg: expected a number >= -30 and <= 30, got 31"),
        (["--theta0-deg", "0.2"], "--theta0-deg: expected an angle at least drop_test.release_threshold_deg"),
        (["--current", "1.5"], "--current: expected a current in [0, 1] A (rig.current_max_a), got 1.5"),
        (["--current", "-0.1"], "--current: expected a current in [0, 1] A"),
        (["--duration", "nan"], "--duration: drop_test.duration_s: expected a number > 0"),
        (["--current", "0.5", "--current", "0.5"], "--current: each current once, got [0.5, 0.5]"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "D"
    assert main(["drop-test", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not out.exists()


def test_bad_config_key_exit_2_and_write_nothing(tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    config.write_text("rig:\n  coil_tau_z: 0.01\n")
    out = tmp_path / "D"
    assert main(["drop-test", "--config", str(config), "--out", str(out)]) == 2
    assert "bad.yaml: rig.coil_tau_z: unknown key" in capsys.readouterr().err
    assert not out.exists()


def test_console_script_help_and_usage_errors():
    help_text = subprocess.run(
        [sys.executable, "-m", "sashil", "drop-test", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "--theta0-deg" in help_text and "example:" in help_text
    bad = subprocess.run(
        [sys.executable, "-m", "sashil", "drop-test", "--duration", "x"], capture_output=True, text=True
    )
    assert bad.returncode == 2
    assert "invalid float value" in bad.stderr and bad.stderr.count("\n") <= 2


class _FailingRig:
    """A simulated rig whose link dies on the Nth read (as a cable pulled mid-test)."""

    def __init__(self, rig, fail_on: int):
        self.rig, self.fail_on, self.reads = rig, fail_on, 0
        self.currents: list[float] = []
        self.deactivated = self.closed = 0

    def __getattr__(self, name):
        return getattr(self.rig, name)

    def read(self, t_ns, dt_ns):
        self.reads += 1
        if self.reads == self.fail_on:
            from sashil.errors import DriverIOError

            raise DriverIOError("serial /dev/ttyACM0: device disconnected")
        return self.rig.read(t_ns, dt_ns)

    def write(self, cmd, t_ns, dt_ns):
        self.currents.append(cmd.current_a)
        self.rig.write(cmd, t_ns, dt_ns)

    def deactivate(self):
        self.deactivated += 1
        self.rig.deactivate()

    def close(self):
        self.closed += 1
        self.rig.close()


def test_a_link_failure_mid_test_keeps_the_data_and_ends_at_zero_amps(config):
    from sashil.drivers import open_rig
    from sashil.lab._drop_test import run_drop_test

    rig = _FailingRig(open_rig(rig_parts(config)), fail_on=1300)  # 0.3 s hold, then ~1 s of oscillation
    record = run_drop_test(config, -5.0, 1.0, 10.0, rig=rig)
    assert record.error is not None and "device disconnected" in str(record.error)
    assert record.summary["exit_status"] == "error"
    assert 0.9 < record.data["time_s"][-2] < 1.0  # the data up to the fault is kept,
    assert record.data["current_cmd_a"][-1] == 0.0  # then the 0 A the shutdown sent
    assert rig.currents[-1] == 0.0  # the safe command went out last
    assert (rig.deactivated, rig.closed) == (1, 1)
    assert rig.rig._command == 0.0  # and the simulated coil is driven to 0 A


def test_the_configs_controller_takes_over_at_the_release(tmp_path):
    config = tmp_path / "td.yaml"
    config.write_text("controller:\n  law: target-damping\n  zeta: 0.07\n")
    out = tmp_path / "D"
    assert main(["drop-test", "--config", str(config), "--current", "0.5", "--duration", "6", "--out", str(out)]) == 0
    (run,) = json.loads((out / "summary.json").read_text())["runs"]
    # target damping: each cycle decays like a linear damper of zeta 0.07 (log decrement 2 pi zeta / sqrt(1 - zeta^2))
    target = 2 * math.pi * 0.07 / math.sqrt(1 - 0.07**2)
    assert len(run["log_decrements"]) >= 4
    assert all(abs(d / target - 1) < 0.1 for d in run["log_decrements"])
    data = read_data_csv(out / "data.csv", required=REQUIRED_COLUMNS)
    assert (
        0.0 < data["current_cmd_a"].max() <= 1.0 and data["current_cmd_a"].min() == 0.0
    )  # the law modulates the current
    # the controller's own signals are recorded, and the held arm gave the estimator no false motion
    assert {"theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm"} <= set(data)
    assert abs(data["theta_dot_rad_s"][0]) < 0.01

"""``sashil run``: bad input (one line, exit 2, nothing created) and real-clock runs in a subprocess."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from sashil.cli import main
from sashil.recording.data_file import read_data_csv

QUIET_RT = "loop:\n  rt:\n    priority: 0\n    mlockall: false\n"
CLI = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main())", "run"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--rate", "0"], "--rate: loop.rate_hz: expected a number > 0 and <= 20000, got 0"),
        (["--rate", "-5"], "--rate: loop.rate_hz: expected a number > 0 and <= 20000, got -5"),
        (["--rate", "15000"], "--rate: 15000 Hz is above what the sim backend can do (10000 Hz)"),
        (["--duration", "-1"], "--duration: run.duration_s: expected a number > 0 or null, got -1"),
        (["--set", "driver.clock=virtual"], "driver.clock: virtual: sashil run runs on the real clock"),
        (["--controller", "no-such-law"], "no-such-law"),
        (
            ["--current", "3"],
            "--current: controller.current_a: expected a current in [0, 1] A (rig.current_max_a), got 3",
        ),
        (["--controller", "skyhook", "--current", "0.5"], "--current: only for --controller passive"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    code = main(["run", *argv, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and message in err
    assert not out.exists()


def test_unknown_config_key_is_exit_2(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("safety:\n  sensor_timeout_cycles: 0\n")
    assert main(["run", "--config", str(cfg), "--duration", "1", "--out", str(tmp_path / "o")]) == 2
    assert "safety.sensor_timeout_cycles: expected an integer >= 1" in capsys.readouterr().err


def _config(tmp_path, extra=""):
    cfg = tmp_path / "rt.yaml"
    cfg.write_text(QUIET_RT + extra)
    return str(cfg)


@pytest.mark.e2e
def test_short_real_clock_run_writes_a_complete_folder(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [*CLI, "--config", _config(tmp_path), "--duration", "0.3", "--current", "0.4", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "ok" and summary["timing"]["cycles"] == 300
    assert summary["realtime"]["sched_fifo"]["status"] == "skipped"
    data = read_data_csv(out / "data.csv", required=("time_s", "theta_rad", "current_a", "current_cmd_a"))
    assert len(data["time_s"]) == 300 + 1 and set(data["current_cmd_a"][:-1]) == {0.4}
    assert data["current_cmd_a"][-1] == 0.0  # the stream ends on the safe state the shutdown sent
    assert "clock: real" in (out / "config.yaml").read_text()
    assert "lateness" in proc.stderr and "missed deadline" in proc.stderr


@pytest.mark.e2e
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_during_a_real_clock_run_leaves_a_complete_folder(tmp_path, sig):
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [*CLI, "--config", _config(tmp_path), "--current", "0.3", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        data_file = out / "data.csv"
        while time.monotonic() < deadline and (not data_file.exists() or data_file.stat().st_size < 5000):
            time.sleep(0.05)
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "stopped" and summary["stop_reason"] == sig.name
    assert summary["exit_code"] == 130
    data = read_data_csv(out / "data.csv", required=("time_s", "theta_rad", "current_a", "current_cmd_a"))
    assert len(data["time_s"]) == summary["timing"]["cycles"] + 1 == summary["recording"]["rows_written"]
    assert data["current_cmd_a"][-1] == 0.0  # the safe state's row after the last cycle
    assert (out / "config.yaml").exists()
    assert f"stopped by {sig.name}" in stderr


@pytest.mark.parametrize("driver", ["serial", "can"])
def test_a_port_that_cannot_be_opened_is_refused_before_any_output(tmp_path, capsys, driver):
    out = tmp_path / "out"
    code = main(
        ["run", "--driver", driver, "--port", str(tmp_path / "NO-SUCH-TTY"), "--duration", "1", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "cannot open" in err, err  # no set-up lines, no timing table
    assert not out.exists()

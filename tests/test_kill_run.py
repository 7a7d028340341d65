"""Crash safety: SIGKILL during `sashil run` leaves a data.csv that parses, ending within 1 s of the kill.

End to end with a subprocess on the real clock (so it waits on real time, with generous timeouts).
The run's time zero is taken from the moment its `realtime:` set-up lines arrive on stderr (printed
right before the loop starts); the kill comes 2.5 s later by the test's clock (both
CLOCK_MONOTONIC). The last row in data.csv must be within 1 s of the run time at the kill.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from sashil.recording.data_file import REQUIRED_COLUMNS, read_data_csv

pytestmark = pytest.mark.e2e  # wall clock, real pty/link/processes: `pytest -m "not e2e"` skips them

KILL_AFTER_S = 2.5


@pytest.mark.skipif(sys.platform != "linux", reason="SIGKILL end-to-end test needs Linux")
def test_sigkill_during_run_leaves_a_parseable_data_csv_ending_within_1s(tmp_path):
    out = tmp_path / "R"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", "run", "--duration", "60", "--current", "0.5", "--out", str(out)],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        started = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stderr.readline()  # type: ignore[union-attr]
            if not line:
                break
            if line.startswith("realtime:"):
                started = time.monotonic()  # the loop starts right after these lines
                break
        assert started is not None, "sashil run did not start its loop"
        time.sleep(KILL_AFTER_S)
        killed_at = time.monotonic() - started
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not (out / "summary.json").exists()  # it really died mid-run
    data = read_data_csv(out / "data.csv", required=REQUIRED_COLUMNS)
    last = float(data["time_s"][-1])
    assert last <= killed_at + 0.05  # nothing from after the kill (50 ms for the start-line latency)
    assert killed_at - last <= 1.0, f"data.csv ends {killed_at - last:.3f} s before the kill"
    assert (data["current_cmd_a"] == 0.5).all()

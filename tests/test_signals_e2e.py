"""SIGINT, SIGTERM and SIGHUP stop every rig verb cleanly: data kept, summary written, exit 130."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e

REAL_CLOCK = ["--set", "driver.clock=real"]


def _stop_when_running(args: list[str], out: Path, sig: int) -> subprocess.CompletedProcess:
    """Start ``sashil ARGS --out OUT -v`` on the real clock; once its loop says it is running, send
    ``sig``; return the finished process."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", *args, *REAL_CLOCK, "--out", str(out), "-v"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: queue.Queue[str] = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr], daemon=True)  # type: ignore[union-attr]
    reader.start()
    seen = []
    try:
        while True:
            line = lines.get(timeout=120)
            seen.append(line)
            if line.startswith("loop: running"):
                break
        time.sleep(0.3)  # some cycles into the loop
        proc.send_signal(sig)
        stdout = proc.stdout.read() if proc.stdout else ""
        proc.wait(timeout=60)
        reader.join(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    while not lines.empty():
        seen.append(lines.get())
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, "".join(seen))


def _rows(path: Path) -> int:
    return len(path.read_text().splitlines()) - 1


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_during_a_drop_test_keeps_its_data_and_summary(tmp_path, sig):
    out = tmp_path / "drop"
    done = _stop_when_running(["drop-test", "--duration", "30"], out, sig)
    assert done.returncode == 130, done.stderr
    assert len([line for line in done.stderr.splitlines() if "error" in line]) <= 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "stopped" and summary["exit_code"] == 130
    assert summary["runs"][0]["exit_status"] == "stopped"
    assert (out / "data.csv").exists()


def test_sighup_during_a_sweep_keeps_its_data_and_summary(tmp_path):
    out = tmp_path / "sweep"
    done = _stop_when_running(["sweep", "--f-start", "1", "--f-stop", "1", "--duration", "30"], out, signal.SIGHUP)
    assert done.returncode == 130, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "stopped" and "SIGHUP" in summary["error"]
    assert _rows(out / "data.csv") > 100  # what ran before the signal (0.5 s and more at 1 kHz)


def test_sighup_during_a_run_writes_its_summary(tmp_path):
    out = tmp_path / "run"
    done = _stop_when_running(["run", "--duration", "30", "--current", "0.3"], out, signal.SIGHUP)
    assert done.returncode == 130, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "stopped"
    assert _rows(out / "data.csv") > 100


@pytest.mark.parametrize(
    "verb", [["drop-test", "--duration", "30"], ["sweep", "--f-start", "1", "--f-stop", "1", "--duration", "30"]]
)
def test_after_kill_9_of_the_session_its_loop_process_ends_the_run_with_every_row_on_disk(tmp_path, verb):
    # a drop's or a sweep's loop runs in its own process: it sees its session die within a cycle,
    # stops at 0 A, writes the rows the recorder had not, and the run's summary saying so
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", *verb, *REAL_CLOCK, "--out", str(out), "-v"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        for line in proc.stderr:  # type: ignore[union-attr]
            if line.startswith("loop: running"):
                break
        time.sleep(1.0)
        proc.kill()
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()  # type: ignore[union-attr]
    deadline = time.monotonic() + 30
    while not (out / "summary.json").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["verb"] == verb[0] and summary["exit_status"] == "error"
    assert summary["stop_reason"] == "the session process died"
    lines = (out / "cycles.csv").read_text().splitlines()
    last = dict(zip(lines[0].split(","), lines[-1].split(","), strict=True))
    settled = summary["safe_state"]["reads"]  # rows read at 0 A while the coil's current decayed
    assert len(lines) - 1 == summary["timing"]["cycles"] + settled + 1  # every cycle, then the safe state's row
    assert float(last["current_cmd_a"]) == 0.0 and float(last["road_speed_cmd_rad_s"]) == 0.0


def test_a_burst_of_sigterms_stops_the_emulator(tmp_path):
    # pkill and a supervising `timeout` both signal it: the second signal must not deadlock the first
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", "emulate", "--link", str(tmp_path / "rig"), "--duration", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert "rig on /dev/" in proc.stdout.readline()  # type: ignore[union-attr]
        for _ in range(50):
            proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            pytest.fail("sashil emulate hung after a burst of SIGTERM")
        proc.stdout.close()  # type: ignore[union-attr]
        proc.stderr.close()  # type: ignore[union-attr]
    assert not (tmp_path / "rig").exists()  # its link removed on the way out

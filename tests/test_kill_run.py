"""Crash safety: SIGKILL of `sashil run` puts the coil at rest within 0.1 s, its loop ending the run alone.

End to end on the real clock: the session is a subprocess, its loop a process forked from the
session's loop server; the loop runs a second at 0.8 A, then the session gets SIGKILL. The loop
process must see its session's death at once (sashil.runtime.orphan.SessionWatch), stop at 0 A
and read on until the coil's current is at rest, then write the rest of the rows and the summary
itself; the loop server ends too. Times are on CLOCK_MONOTONIC from the kill: the record's
``time_s`` counts from the loop's start, ``summary.json``'s ``loop_process.start_ns``. Over serial
against the emulated C board, the coil's true current is the emulator's truth log, joined with
the record on the samples' ``seq``. The loop runs with the configured real-time set-up (SCHED_FIFO
where the process may), as at the bench.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import children, running_loop

from sashil.drivers.firmware import compiler
from sashil.recording.data_file import REQUIRED_COLUMNS, read_data_csv
from sashil.runtime.loop import SAFE_CURRENT_A, SETTLE_PHASE
from sashil.runtime.mailbox import SESSION_DIED

# wall clock, real processes; `alone`: it judges how soon after the kill the coil rests
pytestmark = [
    pytest.mark.e2e,
    pytest.mark.alone,
    pytest.mark.skipif(sys.platform != "linux", reason="a loop process and SIGKILL end to end need Linux"),
]

#: the bound: the coil at rest this soon after the kill [s]
REST_WITHIN_S = 0.1
#: the loop server ends this soon after its session [s] (it leaves at once; a loaded machine schedules it late)
SERVER_WITHIN_S = 0.5
CURRENT_A = 0.8
BACKENDS = ["sim", pytest.param("serial-c", marks=pytest.mark.skipif(compiler() is None, reason="no C compiler"))]


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended and not yet reaped by its new parent, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _kill_the_session(out: Path, *args: str) -> tuple[int, dict[str, int]]:
    """``sashil run`` whose session gets SIGKILL a second into the loop; the kill's time [ns] and
    when its loop server and loop process were seen ended [ns] (the session itself waited for)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "sashil", "run", "--duration", "30", "--current", str(CURRENT_A), "--out", str(out),
         "-v", *args],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        loop = running_loop(proc)
        (server,) = children(proc.pid)
        time.sleep(1.0)  # the coil at 0.8 A
        killed = time.monotonic_ns()
        proc.kill()
        ended: dict[str, int] = {}
        while len(ended) < 2 and time.monotonic_ns() - killed < 30e9:
            for name, pid in (("server", server), ("loop", loop)):
                if name not in ended and not _running(pid):
                    ended[name] = time.monotonic_ns()
            time.sleep(0.001)  # polling other processes' ends, 1 ms apart
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()  # type: ignore[union-attr]
    assert proc.returncode == -signal.SIGKILL
    assert set(ended) == {"server", "loop"}, f"outlived their session by 30 s: {set(('server', 'loop')) - set(ended)}"
    return killed, ended


def _at_rest_from(current: np.ndarray) -> int:
    """The index from which on every ``current`` is at rest (at most SAFE_CURRENT_A)."""
    above = np.flatnonzero(np.abs(current) > SAFE_CURRENT_A)
    return int(above[-1]) + 1 if above.size else 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_kill_9_of_the_session_puts_the_coil_at_rest_within_0_1_s(tmp_path, backend):
    emulator = None
    args: tuple[str, ...] = ()
    if backend == "serial-c":
        from test_link_e2e import Emulator, relaxed_config

        emulator = Emulator(tmp_path, "serial", "c", "--truth", str(tmp_path / "truth.csv"))
        args = ("--driver", "serial", "--port", emulator.link, "--config", relaxed_config(tmp_path))
    out = tmp_path / "run"
    try:
        killed, ended = _kill_the_session(out, *args)
    finally:
        if emulator is not None:
            emulator.stop()
    assert (ended["server"] - killed) * 1e-9 <= SERVER_WITHIN_S, "the loop server outlived its session"

    summary = json.loads((out / "summary.json").read_text())  # written by the loop process alone
    assert summary["exit_status"] == "error" and summary["stop_reason"] == SESSION_DIED
    assert summary["loop_process"]["session_died"] is True and summary["safe_state"]["confirmed"]
    data = read_data_csv(out / "data.csv", required=REQUIRED_COLUMNS)
    cycles = summary["timing"]["cycles"]
    assert len(data["time_s"]) == cycles + summary["safe_state"]["reads"] + 1  # every row, then the safe state's
    if emulator is None:  # the simulated rig's samples: one a cycle (a link may lose some)
        assert np.all(np.diff(data["seq"][:-1]) == 1)

    after_s = (summary["loop_process"]["start_ns"] + data["time_s"] * 1e9 - killed) * 1e-9
    assert after_s[cycles - 1] < 0.05  # the loop ran until the kill (its last cycle within 50 ms of it)
    assert np.all(data["current_cmd_a"][:cycles] == CURRENT_A)  # ... at 0.8 A
    settle = slice(cycles, cycles + summary["safe_state"]["reads"])
    assert np.all(data["phase"][settle] == SETTLE_PHASE) and np.all(data["current_cmd_a"][cycles:] == 0.0)
    rest = _at_rest_from(data["current_a"])
    assert rest >= cycles  # the coil rested only after the loop commanded 0 A
    assert after_s[rest] <= REST_WITHIN_S, f"the coil at rest {after_s[rest]:.3f} s after the kill"

    if emulator is not None:  # the board's own coil: its true current, sample by sample, on the host's clock
        truth = read_data_csv(tmp_path / "truth.csv", required=("seq", "device_time_us", "current_true_a"))
        truth_ns = _on_the_host_s_clock(truth, data, summary["loop_process"]["start_ns"])
        true_rest = _at_rest_from(truth["current_true_a"])
        assert true_rest < len(truth_ns), "the board's coil was not at rest when the emulator stopped"
        true_after_s = (truth_ns[true_rest] - killed) * 1e-9
        assert true_after_s <= REST_WITHIN_S, f"the true coil at rest {true_after_s:.3f} s after the kill"


def _on_the_host_s_clock(truth: dict[str, np.ndarray], data: dict[str, np.ndarray], start_ns: int) -> np.ndarray:
    """The truth log's samples on the host's CLOCK_MONOTONIC [ns]: the board's clock shifted by the
    median of (host row time - device time) over the samples both hold (joined on ``seq``)."""
    device_ns = {int(seq): int(us) * 1000 for seq, us in zip(truth["seq"], truth["device_time_us"], strict=True)}
    host_ns = start_ns + np.round(data["time_s"] * 1e9)
    shifts = [
        host - device_ns[int(seq)] for seq, host in zip(data["seq"], host_ns, strict=True) if int(seq) in device_ns
    ]
    return truth["device_time_us"] * 1000 + np.median(shifts)

"""CAN frame traces (``--format blf|asc|log|mf4``): python-can's writers fed off the hot path."""

from __future__ import annotations

import importlib.util
import itertools
import json
import signal
import subprocess
import sys
import time

import can
import numpy as np
import pytest

from sashil.drivers.can_codec import ID_ROAD_SPEED
from sashil.errors import ConfigError
from sashil.recording.can_trace import CanTrace


def _frames(n: int) -> list[can.Message]:
    out = []
    for k in range(n):
        rx = k % 3 != 0
        out.append(
            can.Message(
                timestamp=1_700_000_000.0 + k * 1e-3,
                arbitration_id=0x111 if rx else 0x100,
                data=bytes([k & 0xFF, 1, 2, 3, 4]),
                is_extended_id=False,
                is_rx=rx,
            )
        )
    return out


FORMATS = ["blf", "asc", "log"] + (["mf4"] if importlib.util.find_spec("asammdf") else [])


@pytest.mark.parametrize("fmt", FORMATS)
def test_trace_writes_every_frame_in_order_with_direction_and_time(tmp_path, fmt):
    sent = _frames(500)
    trace = CanTrace([tmp_path / f"can.{fmt}"], interval_s=0.01).start()
    for msg in sent[:250]:
        trace.put(msg)
    time.sleep(0.03)  # the writer thread drains while frames keep coming
    for msg in sent[250:]:
        trace.put(msg)
    stats = trace.close()
    assert stats["frames_rx"] + stats["frames_tx"] == 500 and stats["error"] is None
    back = list(can.LogReader(str(tmp_path / f"can.{fmt}")))
    assert [m.arbitration_id for m in back] == [m.arbitration_id for m in sent]
    assert [bytes(m.data) for m in back] == [bytes(m.data) for m in sent]
    if fmt != "log":  # candump's format has no direction for received frames of other nodes
        assert [m.is_rx for m in back] == [m.is_rx for m in sent]
    steps = [b.timestamp - a.timestamp for a, b in itertools.pairwise(back)]
    assert all(step == pytest.approx(1e-3, abs=2e-5) for step in steps)
    assert trace._thread is None  # no thread left behind


def test_attach_refuses_a_backend_without_can_frames(tmp_path):
    class NotCan:
        name = "serial"

    with pytest.raises(ConfigError, match="the serial backend has no CAN frames"):
        CanTrace([tmp_path / "can.blf"]).attach(NotCan())


SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]


@pytest.fixture
def slcan_rig(tmp_path):
    """``sashil emulate --transport slcan`` in its own process; yields the link path, stops it after."""
    link = str(tmp_path / "rig-slcan")
    proc = subprocess.Popen(
        [*SASHIL, "emulate", "--transport", "slcan", "--link", link, "--duration", "120"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()  # "sashil emulate: slcan rig on /dev/pts/N (link ...)"
        assert "rig on /dev/" in line, line + proc.stderr.read()
        yield link
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)


@pytest.mark.e2e  # the emulator in its own process, a run on the wall clock over a pty
def test_run_over_slcan_traces_both_directions(tmp_path, slcan_rig):
    out = tmp_path / "run"
    config = tmp_path / "link.yaml"  # a loaded machine may starve the emulator: relaxed link timeouts and budgets
    config.write_text(
        "driver:\n  sample_timeout_ms: 250.0\n  link_lost_ms: 500.0\n  max_lost_fraction: 1.0\n"
        "loop:\n  max_missed_fraction: 1.0\n  rt:\n    priority: 0\n    mlockall: false\n"
    )
    done = subprocess.run(
        [*SASHIL, "run", "--driver", "can", "--port", slcan_rig, "--config", str(config), "--duration", "0.5",
         "--current", "0.3", "--road", "sine:2:1", "--format", "blf", "--format", "asc", "--out", str(out), "-q"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    stats = summary["can_trace"]
    assert stats["files"] == ["can.blf", "can.asc"] and stats["error"] is None and stats["frames_dropped"] == 0
    assert summary["loop_process"]["threads"] == 1  # the frames crossed the stream to the session's writer
    for name in stats["files"]:
        frames = list(can.LogReader(str(out / name)))
        assert len(frames) == stats["frames_rx"] + stats["frames_tx"]
        tx = [m for m in frames if not m.is_rx]
        rx = [m for m in frames if m.is_rx]
        assert len(tx) >= 500 and len(rx) >= 2 * 450  # a command per cycle; two frames per sample
        assert {m.arbitration_id for m in rx} >= {0x110, 0x111}  # the sample frames
        assert ID_ROAD_SPEED in {m.arbitration_id for m in tx}  # road speed commands went out (--road over a link)
    import sashil

    road = sashil.load_run(out).data["theta_road_rad"]
    assert np.ptp(road) > np.radians(0.2)  # the emulated road wheel followed the profile


@pytest.mark.e2e  # the emulator in its own process, a drop test on the wall clock over a pty
@pytest.mark.alone  # a drop test over slcan at the default sample timeout (2.5 ms) and link-lost time
def test_a_single_current_can_drop_test_puts_its_trace_at_the_top_of_the_summary(tmp_path):
    link = str(tmp_path / "rig-slcan")
    emulator = subprocess.Popen(
        [*SASHIL, "emulate", "--transport", "slcan", "--link", link, "--duration", "120", "--hold-deg", "-5",
         "--release-after", "0.5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        line = emulator.stdout.readline()
        assert "rig on /dev/" in line, line + emulator.stderr.read()
        out = tmp_path / "drop"
        done = subprocess.run(
            [*SASHIL, "drop-test", "--driver", "can", "--port", link, "--duration", "1", "--format", "asc",
             "--out", str(out), "-q"],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        if emulator.poll() is None:
            emulator.send_signal(signal.SIGTERM)
        emulator.communicate(timeout=30)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    (run,) = summary["runs"]
    assert summary["can_trace"] == run["can_trace"] and summary["can_trace"]["files"] == ["can.asc"]
    assert summary["can_trace"]["frames_rx"] > 0 and summary["link"] == run["link"] is not None


def test_a_failing_writer_ends_the_trace_not_the_run_and_the_queue_stays_bounded(tmp_path):
    trace = CanTrace([tmp_path / "can.asc"], interval_s=0.005).start()

    class Broken:
        def on_message_received(self, msg):
            raise OSError(28, "No space left on device")

        def stop(self):
            pass

    trace._loggers.append(Broken())
    frames = _frames(100)
    for msg in frames[:50]:
        trace.put(msg)
    deadline = time.monotonic() + 5
    while trace.error is None and time.monotonic() < deadline:
        time.sleep(0.005)
    for msg in frames[50:]:  # the cycle keeps handing frames over; they are counted and dropped
        trace.put(msg)
    stats = trace.close()
    assert stats["error"] == "OSError: [Errno 28] No space left on device"
    assert stats["frames_rx"] + stats["frames_tx"] + stats["frames_dropped"] == 100
    assert stats["frames_dropped"] >= 50 and not trace._queue

"""The run's stream: the shared ring the loop process writes and the session reads (no processes here)."""

from __future__ import annotations

import math
import os
import signal

import numpy as np
import pytest

from sashil.control.law_api import Law, Param
from sashil.drivers import rig_parts
from sashil.errors import RecordingError
from sashil.runtime.mailbox import SESSION_DIED, LoopStop, MailboxTuning
from sashil.runtime.orphan import SessionWatch
from sashil.runtime.signals import StopFlag
from sashil.runtime.stream import (
    COMMITTED_W,
    LOOP_PID_W,
    RECORDED_W,
    RECORDER_W,
    SESSION_PID_W,
    STOP_BY_CALLER,
    STOP_W,
    Stream,
    StreamFull,
    StreamWriter,
    remove_stale,
)
from sashil.runtime.stream_recorder import StreamRecorder, format_block
from sashil.runtime.timing import TimingStats

COLUMNS = ("time_s", "theta_rad", "seq", "phase")


@pytest.fixture
def stream(tmp_path):
    made = Stream.create(COLUMNS, capacity=8, window=4096, folder=tmp_path)
    yield made
    made.close()


def _commit(writer: StreamWriter, k: int) -> None:
    row = writer.begin_row()
    row[0], row[1], row[2], row[3] = k * 1e-3, -0.1 * k, k, 2
    writer.commit_row()


def test_a_stream_is_allocated_whole_and_named_for_its_session(tmp_path, stream):
    assert stream.path.parent == tmp_path and stream.path.name.startswith(f"sashil-{os.getpid()}-")
    size = Stream.size(len(COLUMNS), 8, 4096)
    assert stream.path.stat().st_size == size
    assert stream.path.stat().st_blocks * 512 >= size  # fallocated: no hole the loop could fault on
    other = Stream.attach(stream.path)
    try:
        assert other.columns == COLUMNS and other.capacity == 8 and other.width == 4
        assert int(other.header[SESSION_PID_W]) == os.getpid()
    finally:
        other.close()
    assert stream.path.exists()  # attaching and closing does not remove the owner's file


def test_attach_refuses_a_file_that_is_not_a_stream(tmp_path):
    bogus = tmp_path / "x.stream"
    bogus.write_bytes(b"\0" * 8192)
    with pytest.raises(ValueError, match="not a sashil stream"):
        Stream.attach(bogus)


def test_committed_rows_read_back_exactly_and_the_count_is_written_last(stream):
    writer = StreamWriter(Stream.attach(stream.path))
    for k in range(5):
        _commit(writer, k)
    assert stream.rows_committed == 5 == int(stream.header[COMMITTED_W])
    block = stream.block(1, 4)
    assert block.tolist() == [[k * 1e-3, -0.1 * k, float(k), 2.0] for k in (1, 2, 3)]
    assert stream.copy_rows(0, 5, 2) == [tuple(row) for row in stream.block(0, 5)[::2].tolist()]
    writer.release()


def test_views_read_the_newest_rows_across_the_ring_end(stream):
    writer = StreamWriter(stream)
    for k in range(13):  # no recorder: the writer wraps freely, views are lossy
        _commit(writer, k)
    assert stream.block(9, 13)[:, 2].tolist() == [9.0, 10.0, 11.0, 12.0]  # rows 8..12 sit at 0..4 and 7
    assert stream.block(5, 13)[:, 2].tolist() == [float(k) for k in range(5, 13)]
    writer.release()


def test_the_loop_never_overwrites_a_row_the_recorder_has_not_written(stream):
    stream.header[RECORDER_W] = 1
    writer = StreamWriter(stream)
    for k in range(8):
        _commit(writer, k)
    assert writer.error is None
    _commit(writer, 8)  # the ring is full of unrecorded rows
    assert isinstance(writer.error, StreamFull) and "fell 8 rows behind" in str(writer.error)
    assert stream.rows_committed == 8 and stream.block(0, 1)[0, 2] == 0.0  # row 0 intact
    stream.header[RECORDED_W] = 3  # the recorder caught up three rows: room again
    writer.error = None
    _commit(writer, 8)
    assert writer.error is None and stream.rows_committed == 9
    writer.release()


def test_the_recorder_writes_data_csv_with_integer_columns_as_integers(tmp_path, stream):
    writer = StreamWriter(stream)
    recorder = StreamRecorder(stream, tmp_path / "data.csv", interval_s=60.0).start()
    for k in range(3):
        _commit(writer, k)
    recorder.close()
    assert (tmp_path / "data.csv").read_text().splitlines() == [
        "time_s,theta_rad,seq,phase",
        "0.0,-0.0,0,2",
        "0.001,-0.1,1,2",
        "0.002,-0.2,2,2",
    ]
    assert int(stream.header[RECORDED_W]) == 3 and recorder.summary()["rows_written"] == 3
    writer.release()


def test_format_block_keeps_floats_exact_and_nan_readable():
    text = format_block(("time_s", "seq", "z_hat"), np.array([[0.1 + 0.2, 7.0, math.nan]]))
    assert text == "0.30000000000000004,7,nan\n"


def test_a_stalled_recorder_stops_the_loop_at_0_a_and_keeps_every_recorded_row(tmp_path):
    from sashil.control.stages import ConstantCurrent
    from sashil.drivers.sim import SimulatedRig
    from sashil.engine.resolve import load_config
    from sashil.runtime.clock import VirtualClock
    from sashil.runtime.loop import ControlLoop, record_columns

    config = load_config(None)
    rig = SimulatedRig.from_parts(rig_parts(config, "sim"))
    stage = ConstantCurrent(0.4)
    shared = Stream.create(record_columns(stage), capacity=64, window=4096, folder=tmp_path)
    shared.header[RECORDER_W] = 1  # a recorder that never drains
    writer = StreamWriter(shared)
    loop = ControlLoop(rig, stage, VirtualClock(), 1000.0, 1.0, recorder=writer)
    with pytest.raises(RecordingError, match="the recorder fell 64 rows behind"):
        loop.run()
    assert loop.result.exit_status == "error" and rig._command == 0.0  # the safe command reached the rig
    assert shared.rows_committed == 64 and shared.block(63, 64)[0, 3] == 0.4
    writer.release()
    shared.close()


NO_SUCH_PID = 2**22 + 12345  # above pid_max: no such process


def test_stale_streams_go_and_live_ones_stay(tmp_path):
    live = Stream.create(COLUMNS, capacity=4, window=4096, folder=tmp_path)
    dead = Stream.create(COLUMNS, capacity=4, window=4096, folder=tmp_path)
    dead.header[SESSION_PID_W] = dead.header[LOOP_PID_W] = NO_SUCH_PID
    gone = tmp_path / f"sashil-{NO_SUCH_PID}-0a1b2c3d.stream"  # made by a process that is gone too
    os.rename(dead.path, gone)
    assert remove_stale(tmp_path) == [gone]
    assert live.path.exists() and not gone.exists()
    live.close()
    dead.close()


def test_a_planners_plan_file_goes_with_its_loop_process(tmp_path):
    mine = tmp_path / f"sashil-planner-{os.getpid()}-0a1b2c3d"
    orphan = tmp_path / f"sashil-planner-{NO_SUCH_PID}-0a1b2c3d"
    for path in (mine, orphan):
        path.write_bytes(bytes(64))
    assert remove_stale(tmp_path) == [orphan]
    assert mine.exists()


def test_a_stream_being_made_stays(tmp_path):
    # its maker (the pid in its name) is alive and has not written the header's pids yet: all zero
    making = tmp_path / f"sashil-{os.getpid()}-0a1b2c3d.stream"
    making.write_bytes(bytes(8 * 4096))
    assert remove_stale(tmp_path) == []
    assert making.exists()
    orphan = tmp_path / f"sashil-{NO_SUCH_PID}-0a1b2c3d.stream"
    making.rename(orphan)  # the same file, its maker gone before it wrote the header
    assert remove_stale(tmp_path) == [orphan]


def test_the_mailbox_carries_one_request_and_its_answer(stream):
    loop_side = Stream.attach(stream.path)
    assert not loop_side.mail_pending and loop_side.take_mail() is None
    number = stream.post({"set": {"gain": 2.0}})
    assert loop_side.mail_pending and loop_side.take_mail() == {"set": {"gain": 2.0}}
    assert stream.reply(number) is None
    loop_side.answer({"ok": True})
    assert stream.reply(number) == {"ok": True} and not loop_side.mail_pending
    loop_side.close()


def test_the_loop_stops_on_the_stop_word_and_on_its_session_s_death(stream):
    flag = StopFlag()
    stop = LoopStop(flag, stream)
    assert not stop.requested
    stream.header[STOP_W] = int(signal.SIGTERM)
    assert stop.requested and stop.signal_name == "SIGTERM" and not stop.orphaned
    other = LoopStop(StopFlag(), stream)
    stream.header[STOP_W] = STOP_BY_CALLER
    assert other.requested and other.signal_name == "stop requested"
    stream.header[STOP_W] = 0
    read_fd, write_fd = os.pipe()  # the job's pipe: the session holds the write end
    orphan_flag = StopFlag()
    session = SessionWatch(read_fd, None, lambda: orphan_flag.request(SESSION_DIED)).start()
    try:
        orphan = LoopStop(orphan_flag, stream, session)
        assert not orphan.requested and not orphan.orphaned
        os.close(write_fd)  # the session's end: SIGIO, the flag set before the next cycle asks
        assert orphan_flag.requested and orphan.requested and orphan.orphaned
        assert orphan.signal_name == SESSION_DIED
    finally:
        session.stop()
        os.close(read_fd)


class Gain(Law):
    """A law with one tunable float."""

    name = "gain-test"
    gain = Param(1.0, low=0.0, high=5.0, doc="a gain")

    def current(self, state):  # pragma: no cover - not run here
        return 0.0


def test_mailbox_tuning_applies_a_change_between_cycles_and_refuses_a_bad_one(stream):
    law = Gain()
    tuning = MailboxTuning(law, 1000.0, 0.0, stream)
    assert not tuning.busy
    number = stream.post({"set": {"gain": 2.5}})
    assert tuning.busy
    tuning.service(0.25, 250)
    assert law.gain == 2.5 and not tuning.busy
    reply = stream.reply(number)
    assert reply["ok"] and reply["events"][0]["cycle"] == 250 and reply["events"][0]["new"] == 2.5
    number = stream.post({"set": {"gain": 9.0}})
    tuning.service(0.3, 300)
    reply = stream.reply(number)
    assert not reply["ok"] and "gain" in reply["error"] and law.gain == 2.5
    assert [event.status for event in tuning.events] == ["applied", "refused"]
    number = stream.post({"get": True})
    tuning.service(0.31, 310)
    assert stream.reply(number)["parameters"]["gain"] == 2.5


def test_timing_on_shared_rings_gives_the_loop_s_summary_to_a_reader(tmp_path):
    writer_side = Stream.create(COLUMNS, capacity=4, window=4096, folder=tmp_path)
    loop_timing = writer_side.timing(1000.0)
    for cycle in range(5000):
        slot = cycle & loop_timing.mask
        loop_timing.lateness[slot] = 1000 + cycle % 7
        loop_timing.compute[slot] = 5000
        loop_timing.cycles = cycle + 1
        if not loop_timing.cycles & 4095:
            loop_timing.fold()
    loop_timing.skip(2_500_000, 1_000_000, 2)
    loop_timing.missed_deadlines, loop_timing.overruns = 2, 1
    reader = Stream.attach(writer_side.path).timing(1000.0).restore(loop_timing.counters())
    assert reader.summary() == loop_timing.summary()
    private = TimingStats(1000.0, 4096)
    assert isinstance(private.lateness[0], int)
    writer_side.close()


def test_a_closed_stream_gives_its_last_counts_and_no_rows(tmp_path):
    made = Stream.create(COLUMNS, capacity=8, window=4096, folder=tmp_path)
    writer = StreamWriter(made)
    for k in range(3):
        _commit(writer, k)
    writer.release()
    made.close()
    assert not made.path.exists()  # the owner removes its file
    assert made.rows_committed == 3 and made.copy_rows(0, 3) == []  # a view that outlived the run


def test_a_stop_request_is_passed_on_when_it_is_made():
    flag = StopFlag()
    told: list[str | None] = []
    flag.on_request = lambda: told.append(flag.signal_name)
    flag.request("STOP (page)")
    assert flag.requested and told == ["STOP (page)"]


def test_a_third_stop_signal_kills_a_loop_process_that_does_not_stop():
    import subprocess
    from types import SimpleNamespace

    from sashil.runtime.loop_process import SessionSignals

    before = signal.getsignal(signal.SIGTERM)
    child = subprocess.Popen(["sleep", "60"])  # a loop process that never reaches its next cycle
    flag = StopFlag()
    try:
        with SessionSignals(flag, SimpleNamespace(process=child)):  # type: ignore[arg-type]
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGTERM)
            assert flag.requested and flag.signal_name == "SIGTERM" and child.poll() is None
            os.kill(os.getpid(), signal.SIGTERM)
            assert child.wait(timeout=10) == -signal.SIGKILL
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert signal.getsignal(signal.SIGTERM) is before  # the session's handlers are gone after the run

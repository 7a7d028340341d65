"""The loop's watch on its session (sashil.runtime.orphan): the session's hold on the stream, a robust
mutex the kernel marks when its holding thread dies, and the end of the job's pipe, signalled."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys

import pytest

from sashil.runtime.mailbox import SESSION_DIED, LoopStop
from sashil.runtime.orphan import SessionHold, SessionWatch
from sashil.runtime.signals import StopFlag
from sashil.runtime.stream import HOLDER_W, Stream

#: the robust futex's bit the kernel sets when the owner died (linux/futex.h FUTEX_OWNER_DIED)
FUTEX_OWNER_DIED = 0x40000000


@pytest.fixture
def stream(tmp_path):
    made = Stream.create(("time_s", "current_a"), capacity=8, window=4096, folder=tmp_path)
    yield made
    made.close()


@pytest.fixture
def pipe():
    read_fd, write_fd = os.pipe()
    ends = {"read": read_fd, "write": write_fd}
    yield ends
    for fd in ends.values():
        if fd >= 0:
            os.close(fd)


def _close(ends: dict[str, int], end: str) -> None:
    os.close(ends[end])
    ends[end] = -1


def test_the_pipe_s_end_is_signalled_at_once_and_the_callback_runs_once(pipe):
    called: list[bool] = []
    before = signal.getsignal(signal.SIGIO)
    watch = SessionWatch(pipe["read"], None, lambda: called.append(True)).start()
    try:
        assert watch.hold is None and not watch.gone and not watch.check() and called == []
        os.write(pipe["write"], b"x")  # bytes from the session are no end: dropped
        assert not watch.check() and not watch.gone
        _close(pipe, "write")  # the session's end: SIGIO, no look of the loop's own
        assert watch.gone and called == [True]
        assert watch.check() and called == [True]
    finally:
        watch.stop()
    assert signal.getsignal(signal.SIGIO) is before  # disarmed: SIGIO's handler is the one it was
    assert not fcntl.fcntl(pipe["read"], fcntl.F_GETFL) & os.O_ASYNC


def test_a_session_that_ended_before_the_watch_started_is_seen_by_the_start(pipe):
    _close(pipe, "write")
    watch = SessionWatch(pipe["read"], None).start()
    try:
        assert watch.gone
    finally:
        watch.stop()


def test_the_hold_is_a_word_the_loop_reads_each_cycle_and_letting_it_go_stops_the_loop(stream, pipe):
    hold = SessionHold(stream).take()
    try:
        assert hold.held, "no robust mutex here (glibc's layout expected on Linux)"
        holder = int(stream.header[HOLDER_W])
        assert holder != 0 and holder != os.getpid()  # a thread of its own holds it
        flag = StopFlag()
        watch = SessionWatch(pipe["read"], stream, lambda: flag.request(SESSION_DIED)).start()
        try:
            assert watch.holder == holder and watch.hold[0] == holder
            stop = LoopStop(flag, stream, watch)
            assert not stop.requested and not stop.requested
            hold.release()  # the session lets go (it closed the loop process while the loop ran)
            assert stop.requested and stop.orphaned and stop.signal_name == SESSION_DIED
            assert stream.header[HOLDER_W] == 0
        finally:
            watch.stop()
    finally:
        hold.release()


def test_a_killed_session_s_hold_reads_owner_died(stream, pipe):
    session = subprocess.Popen(
        [sys.executable, "-c",
         "import sys\nfrom sashil.runtime.orphan import SessionHold\nfrom sashil.runtime.stream import Stream\n"
         "hold = SessionHold(Stream.attach(sys.argv[1])).take()\nprint(hold.held, flush=True)\nsys.stdin.read()\n",
         str(stream.path)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert session.stdout.readline().strip() == "True"  # type: ignore[union-attr]
        watch = SessionWatch(pipe["read"], stream).start()  # the pipe stays open: the hold alone tells
        try:
            assert not watch.check()
            session.kill()
            session.wait(timeout=30)
            assert watch.hold[0] & FUTEX_OWNER_DIED  # the kernel's mark on the dead holder's word
            assert watch.check() and watch.gone
        finally:
            watch.stop()
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()
        session.stdin.close()  # type: ignore[union-attr]
        session.stdout.close()  # type: ignore[union-attr]

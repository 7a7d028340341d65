"""The loop's watch on its session (sashil.runtime.orphan.SessionWatch), in this process: the end of
the job's pipe, signalled by the kernel, and the end of the session's pid, looked at."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess

import pytest

from sashil.runtime.orphan import SessionWatch


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
        assert not watch.gone and not watch.check() and called == []
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


def test_a_session_whose_pipe_end_outlives_it_is_seen_by_its_pid(pipe):
    # the session's write end still held elsewhere (a child it forked kept it): its pid's end tells
    session = subprocess.Popen(["cat"], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL)
    try:
        watch = SessionWatch(pipe["read"], session.pid).start()
        try:
            assert not watch.check()
            session.stdin.close()  # type: ignore[union-attr]  # cat ends at its input's end
            session.wait(timeout=30)
            assert watch.check() and watch.gone
        finally:
            watch.stop()
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()

"""The loop server: loop processes forked from one warm interpreter (sashil.runtime.loop_server)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import processes
import pytest

from sashil.runtime import loop_server

pytestmark = pytest.mark.e2e  # real processes: the server prepares its kernels (seconds)


@pytest.fixture
def server():
    started = loop_server.LoopServer()
    try:
        yield started
    finally:
        started.close()


def _fork(server: loop_server.LoopServer) -> tuple[loop_server.ForkedLoop, int]:
    read_fd, write_fd = os.pipe()
    try:
        return server.fork(write_fd), read_fd
    finally:
        os.close(write_fd)


def _messages(fd: int) -> list[dict]:
    with os.fdopen(fd, "rb") as pipe:
        return [json.loads(line) for line in pipe.read().splitlines()]


def test_each_loop_is_a_child_of_the_server_and_its_exit_code_comes_back(server, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    idle, idle_fd = _fork(server)
    assert processes.children(server.pid) == [idle.pid] and idle.poll() is None
    assert os.readlink(f"/proc/{idle.pid}/cwd") == str(tmp_path)  # the session's directory when asked
    assert idle.stdin is not None
    idle.stdin.close()  # a loop never given a job ends at once, nothing done
    assert idle.wait(timeout=30) == 0 and _messages(idle_fd) == []

    bad, bad_fd = _fork(server)
    assert bad.pid != idle.pid and bad.stdin is not None
    bad.stdin.write(b"{not json\n")
    bad.stdin.close()
    assert bad.wait(timeout=30) == 1
    (error,) = _messages(bad_fd)
    assert error["kind"] == "error"

    killed, killed_fd = _fork(server)
    killed.kill()
    assert killed.wait(timeout=30) == -signal.SIGKILL
    os.close(killed_fd)
    assert killed.stdin is not None
    killed.stdin.close()
    assert processes.children(server.pid) == []  # every loop reaped


def test_the_server_ends_at_once_when_its_session_dies(tmp_path):
    session = subprocess.run(
        [
            sys.executable,
            "-c",
            textwrap.dedent(
                """
                import os, sys
                from sashil.runtime import loop_server
                server = loop_server.server()
                print(server.pid, flush=True)
                os._exit(0)  # dies without a word to its server
                """
            ),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    pid = int(session.stdout)
    deadline = time.monotonic() + 10.0
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.01)  # polling another process's end, not timing the test
    if _running(pid):
        os.kill(pid, signal.SIGKILL)
        pytest.fail("the loop server outlived its session")


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended and not yet reaped by its new parent, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_changed_startup_variable_gets_a_new_server_any_other_change_keeps_it(monkeypatch):
    first = loop_server.server()
    try:
        assert loop_server.server() is first
        monkeypatch.setenv("LAB_NOTE", "a run's own variable")  # travels with each fork instead
        monkeypatch.setenv("PYTEST_CURRENT_TEST", "another test")
        assert loop_server.server() is first and first.alive()
        monkeypatch.setenv("SASHIL_TEST_MARK", "1")  # read while a loop process starts
        second = loop_server.server()
        assert second is not first and not first.alive()
    finally:
        loop_server.stop()


def test_a_fork_takes_the_sessions_environment_as_its_own():
    from sashil.runtime import serve

    job_read, job_write = os.pipe()
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # stands for the server's fork: the job reports the environment it runs in

        def take_job(messages: int) -> int:
            os.write(messages, json.dumps(dict(os.environ)).encode())
            return 0

        code = 1
        try:
            os.close(read_fd)
            code = serve._forked([job_read, write_fd, os.dup(1), os.dup(2)], {"LAB_NOTE": "from the session"}, take_job)
        finally:
            os._exit(code)
    for fd in (job_read, job_write, write_fd):
        os.close(fd)
    with os.fdopen(read_fd, "rb") as pipe:
        environment = json.loads(pipe.read())
    assert os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0
    assert environment == {"LAB_NOTE": "from the session"}


def test_a_fork_of_the_session_starts_its_own_server_and_leaves_its_parents_alone():
    first = loop_server.server()
    try:
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:  # the fork: its own server, told to end when done
            code = 1
            try:
                own = loop_server.server()
                os.write(write_fd, f"{own.pid}\n".encode())
                loop_server.stop()
                code = 0
            finally:
                os._exit(code)
        os.close(write_fd)
        with os.fdopen(read_fd) as pipe:
            child_server = int(pipe.read())
        assert os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0
        assert child_server != first.pid and first.alive() and loop_server.server() is first
        loop, messages = _fork(first)  # the parent's server still forks its loops
        assert loop.stdin is not None
        loop.stdin.close()
        assert loop.wait(timeout=30) == 0
        os.close(messages)
    finally:
        loop_server.stop()

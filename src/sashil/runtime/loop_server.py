"""Loop processes forked from one warm server: the session's side.

A fresh interpreter for each loop process costs about 1.5 s of CPU before its job can start: the
imports, numba's registries and every kernel loaded from the cache. A session that runs several
loops (a drop test's currents, a calibration's steps, a sweep's frequencies, a test suite's runs)
pays that once instead. The server (``python -m sashil.runtime.worker --serve FD``) is a fresh
interpreter started once per session process; it imports the loop's modules and loads every kernel
(:func:`sashil.runtime.worker.prepare`), then forks one loop process per run. It runs no thread
and holds no lock when it forks, so each fork is the clean copy a fresh interpreter would be, with
the work already done; the job then crosses to it as it does to a fresh one (stdin, one JSON line).

What a fork takes from the session at the moment it is asked for: the working directory, the
environment and the session's standard output and error (their descriptors cross the control
socket, so a loop's lines go where a fresh process's would). The variables read while an interpreter
starts and the kernels load (:data:`STARTUP_PREFIXES`) shaped the server itself: a session where
one of them has changed since starts a new server (:func:`server`); any other change (a test's
name, a run's own variable) travels with the next fork.

Lifetime and the session's death. The server ignores the terminal's and ``kill``'s stop signals
(a Ctrl-C stops the loop, which the session and the loop handle, never the server under it) and
ends when its control socket says so: a ``close`` message (the session is done: the server ends
once its loops have) or the socket's end with no ``close`` (the session died: the server leaves
at once, without the interpreter's teardown). The server relays nothing of the session's death:
each loop process watches its session itself, through the session's end of the job's pipe (its
stdin) and the session's pid (:class:`~sashil.runtime.orphan.SessionWatch`), stops at 0 A at its
next cycle, and ends its run alone (:mod:`sashil.runtime.orphan`), whether the server has ended
yet or not.

Protocol on the control socket (``AF_UNIX``, ``SOCK_SEQPACKET``: one message a packet, JSON):

- session → server: ``{"kind": "fork", "cwd": ..., "environment": {...}}`` with four descriptors (the job's read end,
  the messages' write end, standard output, standard error); ``{"kind": "close"}``;
- server → session: ``{"kind": "progress", "text": ...}`` while it prepares, ``{"kind": "forked",
  "pid": N}`` for each fork, ``{"kind": "exit", "pid": N, "code": C}`` when a loop process has
  ended (C as :attr:`subprocess.Popen.returncode`: negative for a signal).
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import IO, Any

from sashil.runtime.stream import pid_alive

#: the descriptors a fork request carries, in order
FORK_FDS = 4
#: the largest control message [bytes]
PACKET = 65536
#: how often the server looks for loops that have ended [s]
REAP_S = 0.05
#: the environment variables that shape an interpreter's start and its imports (the interpreter's
#: own, numba's, the numeric libraries' threads, the dynamic loader's, sashil's) or that a module
#: keeps once read (the temporary directory: :mod:`tempfile`): a server started under other values
#: is not the one a fresh loop process would be
STARTUP_PREFIXES = ("PYTHON", "NUMBA_", "SASHIL_", "LD_", "OMP_", "OPENBLAS_", "MKL_", "TMP", "TEMP")


def startup_environment(environ: Mapping[str, str]) -> dict[str, str]:
    """The part of ``environ`` that shapes a fresh interpreter's start (:data:`STARTUP_PREFIXES`)."""
    return {name: value for name, value in environ.items() if name.startswith(STARTUP_PREFIXES)}


class ForkedLoop:
    """A loop process forked by the server, with the part of :class:`subprocess.Popen`'s interface
    the session uses: ``pid``, ``stdin``, ``returncode``, :meth:`poll`, :meth:`wait`, :meth:`kill`."""

    def __init__(self, server: LoopServer, pid: int, stdin: IO[bytes]):
        self.server = server
        self.pid = pid
        self.stdin: IO[bytes] | None = stdin
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self.server.exit_code(self.pid, 0.0)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.poll()) is None:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(f"loop process {self.pid}", timeout or 0.0)
            self.returncode = self.server.exit_code(self.pid, REAP_S if left is None else min(left, REAP_S))
        return code

    def send_signal(self, signum: int) -> None:
        if self.poll() is None:
            try:
                os.kill(self.pid, signum)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class LoopServer:
    """The server process and its control socket (module doc)."""

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "sashil.runtime.worker", "--serve", str(theirs.fileno())],
                stdin=subprocess.DEVNULL,
                pass_fds=(theirs.fileno(),),
                close_fds=True,
            )
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        self.pid = self.process.pid
        #: the session process whose server this is (a fork of the session has none of its own yet)
        self.owner = os.getpid()
        #: the variables its start read (:func:`startup_environment`)
        self.environment = startup_environment(os.environ)
        self._control = ours
        self._lock = threading.Lock()
        self._exits: dict[int, int] = {}

    def alive(self) -> bool:
        return self.process.poll() is None and self._control.fileno() >= 0

    def fork(self, messages_fd: int, say: Callable[[str], None] | None = None) -> ForkedLoop:
        """A new loop process whose messages go to ``messages_fd``; the server's progress while it
        prepares (its first fork on a machine whose kernels are not cached yet) goes to ``say``.
        The job's pipe's write end (``stdin``) is this process's alone: its end is the loop's sign
        of this process's end (:mod:`sashil.runtime.orphan`)."""
        job_read, job_write = os.pipe()
        try:
            request = json.dumps({"kind": "fork", "cwd": os.getcwd(), "environment": dict(os.environ)}).encode()
            if len(request) > PACKET:
                raise OSError(f"the session's environment ({len(request)} bytes) does not fit a control message")
            with self._lock:
                socket.send_fds(self._control, [request], [job_read, messages_fd, 1, 2])
                pid = self._until_forked(say)
        except BaseException:
            os.close(job_write)
            raise
        finally:
            os.close(job_read)
        return ForkedLoop(self, pid, os.fdopen(job_write, "wb"))

    def _until_forked(self, say: Callable[[str], None] | None) -> int:
        while True:
            message = self._receive(None)
            if message is None:
                raise ConnectionError(f"the loop server (pid {self.pid}) ended (exit status {self.process.wait()})")
            if message["kind"] == "forked":
                return int(message["pid"])
            if message["kind"] == "progress" and say is not None:
                say(str(message["text"]))

    def exit_code(self, pid: int, timeout_s: float) -> int | None:
        """The exit code of loop process ``pid`` once it has ended, else None after ``timeout_s``."""
        with self._lock:
            if pid not in self._exits:
                self._receive(timeout_s)
            if pid in self._exits:
                return self._exits[pid]
            if not self.alive() and not pid_alive(pid):  # the server died: its loop's code is lost
                return self._exits.setdefault(pid, 1)
            return None

    def _receive(self, timeout_s: float | None) -> dict[str, Any] | None:
        """One message from the server (exits are filed as they come), or None at its end or timeout."""
        if self._control.fileno() < 0:
            return None
        ready, _, _ = select.select([self._control], [], [], timeout_s)
        if not ready:
            return None
        data = self._control.recv(PACKET)
        if not data:
            self._control.close()
            return None
        message: dict[str, Any] = json.loads(data)
        if message["kind"] == "exit":
            self._exits[int(message["pid"])] = int(message["code"])
        return message

    def close(self) -> None:
        """Tell the server to end once its loops have ended, and wait for it (60 s at most; a
        server still there then is killed)."""
        if self._control.fileno() >= 0:
            try:
                self._control.send(json.dumps({"kind": "close"}).encode())
            except OSError:  # it has ended already
                pass
            self._control.close()
        try:
            self.process.wait(timeout=60.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


_server: LoopServer | None = None
_server_lock = threading.Lock()


def server() -> LoopServer:
    """This process's loop server, started on first use, and again when it has ended or when a
    variable that shaped its start has changed since (:func:`startup_environment`); a process
    forked from a session starts its own."""
    global _server
    with _server_lock:
        if _server is not None and _server.owner != os.getpid():  # a fork of the session: the server is its parent's
            _server._control.close()  # this copy only: the parent's keeps the socket open
            _server = None
        if _server is not None and (not _server.alive() or _server.environment != startup_environment(os.environ)):
            old, _server = _server, None
            old.close()
        if _server is None:
            _server = LoopServer()
        return _server


def running() -> LoopServer | None:
    """This process's loop server if it runs (the tests' leak check counts its loops as this process's)."""
    return _server if _server is not None and _server.owner == os.getpid() and _server.alive() else None


def stop() -> None:
    """End this process's loop server, if one runs (once its loops have ended)."""
    global _server
    with _server_lock:
        old, _server = _server, None
    if old is not None:
        old.close()

"""The loop server's side: prepare once, fork one loop process per request (the protocol, the
lifetime and why: :mod:`sashil.runtime.loop_server`).

The server is single-threaded and stays so: it waits on its control socket, forks, and reaps the
loops it forked. Each fork takes the request's descriptors as its stdin (the job), its messages'
descriptor and its standard output and error, starts in the request's working directory, gets the
default stop signals back and takes its job as a fresh loop process would
(:func:`sashil.runtime.worker.take_job`), its parent the server. The loop watches its session, not
its parent (:class:`~sashil.runtime.orphan.SessionWatch`): the server's end, whatever its cause,
stops no run.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import sys
from collections.abc import Callable
from typing import Any

from sashil.runtime.loop_server import FORK_FDS, PACKET, REAP_S

#: the signals the server ignores: a stop is for the loop and the session, never for the server
IGNORED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def serve(
    control_fd: int,
    prepare: Callable[[Callable[[str], None]], None],
    take_job: Callable[..., int],
) -> int:
    """Serve fork requests on ``control_fd`` until the session closes the socket (then once every
    loop forked has ended) or dies (then at once, its loops left to end their runs alone, each
    having seen its session's end itself); ``prepare(progress)`` first, once. Each fork runs
    ``take_job(messages_fd)``."""
    for signum in IGNORED:
        signal.signal(signum, signal.SIG_IGN)
    control = socket.socket(fileno=control_fd)

    def send(kind: str, **fields: Any) -> None:
        try:
            control.send(json.dumps({"kind": kind, **fields}).encode())
        except OSError:  # the session has gone: nothing to tell
            pass

    prepare(lambda line: send("progress", text=line))
    children: set[int] = set()
    closing = False
    while not (closing and not children):
        for pid in [pid for pid in children if _ended(pid, send)]:
            children.discard(pid)
        if closing:
            select.select([], [], [], REAP_S)
            continue
        ready, _, _ = select.select([control], [], [], REAP_S)
        if not ready:
            continue
        data, fds, _, _ = socket.recv_fds(control, PACKET, FORK_FDS)
        if not data:  # the session died without a word: end at once, its loops have seen it themselves
            return 0
        request = json.loads(data)
        if request["kind"] == "close":
            closing = True
            continue
        with contextlib.suppress(OSError):  # the fork starts in the session's directory (else the server's)
            os.chdir(request["cwd"])
        pid = os.fork()
        if pid == 0:  # the fork: a loop process, which never returns to this loop
            code = 1
            try:
                control.close()
                code = _forked(fds, request["environment"], take_job)
            finally:
                os._exit(code)
        for fd in fds:
            os.close(fd)
        children.add(pid)
        send("forked", pid=pid)
    return 0


def _ended(pid: int, send: Callable[..., None]) -> bool:
    done, status = os.waitpid(pid, os.WNOHANG)
    if done == 0:
        return False
    send("exit", pid=pid, code=os.waitstatus_to_exitcode(status))
    return True


def _forked(fds: list[int], environment: dict[str, str], take_job: Callable[..., int]) -> int:
    """The fork's life as a loop process: its job's descriptors in place and the session's
    ``environment`` its own, then the job (``take_job(messages_fd)``); its exit code."""
    code = 1
    try:
        os.environ.clear()
        os.environ.update(environment)
        job, messages, out, err = fds
        for fd, target in ((job, 0), (out, 1), (err, 2)):
            os.dup2(fd, target)
            os.close(fd)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for signum in IGNORED[1:]:
            signal.signal(signum, signal.SIG_DFL)
        code = take_job(messages)
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
    return code

"""A warm interpreter for the tests' ``sashil`` commands: each one a fork of it, not a new interpreter.

A fresh ``sashil`` process spends a second or more before its verb starts (numpy, numba and the
compiled kernels from its cache, scipy, matplotlib, the lab's modules); the manual's pages and the
link tests run dozens of them. This server pays that once: it imports what a verb loads and loads
every loop kernel, then forks one child per command. The child is the command: it takes the caller's
standard streams, working folder and environment, runs ``sashil.cli.main`` on the caller's arguments
and sends its exit code back. The caller is a small client (:func:`client_script`, an executable
named ``sashil``) that passes on the signals it gets (SIGINT, SIGTERM, SIGHUP) and exits with the
child's code; the client named ``sashil-python`` runs a Python script so. A test that signals the session itself with SIGKILL, or reads its pid, keeps a fresh
interpreter.

The server runs as its own process (``python tests/warm_sashil.py SOCKET``), single-threaded, so a
fork copies one thread; it ends when its standard input closes (:class:`WarmSashil`).
"""

from __future__ import annotations

import gc
import json
import os
import runpy
import select
import signal
import socket
import subprocess
import sys
from pathlib import Path

#: the client named so runs a Python script (its first argument) instead of a sashil command
PYTHON = "sashil-python"

#: the client: connect, hand over the streams, wait for the exit code (``{socket!r}``: the server's)
CLIENT = r"""
import json, os, signal, socket, sys
sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
sock.connect({socket!r})
name = os.path.basename(sys.argv[0])
request = json.dumps({"name": name, "argv": sys.argv[1:], "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
socket.send_fds(sock, [len(request).to_bytes(8, "big") + request], [0, 1, 2])
reply = b""
while b"\n" not in reply:
    chunk = sock.recv(64)
    if not chunk:
        sys.exit(1)
    reply += chunk
pid, code = reply.split(b"\n", 1)  # the child's pid first, then (once it ends) its exit code
child = int(pid)


def forward(signum):
    try:
        os.kill(child, signum)
    except ProcessLookupError:
        pass


for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
    signal.signal(number, lambda signum, frame: forward(signum))
while True:
    try:
        chunk = sock.recv(64)
    except InterruptedError:
        continue
    if not chunk:
        break
    code += chunk
sys.exit(int(code) if code.strip() else 1)
"""


def _warm() -> None:
    """Import what the verbs load and load every loop kernel (numba's cache) once, for every child."""
    import matplotlib.backends.backend_agg
    import matplotlib.figure  # noqa: F401

    import sashil.cli
    import sashil.lab
    from sashil.runtime.warmup import warm_kernels

    warm_kernels()
    sashil.cli.build_parser()


def _receive(conn: socket.socket) -> tuple[dict, list[int]]:
    head, fds, _, _ = socket.recv_fds(conn, 8, 3)
    while len(head) < 8:
        head += conn.recv(8 - len(head))
    size = int.from_bytes(head, "big")
    body = b""
    while len(body) < size:
        body += conn.recv(size - len(body))
    return json.loads(body), fds


def _child(conn: socket.socket, request: dict, fds: list[int]) -> None:
    """The command: the caller's streams, folder and environment, then ``sashil``; never returns."""
    code = 1
    try:
        conn.sendall(f"{os.getpid()}\n".encode())  # first: the client passes its signals on to it
        for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD):
            signal.signal(number, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        if request["name"] == PYTHON:  # a script, as ``python SCRIPT ARGS...`` runs it
            script = request["argv"][0]
            sys.argv = list(request["argv"])
            sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
            runpy.run_path(script, run_name="__main__")
            code = 0
        else:
            sys.argv = ["sashil", *request["argv"]]
            from sashil.cli import main

            code = main(request["argv"]) or 0
    except SystemExit as stop:
        code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    except KeyboardInterrupt:
        code = 130
    except BaseException:
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except Exception:
            pass
        try:
            conn.sendall(f"{code}\n".encode())
        finally:
            os._exit(code if isinstance(code, int) else 1)


def serve(path: Path) -> None:
    _warm()
    # what the warm-up loaded is never freed: out of the collector's sight, a child's collections
    # stay as short as a fresh interpreter's (and do not copy the shared pages)
    gc.freeze()
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children are reaped as they end
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(16)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    stdin = sys.stdin.fileno()
    while True:
        ready, _, _ = select.select([listener, stdin], [], [])
        if stdin in ready and not os.read(stdin, 1):
            break  # the test ended
        if listener not in ready:
            continue
        conn, _ = listener.accept()
        request, fds = _receive(conn)
        pid = os.fork()
        if pid == 0:
            listener.close()
            _child(conn, request, fds)
        for fd in fds:
            os.close(fd)
        conn.close()
    listener.close()


def client_script(socket_path: Path) -> str:
    """The client's source, an executable script for this interpreter (``-S``: no site-packages)."""
    return f"#!{sys.executable} -S\n" + CLIENT.replace("{socket!r}", repr(str(socket_path)))


class WarmSashil:
    """The server started in ``folder``, and its clients ``folder/bin/sashil`` (:attr:`command`) and
    ``folder/bin/sashil-python`` (:attr:`python`)."""

    def __init__(self, folder: Path):
        self.bin = folder / "bin"
        self.bin.mkdir()
        socket_path = folder / "server.sock"
        for name in ("sashil", PYTHON):
            client = self.bin / name
            client.write_text(client_script(socket_path), encoding="utf-8")
            client.chmod(0o755)
        self.command = [str(self.bin / "sashil")]
        #: runs a Python script (``[*python, SCRIPT]``) in a fork of the warm interpreter
        self.python = [str(self.bin / PYTHON)]
        self.server = subprocess.Popen(
            [sys.executable, __file__, str(socket_path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert self.server.stdout is not None
        if self.server.stdout.readline() != "ready\n":
            self.close()
            raise RuntimeError("the warm sashil server did not start")

    def close(self) -> None:
        """End the server (its standard input closes); the commands it forked end on their own."""
        if self.server.stdin is not None:
            self.server.stdin.close()
        self.server.wait(timeout=30)
        if self.server.stdout is not None:
            self.server.stdout.close()


if __name__ == "__main__":
    serve(Path(sys.argv[1]))

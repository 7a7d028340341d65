"""Spawning the rerun viewer for ``--rerun``, listening on the loopback interface only.

rerun's own ``rr.spawn`` starts the viewer with its default bind address, every interface
(``0.0.0.0``), so anyone on the lab network could stream into or read the live view. This starts
the same viewer executable with ``--bind 127.0.0.1`` (``--rerun-bind`` asks for another address)
and waits until its port accepts connections; a viewer already listening there is reused.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time

from sashil.errors import ConfigError

DEFAULT_PORT = 9876
LOOPBACK = "127.0.0.1"


def listening(host: str, port: int, timeout_s: float = 0.2) -> bool:
    """Whether something accepts TCP connections at ``host:port``."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def reachable_host(bind: str) -> str:
    """Where this machine reaches a viewer bound to ``bind``."""
    return LOOPBACK if bind in ("0.0.0.0", "::", LOOPBACK) else bind


def viewer_command(executable: str, port: int = DEFAULT_PORT, bind: str = LOOPBACK) -> list[str]:
    """The command line of the spawned viewer."""
    return [
        executable,
        "--port",
        str(port),
        "--bind",
        bind,
        "--memory-limit",
        "75%",
        "--server-memory-limit",
        "1GiB",
        "--expect-data-soon",
    ]


def spawn_viewer(
    executable: str, port: int = DEFAULT_PORT, bind: str = LOOPBACK, timeout_s: float = 15.0
) -> subprocess.Popen | None:
    """Start the viewer (detached: it outlives the run) unless one already listens on ``port``;
    returns the process, or None when an existing viewer is reused."""
    probe = reachable_host(bind)
    if listening(probe, port):
        return None
    try:
        proc = subprocess.Popen(
            viewer_command(executable, port, bind),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # Ctrl-C on the run does not close the viewer
            env={**os.environ, "RERUN_APP_ONLY": "true"},
        )
    except OSError as err:
        raise ConfigError(f"--rerun: cannot start the rerun viewer {executable} ({err.strerror})") from None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if listening(probe, port):
            return proc
        if proc.poll() is not None:
            raise ConfigError(
                f"--rerun: the rerun viewer exited at once (code {proc.returncode}; no display?); "
                "use --rerun-save FILE.rrd"
            )
        time.sleep(0.05)
    raise ConfigError(f"--rerun: the rerun viewer did not listen on {probe}:{port} within {timeout_s:g} s")

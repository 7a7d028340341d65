"""The tests' view of a session's processes in /proc: its children, and its running loop process."""

from __future__ import annotations

import subprocess
from pathlib import Path


def children(pid: int) -> list[int]:
    """The pids whose parent is ``pid``."""
    return [int(child) for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def loop_of(session: int) -> int:
    """The running loop process of the session process ``session``: the one child of its one child,
    the session's loop server (sashil.runtime.loop_server)."""
    (server,) = children(session)
    (loop,) = children(server)
    return loop


def running_loop(session: subprocess.Popen) -> int:
    """The loop process of ``session`` (a ``sashil run -v`` with stderr piped), once its stderr says
    ``loop: running``; AssertionError naming its exit code when it never does."""
    for line in session.stderr:  # type: ignore[union-attr]
        if line.startswith("loop: running"):
            return loop_of(session.pid)
    raise AssertionError(f"the loop never ran (exit {session.wait()})")

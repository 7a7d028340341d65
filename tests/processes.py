"""The tests' view of a session's processes in /proc: its children, and its running loop process."""

from __future__ import annotations

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

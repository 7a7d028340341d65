"""What an experiment tells its caller while it runs, as events rather than prints.

An experiment never writes to the terminal itself: it calls ``on_event(Event(...))``. The command
line prints events (:func:`printer`); a script collects them or ignores them (the default); a page
forwards them to the browser.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = ["Event", "Listener", "ignore", "printer"]

#: ``progress``: what is starting or running; ``prompt``: an operator instruction at the bench (shown
#: even when quiet); ``result``: a figure of a finished run; ``warning``: what the operator should
#: know; ``folder``: the run folder, once it holds the run
Kind = Literal["progress", "prompt", "result", "warning", "folder", "output"]


@dataclass(frozen=True)
class Event:
    """One message of an experiment: its kind, one line of text, and the values behind it."""

    kind: Kind
    text: str
    data: dict[str, Any] = field(default_factory=dict)


Listener = Callable[[Event], None]


def ignore(event: Event) -> None:
    """The default listener of a library call: events are dropped."""


def printer(quiet: bool = False, stream: Any = None) -> Listener:
    """A listener that prints each event as one line on ``stream`` (default stderr); ``quiet`` keeps
    only prompts, warnings and the folder line."""

    def show(event: Event) -> None:
        if quiet and event.kind in ("progress", "result"):
            return
        out = sys.stdout if event.kind == "output" else (stream or sys.stderr)
        prefix = "  " if event.kind in ("prompt", "result") else ""
        out.write(prefix + event.text + "\n")  # one write: a loop process's own lines never land inside it
        out.flush()

    return show

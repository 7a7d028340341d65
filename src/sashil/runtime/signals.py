"""SIGINT/SIGTERM/SIGHUP -> a stop flag the loop checks once per cycle -> a clean stop (0 A, data, summary).

The handler only sets a flag (nothing else is safe inside a signal handler in the middle of a
cycle); the loop sees it at the top of the next cycle, at most one period later, and ends through
its ordinary shutdown path. Previous handlers are restored when the ``catch_stop_signals`` block
ends. The CLI then exits with code 130 (``sashil.cli.EXIT_CODES``).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from sashil.errors import Stopped

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopFlag:
    """Set by a signal (or by any code that wants the loop to stop cleanly)."""

    __slots__ = ("on_request", "requested", "signal_name")

    def __init__(self) -> None:
        self.requested = False
        self.signal_name: str | None = None
        #: called after each request (a loop in another process is told at once through its stream)
        self.on_request: Callable[[], None] | None = None

    def request(self, reason: str = "stop requested") -> None:
        self.signal_name = self.signal_name or reason
        self.requested = True
        if self.on_request is not None:
            self.on_request()


def stopped_error(flag: StopFlag) -> Stopped:
    """The error a verb ends with after ``flag`` stopped its loop cleanly (exit 130)."""
    return Stopped(f"stopped by {flag.signal_name} after a clean shutdown (0 A; the data up to it kept)")


@contextmanager
def catch_stop_signals(flag: StopFlag | None = None) -> Iterator[StopFlag]:
    """Route SIGINT, SIGTERM and SIGHUP to ``flag`` for the duration of the block (main thread only)."""
    flag = flag if flag is not None else StopFlag()
    if threading.current_thread() is not threading.main_thread():
        yield flag  # signals are delivered to the main thread only; nothing to install
        return

    def handler(signum: int, frame: object) -> None:
        flag.request(signal.Signals(signum).name)

    previous = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    try:
        yield flag
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)

"""Progress of a long loop run on stderr, and fanning one session hook out to several.

:class:`RunProgress` is a session hook like the live view (``start(recorder, timing)``,
``close(trips)``): a thread that, every ``interval_s``, prints how far the run is (run time, of
the duration when known, cycles, missed deadlines) — a redrawn bar on a terminal, a plain line
otherwise. It reads two integers the loop already keeps (``timing.cycles``,
``timing.missed_deadlines``) and prints only inside the loop's idle window
(``recorder.window_end_ns``), so it never holds the interpreter when the loop needs it.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any, TextIO

#: printing a line holds the interpreter this long at most (generous)
PRINT_BUDGET_NS = 200_000


class RunProgress:
    """Prints ``run 12.0 s / 60 s [#####-----] 12000 cycles, 0 missed`` every ``interval_s``."""

    def __init__(
        self,
        duration_s: float | None,
        rate_hz: float,
        interval_s: float | None = None,
        stream: TextIO | None = None,
        width: int = 24,
    ):
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.duration_s = duration_s
        self.rate_hz = float(rate_hz)
        self.interval_s = float(interval_s if interval_s is not None else (0.5 if self.tty else 10.0))
        self.width = width
        self.recorder: Any = None
        self.timing: Any = None
        self.lines = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def text(self, cycles: int, missed: int) -> str:
        run_s = cycles / self.rate_hz
        if self.duration_s:
            done = min(1.0, run_s / self.duration_s)
            filled = int(self.width * done)
            head = f"run {run_s:6.1f} s / {self.duration_s:g} s [{'#' * filled}{'-' * (self.width - filled)}]"
        else:
            head = f"run {run_s:6.1f} s"
        return f"{head} {cycles} cycles, {missed} missed deadline(s)"

    def start(self, recorder: Any, timing: Any) -> RunProgress:
        self.recorder, self.timing = recorder, timing
        self._thread = threading.Thread(target=self._run, name="sashil-progress", daemon=True)
        self._thread.start()
        return self

    def _emit(self, final: bool = False) -> None:
        line = self.text(self.timing.cycles, self.timing.missed_deadlines)
        self.stream.write(("\r" + line + ("\n" if final else "")) if self.tty else line + "\n")
        self.stream.flush()
        self.lines += 1

    def _run(self) -> None:
        next_at = time.monotonic() + self.interval_s
        while not self._stop.wait(0.01):
            if time.monotonic() < next_at:
                continue
            window = self.recorder.window_end_ns if self.recorder is not None else None
            if window is not None and time.perf_counter_ns() + PRINT_BUDGET_NS > window:
                continue  # the loop needs the interpreter soon: try again in 10 ms
            self._emit()
            next_at += self.interval_s

    def close(self, trips: Sequence[Mapping[str, Any]] = (), notes: Sequence[tuple[float, str]] = ()) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
            if self.tty and self.lines:
                self._emit(final=True)


class SessionHooks:
    """Several session hooks as one (``run_session(live=...)`` takes one); ``close`` returns the
    statistics of the first hook that has any (the live view's)."""

    def __init__(self, *hooks: Any):
        self.hooks = [hook for hook in hooks if hook is not None]

    def start(self, recorder: Any, timing: Any) -> SessionHooks:
        for hook in self.hooks:
            hook.start(recorder, timing)
        return self

    def close(self, trips: Sequence[Mapping[str, Any]] = (), notes: Sequence[tuple[float, str]] = ()) -> Any:
        stats = None
        for hook in self.hooks:
            result = hook.close(trips, notes)
            if stats is None:
                stats = result
        return stats

"""A small progress bar on stderr for long fits (no dependency; silent when disabled)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``Progress(total, label)``; ``advance(n)``; ``close()``. Redraws at most 10 times a second."""

    def __init__(self, total: int, label: str, enabled: bool = True, stream: TextIO | None = None, width: int = 30):
        self.total = max(1, int(total))
        self.label = label
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.width = width
        self.done = 0
        self.started = time.perf_counter()
        self._drawn = 0.0

    def advance(self, count: int = 1, note: str = "") -> None:
        self.done = min(self.total, self.done + count)
        now = time.perf_counter()
        if self.enabled and (now - self._drawn > 0.1 or self.done == self.total):
            self._drawn = now
            filled = int(self.width * self.done / self.total)
            bar = "#" * filled + "-" * (self.width - filled)
            self.stream.write(f"\r{self.label} [{bar}] {self.done}/{self.total} {now - self.started:5.1f}s {note}")
            self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()

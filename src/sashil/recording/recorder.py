"""The threaded recorder: the cycle hands over a row, a writer thread appends it to ``data.csv``.

Hot path (the loop thread): ``row = recorder.begin_row()`` gives a preallocated list from a ring
of ``capacity`` rows, the cycle fills it in place, ``recorder.commit_row()`` publishes it. Nothing
is allocated, nothing blocks: when the writer falls ``capacity`` rows behind, rows are dropped and
counted (``rows_dropped``), never waited for. On simulated time (``lossless``), where no deadline
can be missed, the loop waits for the writer instead, so the stream holds every row.

Kept stream (``keep=True``, simulated time): every row stays in memory as well (the ring grows and is
never reused) and :meth:`Recorder.stream` returns the columns as float arrays, the values the file
would parse back to (``repr`` round-trips a float exactly); ``path=None`` then keeps the rows without
a file or a writer thread. A plan that derives its records from the stream reads them from there
rather than parsing the CSV text again.

Writer thread: formats committed rows as CSV text in small slices and appends them to the file
with ``os.write`` on an ``O_APPEND`` descriptor, each write holding whole lines only, at least
every ``flush_interval_s`` (default 0.25 s, and always within 1 s). So after a crash or SIGKILL
the file parses up to the last write (docs/architecture.md data.csv columns; floats as ``repr``, integers as
``str``, as :func:`sashil.recording.data_file.format_rows` writes them).

The writer shares the GIL with the loop. On the real clock the loop publishes
``window_end_ns``, the time from which it needs the interpreter again (its next wake-up); the writer
starts a slice only when the slice fits before it, so it works while the loop sleeps. If the
window stays closed too long the writer writes anyway, keeping the flush promise.
"""

from __future__ import annotations

import itertools
import os
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sashil.recording.data_file import write_all

#: rows formatted per slice (a slice holds the GIL for roughly SLICE_ROWS * 3 µs)
SLICE_ROWS = 16
SLICE_BUDGET_NS = 80_000
POLL_S = 0.005


class Recorder:
    """Single-producer ring of rows + a writer thread appending CSV lines to ``path``."""

    def __init__(
        self,
        path: str | Path | None,
        columns: Sequence[str],
        capacity: int = 65536,
        flush_interval_s: float = 0.25,
        lossless: bool = False,
        keep: bool = False,
    ):
        if not 0 < flush_interval_s <= 1.0:
            raise ValueError("flush_interval_s must be in (0, 1] s")
        if path is None and not keep:
            raise ValueError("a recorder without a file keeps its rows (keep=True)")
        self.path = None if path is None else Path(path)
        self.columns = tuple(columns)
        self.capacity = int(capacity)
        self.lossless = bool(lossless)
        #: every row stays in memory (module docstring): the ring grows one row per cycle instead
        self.keep = bool(keep)
        self.flush_interval_ns = int(flush_interval_s * 1e9)
        width = len(self.columns)
        self._width = width
        #: the ring's length: rows are reused modulo this (never, when the rows are kept)
        self._bound = sys.maxsize if self.keep else self.capacity
        self._ring: list[list[Any]] = [] if self.keep else [[0.0] * width for _ in range(self.capacity)]
        self._scratch: list[Any] = [0.0] * width
        self._head = 0  # rows committed (written by the loop thread only)
        self._tail = 0  # rows formatted (written by the writer thread only)
        self._slot_ok = False
        self.rows_dropped = 0
        self.rows_written = 0
        self.writes = 0
        self.window_end_ns: int | None = None  # None: the writer may work at any time
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._fd: int | None = None
        self.error: BaseException | None = None

    # lifecycle -------------------------------------------------------------------------------
    def start(self) -> Recorder:
        """Create the file, write the header line, start the writer thread (none without a file)."""
        if self.path is None:
            return self
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        self._write_all((",".join(self.columns) + "\n").encode())
        self._thread = threading.Thread(target=self._run, name="sashil-recorder", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the writer, write every committed row, fsync and close the file. Idempotent."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        if self._fd is not None:
            if self.error is None:
                self._drain()
            try:
                os.fsync(self._fd)
            finally:
                os.close(self._fd)
                self._fd = None
        if self.error is not None:
            raise OSError(f"{self.path}: recording failed: {self.error}") from self.error

    def __enter__(self) -> Recorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # hot path (loop thread) ------------------------------------------------------------------
    def begin_row(self) -> list[Any]:
        """The row to fill this cycle (a preallocated list; a scratch row when the ring is full)."""
        head = self._head
        if self.keep:  # a new row for each committed one, kept
            ring = self._ring
            if head == len(ring):
                ring.append([0.0] * self._width)
            self._slot_ok = True
            return ring[head]
        if head - self._tail >= self.capacity and self.lossless:
            while head - self._tail >= self.capacity and self.error is None and self._thread is not None:
                time.sleep(POLL_S / 10)  # simulated time: wait for the writer rather than drop a row
        if head - self._tail < self.capacity:
            self._slot_ok = True
            return self._ring[head % self.capacity]
        self._slot_ok = False
        return self._scratch

    def commit_row(self) -> None:
        """Publish the row from ``begin_row`` to the writer."""
        if self._slot_ok:
            self._head += 1
        else:
            self.rows_dropped += 1

    @property
    def rows_committed(self) -> int:
        return self._head

    def copy_rows(self, start: int, stop: int, step: int = 1) -> list[tuple[Any, ...]]:
        """Copies of committed rows ``start, start+step, ... < stop`` (row numbers as counted by
        ``rows_committed``) for a reader off the hot path such as the live view. Rows older than
        ``rows_committed - capacity`` are gone; the caller keeps clear of them."""
        ring, cap = self._ring, self._bound
        stop = min(stop, self._head)
        return [tuple(ring[i % cap]) for i in range(max(start, 0), stop, step)]

    # writer thread ---------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            try:  # the writer never competes at real-time priority with the loop
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            except (AttributeError, OSError):
                pass
            pending: list[str] = []
            last_write = time.perf_counter_ns()
            while not self._stop.is_set():
                now = time.perf_counter_ns()
                overdue = now - last_write >= self.flush_interval_ns
                starving = now - last_write >= 3 * self.flush_interval_ns  # still < 1 s
                while self._tail < self._head:
                    window = self.window_end_ns
                    if not starving and window is not None and time.perf_counter_ns() + SLICE_BUDGET_NS > window:
                        break
                    pending.append(self._format_slice(SLICE_ROWS))
                if pending and (overdue or starving):
                    self._write_all("".join(pending).encode())
                    pending.clear()
                    last_write = time.perf_counter_ns()
                elif not pending and self._tail >= self._head:
                    last_write = now  # nothing waits: the flush clock starts with the next row
                self._stop.wait(POLL_S)
            if pending:
                self._write_all("".join(pending).encode())
        except BaseException as err:
            self.error = err

    def _format_slice(self, max_rows: int) -> str:
        ring, cap = self._ring, self._bound
        tail = self._tail
        end = min(self._head, tail + max_rows)
        lines = [",".join(map(repr, ring[i % cap])) for i in range(tail, end)]
        self._tail = end
        self.rows_written += end - tail
        return "\n".join(lines) + "\n"

    def _drain(self) -> None:
        chunks = []
        while self._tail < self._head:
            chunks.append(self._format_slice(4096))
        if chunks:
            self._write_all("".join(chunks).encode())

    def _write_all(self, data: bytes) -> None:
        write_all(self._fd, data)  # type: ignore[arg-type]
        self.writes += 1

    def stream(self) -> dict[str, np.ndarray]:
        """The kept rows (``keep=True``) as one float array per column, in commit order."""
        if not self.keep:
            raise ValueError("the recorder keeps no rows (keep=False)")
        count, width = self._head, self._width
        values = itertools.chain.from_iterable(itertools.islice(self._ring, count))
        try:
            table = np.fromiter(values, dtype=float, count=count * width).reshape(count, width).T.copy()
        except (TypeError, ValueError):  # a stage signal that is not a number (None: NaN, as numpy reads it)
            table = np.array(self._ring[:count], dtype=float).reshape(count, width).T.copy()
        return dict(zip(self.columns, table, strict=True))

    def summary(self) -> dict[str, Any]:
        return {
            "rows_written": self.rows_written,
            "rows_dropped": self.rows_dropped,
            "writes": self.writes,
            "capacity_rows": self.capacity,
        }

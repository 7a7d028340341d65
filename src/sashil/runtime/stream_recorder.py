"""The lossless reader of a run's stream: every committed row into ``data.csv``, in the session process.

The loop process writes rows into the stream (:mod:`sashil.runtime.stream`); this recorder drains
them every ``interval_s`` from its own thread, formats them as CSV (floats as ``repr``, so the text
parses back to the very values; the integer columns as integers, as the in-process recorder writes
them: :mod:`sashil.recording.recorder`) and appends whole lines to the file with ``os.write`` on an
``O_APPEND`` descriptor. After each write it tells the loop how far it got (the stream's
``recorded`` word), which is what keeps the loop from overwriting a row not yet on disk.

It runs in the session process, so its work never takes the loop's interpreter: no slicing around
the loop's wake-ups is needed, unlike the in-process recorder.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np

from sashil.recording.data_file import write_all
from sashil.runtime.stream import RECORDED_W, RECORDER_W, Stream

#: columns whose values are integers (device counters, codes); written without a decimal point
INTEGER_COLUMNS = frozenset(
    ("seq", "device_time_us", "arm_edge_us", "arm_edge_dir", "road_edge_us", "road_edge_dir", "phase", "trip_code")
)
#: how often the recorder drains the stream [s]; a kill -9 of the session loses nothing (the
#: loop process writes what is left), a kill -9 of both at most this much
DRAIN_INTERVAL_S = 0.1


def format_block(columns: tuple[str, ...], block: np.ndarray) -> str:
    """CSV lines of a block of stream rows (no header)."""
    if not len(block):
        return ""
    integer = [name in INTEGER_COLUMNS for name in columns]
    lines = []
    for row in block.tolist():
        lines.append(
            ",".join(
                str(int(value)) if is_int and value == value else repr(value)
                for value, is_int in zip(row, integer, strict=True)
            )
        )
    return "\n".join(lines) + "\n"


def append(fd: int, text: str) -> None:
    """Write all of ``text`` to ``fd``."""
    write_all(fd, text.encode())


class StreamRecorder:
    """Drains ``stream`` into ``path`` (module doc); ``start()``, then ``close()`` once the loop ended."""

    def __init__(self, stream: Stream, path: str | Path, interval_s: float = DRAIN_INTERVAL_S):
        self.stream = stream
        self.path = Path(path)
        self.columns = stream.columns
        self.capacity = stream.capacity
        self.interval_s = float(interval_s)
        self.rows_written = 0
        self.writes = 0
        self.error: BaseException | None = None
        self._fd: int | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        stream.header[RECORDER_W] = 1  # the loop keeps to the rows this recorder has written

    def start(self) -> StreamRecorder:
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        append(self._fd, ",".join(self.columns) + "\n")
        self._thread = threading.Thread(target=self._run, name="sashil-stream-recorder", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while not self._stop.wait(self.interval_s):
                self.drain()
        except BaseException as err:  # the loop stops when the stream fills: the run ends at 0 A
            self.error = err

    def drain(self) -> int:
        """Write every committed row not yet written; returns how many."""
        stream = self.stream
        start, stop = self.rows_written, stream.rows_committed
        if stop <= start or self._fd is None:
            return 0
        append(self._fd, format_block(self.columns, stream.block(start, stop)))
        self.writes += 1
        self.rows_written = stop
        stream.header[RECORDED_W] = stop
        return stop - start

    def close(self) -> None:
        """Stop the thread, write the rest, fsync, close. Idempotent; OSError if recording failed."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        if self._fd is not None:
            try:
                if self.error is None:
                    self.drain()
                os.fsync(self._fd)
            finally:
                os.close(self._fd)
                self._fd = None
        if self.error is not None:
            raise OSError(f"{self.path}: recording failed: {self.error}") from self.error

    def summary(self) -> dict[str, Any]:
        return {
            "rows_written": self.rows_written,
            "rows_dropped": 0,
            "writes": self.writes,
            "capacity_rows": self.capacity,
        }

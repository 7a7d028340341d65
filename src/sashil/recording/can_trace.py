"""The raw CAN frames of a run, both directions, as ``can.blf`` / ``can.asc`` / ``can.log`` / ``can.mf4``.

python-can's ``can.Logger`` picks the writer from the file suffix (BLFWriter, ASCWriter,
CanutilsLogWriter, MF4Writer), so the files open in CANalyzer/CANoe, asammdf, ``candump``/
``canplayer`` and python-can's own ``can.LogReader`` (replay with ``can.MessageSync``).

The cycle does not write: the CAN backend hands each frame to :meth:`CanTrace.put` (a
``deque.append``: no lock held across I/O, nothing allocated beyond the frame object the backend
already has), and a writer thread at normal priority drains the queue every ``interval_s`` into
the loggers. Received frames keep python-can's receive timestamp; sent frames are stamped when
sent. ``is_rx`` says the direction (BLF and ASC record it as Rx/Tx).
"""

from __future__ import annotations

import collections
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError

#: how often the writer thread drains the queue [s]
DRAIN_INTERVAL_S = 0.05


class CanTrace:
    """Queue of frames + a writer thread feeding one ``can.Logger`` per file."""

    def __init__(self, paths: Sequence[str | Path], interval_s: float = DRAIN_INTERVAL_S):
        self.paths = [Path(p) for p in paths]
        self.interval_s = interval_s
        self._queue: collections.deque[Any] = collections.deque()
        self._loggers: list[Any] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames_rx = 0
        self.frames_tx = 0
        self.error: BaseException | None = None
        #: the hot-path entry point: ``trace.put(message)``
        self.put = self._queue.append

    @classmethod
    def for_formats(cls, folder: Path, formats: Sequence[str]) -> CanTrace | None:
        """``can.<ext>`` in ``folder`` for each CAN format, or None when none is asked for."""
        return cls([folder / f"can.{fmt}" for fmt in formats]) if formats else None

    def attach(self, rig: Any) -> Any:
        """Give ``rig`` (a backend with CAN frames: ``frame_sink``) this trace; returns the rig."""
        if not hasattr(rig, "frame_sink"):
            raise ConfigError(
                f"--format: the {getattr(rig, 'name', type(rig).__name__)} backend has no CAN frames to trace"
            )
        rig.frame_sink = self.put
        return rig

    # lifecycle -------------------------------------------------------------------------------
    def start(self) -> CanTrace:
        """Open the files (python-can's writers) and start the writer thread."""
        import can

        for path in self.paths:
            try:
                self._loggers.append(can.Logger(str(path)))
            except (ImportError, ValueError, OSError) as err:
                self._stop_loggers()
                raise ConfigError(f"--format {path.suffix[1:]}: cannot write {path} ({err})") from None
        self._thread = threading.Thread(target=self._run, name="sashil-can-trace", daemon=True)
        self._thread.start()
        return self

    def close(self) -> dict[str, Any]:
        """Stop the thread, write every queued frame, close the files; returns the trace summary."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        if self.error is None:
            self._drain()
        self._stop_loggers()
        return self.summary()

    def __enter__(self) -> CanTrace:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def summary(self) -> dict[str, Any]:
        return {
            "files": [p.name for p in self.paths],
            "frames_rx": self.frames_rx,
            "frames_tx": self.frames_tx,
            "error": None if self.error is None else str(self.error),
        }

    # writer thread ---------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            try:  # never at the loop's real-time priority
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            except (AttributeError, OSError):
                pass
            while not self._stop.wait(self.interval_s):
                self._drain()
        except BaseException as err:  # reported in the summary; the run goes on without the trace
            self.error = err

    def _drain(self) -> None:
        queue, loggers = self._queue, self._loggers
        while queue:
            msg = queue.popleft()
            if msg.is_rx:
                self.frames_rx += 1
            else:
                self.frames_tx += 1
            for logger in loggers:
                logger.on_message_received(msg)

    def _stop_loggers(self) -> None:
        loggers, self._loggers = self._loggers, []
        for logger in loggers:
            try:
                logger.stop()
            except Exception as err:  # a writer that fails on close: keep closing the others
                if self.error is None:
                    self.error = err

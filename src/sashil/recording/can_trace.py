"""The raw CAN frames of a run, both directions, as ``can.blf`` / ``can.asc`` / ``can.log`` / ``can.mf4``.

python-can's ``can.Logger`` picks the writer from the file suffix (BLFWriter, ASCWriter,
CanutilsLogWriter, MF4Writer), so the files open in CANalyzer/CANoe, asammdf, ``candump``/
``canplayer`` and python-can's own ``can.LogReader`` (replay with ``can.MessageSync``).

The cycle does not write: the CAN backend hands each frame to :meth:`CanTrace.put` (a
``deque.append``: no lock held across I/O, nothing allocated beyond the frame object the backend
already has), and a writer thread at normal priority drains the queue every ``interval_s`` into
the loggers, in slices of :data:`SLICE_FRAMES` between which it gives up the interpreter lock.
Received frames keep python-can's receive timestamp; sent frames are stamped when sent. ``is_rx``
says the direction (BLF and ASC record it as Rx/Tx). MF4 is recorded as BLF during the run and
converted when it stops (python-can's MF4Writer is too slow to run beside the loop).
"""

from __future__ import annotations

import collections
import os
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from sashil.drivers.interface import capabilities_of
from sashil.errors import ConfigError

#: how often the writer thread drains the queue [s]
DRAIN_INTERVAL_S = 0.05
#: frames written per slice; between slices the writer gives up the interpreter lock (a BLF/ASC
#: frame costs 2-5 µs, so the loop never waits more than ~80 µs for the writer)
SLICE_FRAMES = 16
#: formats recorded as BLF during the run and converted when it ends: python-can's MF4Writer
#: costs ~80 µs per frame (asammdf), too much beside a 1 kHz loop in the same interpreter
CONVERTED_AFTER = (".mf4",)


class CanTrace:
    """Queue of frames + a writer thread feeding one ``can.Logger`` per file."""

    def __init__(self, paths: Sequence[str | Path], interval_s: float = DRAIN_INTERVAL_S, channel: str = "can0"):
        self.paths = [Path(p) for p in paths]
        #: the files written while the run goes on (a BLF stands in for the formats converted after)
        self._live_paths = [p for p in self.paths if p.suffix not in CONVERTED_AFTER]
        self._converted = [p for p in self.paths if p.suffix in CONVERTED_AFTER]
        self._staging: Path | None = None
        if self._converted and not any(p.suffix == ".blf" for p in self._live_paths):
            self._staging = self._converted[0].with_name(self._converted[0].name + ".part.blf")
            self._live_paths.append(self._staging)
        self.channel = channel  # the channel name frames without one are logged under
        self.interval_s = interval_s
        self._queue: collections.deque[Any] = collections.deque()
        self._loggers: list[Any] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames_rx = 0
        self.frames_tx = 0
        self.frames_dropped = 0  # queued after the writer failed (counted, not written)
        self.error: BaseException | None = None
        #: frames from another process (:meth:`follow`), taken at each drain
        self._source: Callable[[], Iterable[Any]] | None = None
        #: the hot-path entry point: ``trace.put(message)``
        self.put = self._queue.append

    @classmethod
    def for_formats(cls, folder: Path, formats: Sequence[str], port: str | None = None) -> CanTrace | None:
        """``can.<ext>`` in ``folder`` for each CAN format, or None when none is asked for. Frames
        are logged on channel ``port`` when it is a bus name (``can0``), else ``slcan0`` (a tty)."""
        if not formats:
            return None
        channel = port if port and "/" not in port else "slcan0"
        return cls([folder / f"can.{fmt}" for fmt in formats], channel=channel)

    def attach(self, rig: Any) -> Any:
        """Give ``rig`` (a backend with CAN frames: ``frame_sink``) this trace; returns the rig."""
        if not capabilities_of(rig).can_frames:
            raise ConfigError(
                f"--format: the {getattr(rig, 'name', type(rig).__name__)} backend has no CAN frames to trace"
            )
        rig.frame_sink = self.put
        return rig

    def follow(self, source: Callable[[], Iterable[Any]]) -> CanTrace:
        """Take the frames of a rig held by another process: ``source()`` returns the
        ``can.Message`` objects that arrived since its last call (the loop process's frame ring)."""
        self._source = source
        return self

    # lifecycle -------------------------------------------------------------------------------
    def start(self) -> CanTrace:
        """Open the files (python-can's writers) and start the writer thread."""
        import can

        for path in self._live_paths:
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
        else:
            self._discard()
        self._stop_loggers()
        if self._converted:
            self._convert()
        return self.summary()

    def _convert(self) -> None:
        """Write the formats converted after the run from the BLF recorded during it."""
        import can

        source = self._staging or next(p for p in self._live_paths if p.suffix == ".blf")
        try:
            for target in self._converted:
                with can.Logger(str(target)) as writer:
                    for msg in can.LogReader(str(source)):
                        writer.on_message_received(msg)
        except Exception as err:  # reported in the summary; the other files are complete
            if self.error is None:
                self.error = err
        finally:
            if self._staging is not None:
                self._staging.unlink(missing_ok=True)

    def __enter__(self) -> CanTrace:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def summary(self) -> dict[str, Any]:
        return {
            "files": [p.name for p in self.paths],
            "frames_rx": self.frames_rx,
            "frames_tx": self.frames_tx,
            "frames_dropped": self.frames_dropped,
            "error": None if self.error is None else f"{type(self.error).__name__}: {self.error}",
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
            while not self._stop.wait(self.interval_s):
                self._discard()  # the queue must not grow for the rest of the run

    def _discard(self) -> None:
        """Drop the queued frames (after a writer error), counting them."""
        count = len(self._queue)
        for _ in range(count):
            self._queue.popleft()
        if self._source is not None:
            count += sum(1 for _ in self._source())
        self.frames_dropped += count

    def _drain(self, slice_frames: int = SLICE_FRAMES) -> None:
        queue, loggers, channel = self._queue, self._loggers, self.channel
        if self._source is not None:
            queue.extend(self._source())
        while queue:
            for _ in range(min(slice_frames, len(queue))):
                msg = queue.popleft()
                if msg.channel is None:
                    msg.channel = channel
                if msg.is_rx:
                    self.frames_rx += 1
                else:
                    self.frames_tx += 1
                for logger in loggers:
                    logger.on_message_received(msg)
            time.sleep(0)  # let the loop thread have the interpreter between slices

    def _stop_loggers(self) -> None:
        loggers, self._loggers = self._loggers, []
        for logger in loggers:
            try:
                logger.stop()
            except Exception as err:  # a writer that fails on close: keep closing the others
                if self.error is None:
                    self.error = err

"""The run's stream: one memory-mapped file the loop process writes and the session process reads.

The loop writes every cycle's row into a ring of ``capacity`` rows and then, last, the count of
committed rows; a reader copies rows below that count. One writer, many readers, no lock: on
Linux/x86-64 and arm64 a store of an aligned 8-byte word is atomic, and CPython makes each store
in program order, so a row is complete before the count that publishes it.

* **The recorder is lossless.** It drains rows to ``data.csv`` and writes back how far it got
  (``recorded``). The loop never overwrites a row the recorder has not taken: a writer that
  would is stopped with :class:`StreamFull` (the run ends at 0 A, the recorded rows kept).
* **Views are lossy.** A view reads the newest rows it wants and keeps clear of the ones the
  writer may be overwriting (``rows_committed - capacity``); it never writes to the stream, so
  a slow or stalled view cannot slow the loop.

Layout (little-endian int64 words and float64 rows, every region page-aligned):

====================  =======================================================================
page 0                header words (:data:`HEADER`), the column names as JSON and, in its last
                      :data:`HOLD_BYTES`, the session's hold (:class:`~sashil.runtime.orphan.SessionHold`)
page 1                the mailbox: a request to the loop (a live parameter change), as JSON
page 2                the mailbox's reply, as JSON
rows                  ``capacity`` rows of ``width`` float64 (``data.csv``'s columns)
timing                the loop's timing rings and histograms (:func:`~sashil.runtime.timing.shared_size`)
frames                a run with a CAN trace: every frame sent and received (:class:`FrameWriter`)
====================  =======================================================================

The file is created whole before the loop starts (``posix_fallocate``: a full disk is an error
then, never a SIGBUS in the loop later) and every page is touched once, so the loop takes no page
fault on it. It lives in ``/dev/shm`` (memory, not a disk the kernel writes back beside the
loop), named ``sashil-<session pid>-<token>.stream``; the session removes it after the run and
:func:`remove_stale` removes those whose processes are both gone. Plain files and ``mmap`` are
used rather than :mod:`multiprocessing.shared_memory`, whose resource tracker (Python 3.10-3.12)
unlinks segments on its own when a process that merely attached exits.
"""

from __future__ import annotations

import contextlib
import json
import mmap
import os
import secrets
import struct
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sashil.runtime.timing import DEFAULT_WINDOW, TimingStats, shared_size

PAGE = mmap.PAGESIZE
MAGIC = int.from_bytes(b"SASHSTRM", "little")
VERSION = 2
#: where the stream files live: memory-backed when the system has it
STREAM_DIR = Path("/dev/shm") if Path("/dev/shm").is_dir() else Path(tempfile.gettempdir())
#: the most bytes of JSON a mailbox page holds
MAIL_BYTES = PAGE - 8

# header words (index into the int64 view of page 0)
MAGIC_W, VERSION_W, WIDTH_W, CAPACITY_W, WINDOW_W = 0, 1, 2, 3, 4
#: rows the loop has committed (written last for each row)
COMMITTED_W = 5
#: rows the recorder has written to data.csv (written by the session)
RECORDED_W = 6
#: the loop's state (:data:`STATES`)
STATE_W = 7
#: a stop request from the session: 0 none, else a signal number or :data:`STOP_BY_CALLER`
STOP_W = 8
#: mailbox: requests posted by the session, requests answered by the loop
MAIL_POSTED_W, MAIL_ANSWERED_W = 9, 10
#: the loop's counts as they move: missed deadlines (at each overrun), cycles folded into the histograms
MISSED_W, FOLDED_W = 11, 12
LOOP_PID_W, SESSION_PID_W = 13, 14
#: Python threads alive in the loop process once its loop runs
THREADS_W = 15
#: rows the recorder must have room for: 1 once the session attached a recorder (0: no recorder)
RECORDER_W = 16
COLUMNS_LEN_W, MAIL_LEN_W, REPLY_LEN_W = 17, 18, 19
#: the CAN frame ring: its capacity (0: none), frames committed, frames the reader took, frames dropped
FRAMES_CAP_W, FRAMES_W, FRAMES_READ_W, FRAMES_DROPPED_W = 20, 21, 22, 23
#: the run's health as the loop last wrote it (about ten times a second): samples lost on the link,
#: bad frames, samples the board flagged with its watchdog, cycles the controller clipped
SAMPLES_LOST_W, BAD_FRAMES_W, WATCHDOG_W, CLIPPED_W = 24, 25, 26, 27
HEALTH_WORDS = {
    "samples_lost": SAMPLES_LOST_W,
    "bad_frames": BAD_FRAMES_W,
    "watchdog": WATCHDOG_W,
    "clipped_cycles": CLIPPED_W,
}
#: the session's holding thread while it holds the hold (its kernel thread id; 0: no hold)
HOLDER_W = 28
HEADER_WORDS = 32
COLUMNS_OFFSET = 8 * HEADER_WORDS
#: the session's hold, a process-shared robust mutex, at the end of page 0 [bytes] (room for any
#: C library's ``pthread_mutex_t``: 40 bytes with glibc on x86-64, 48 on arm64)
HOLD_BYTES = 64
HOLD_OFFSET = PAGE - HOLD_BYTES

STATES = ("created", "warming", "ready", "running", "ended", "died")
#: a stop asked for by the caller (a page's STOP, a Python caller), not by a signal
STOP_BY_CALLER = 255


class StreamFull(RuntimeError):
    """The recorder fell a whole stream behind: the loop stops rather than overwrite unrecorded rows."""


def _pages(nbytes: int) -> int:
    return -(-nbytes // PAGE) * PAGE


class Stream:
    """One mapped stream file (module doc); :meth:`create` it in the session, :meth:`attach` in the loop."""

    def __init__(self, path: Path, handle: mmap.mmap, owner: bool):
        self.path = path
        self._map = handle
        self.owner = owner
        #: the header's int64 words (after :meth:`close`, a copy of their last values)
        self.header: Any = memoryview(handle)[:PAGE].cast("q")
        self.width = int(self.header[WIDTH_W])
        self.capacity = int(self.header[CAPACITY_W])
        self.window = int(self.header[WINDOW_W])
        raw = bytes(handle[COLUMNS_OFFSET : COLUMNS_OFFSET + int(self.header[COLUMNS_LEN_W])])
        self.columns: tuple[str, ...] = tuple(json.loads(raw.decode()))
        self._rows_at = 3 * PAGE
        rows_bytes = _pages(8 * self.width * self.capacity)
        self.rows = np.frombuffer(handle, dtype=np.float64, count=self.width * self.capacity, offset=self._rows_at)
        self.rows = self.rows.reshape(self.capacity, self.width)
        self._timing_at = self._rows_at + rows_bytes
        self.frames_capacity = int(self.header[FRAMES_CAP_W])
        self._frames_at = self._timing_at + _pages(shared_size(self.window))
        self._mail = memoryview(handle)[PAGE : 2 * PAGE]
        self._reply = memoryview(handle)[2 * PAGE : 3 * PAGE]
        #: the bytes of the session's hold (:data:`HOLD_OFFSET`)
        self.hold = memoryview(handle)[HOLD_OFFSET:PAGE]

    # -- making and opening ---------------------------------------------------------------------
    @staticmethod
    def size(width: int, capacity: int, window: int = DEFAULT_WINDOW, frames: int = 0) -> int:
        """Bytes of a stream of ``capacity`` rows of ``width`` columns, a timing window and a ring
        of ``frames`` CAN frames."""
        return 3 * PAGE + _pages(8 * width * capacity) + _pages(shared_size(window)) + _pages(FRAME.size * frames)

    @classmethod
    def create(
        cls,
        columns: Sequence[str],
        capacity: int,
        window: int = DEFAULT_WINDOW,
        folder: Path | None = None,
        frames: int = 0,
    ) -> Stream:
        """A new stream file for ``columns``, allocated whole and touched (module doc). OSError
        (ENOSPC) when its file system cannot hold it."""
        folder = STREAM_DIR if folder is None else Path(folder)
        names = json.dumps(list(columns)).encode()
        if COLUMNS_OFFSET + len(names) > HOLD_OFFSET:
            raise ValueError(f"{len(columns)} columns do not fit the stream's header")
        if capacity < 2:
            raise ValueError("a stream holds at least 2 rows")
        path = folder / f"sashil-{os.getpid()}-{secrets.token_hex(4)}.stream"
        size = cls.size(len(columns), capacity, window, frames)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.posix_fallocate(fd, 0, size)
            handle = mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        except BaseException:
            os.close(fd)
            path.unlink(missing_ok=True)
            raise
        os.close(fd)
        for offset in range(0, size, PAGE):  # every page resident now, not at the loop's first touch
            handle[offset] = 0
        header = memoryview(handle)[:PAGE].cast("q")
        handle[COLUMNS_OFFSET : COLUMNS_OFFSET + len(names)] = names
        header[VERSION_W], header[WIDTH_W], header[CAPACITY_W], header[WINDOW_W] = (
            VERSION,
            len(columns),
            capacity,
            window,
        )
        header[COLUMNS_LEN_W] = len(names)
        header[FRAMES_CAP_W] = frames
        header[SESSION_PID_W] = os.getpid()
        header[MAGIC_W] = MAGIC  # last: a reader that sees the magic sees the rest
        header.release()
        return cls(path, handle, owner=True)

    @classmethod
    def attach(cls, path: str | Path) -> Stream:
        """Map an existing stream file (the loop process's side); ValueError if it is not one."""
        path = Path(path)
        with open(path, "r+b") as handle:
            mapped = mmap.mmap(handle.fileno(), 0, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        words = memoryview(mapped)[:16].cast("q")
        good = words[MAGIC_W] == MAGIC and words[VERSION_W] == VERSION
        words.release()
        if not good:
            mapped.close()
            raise ValueError(f"{path}: not a sashil stream of version {VERSION}")
        return cls(path, mapped, owner=False)

    def close(self, unlink: bool | None = None) -> None:
        """Unmap; the owner (or ``unlink=True``) removes the file too. A view that still holds the
        stream reads its last counts and no rows."""
        self.rows = np.empty((0, self.width))
        header = self.header
        self.header = list(header)
        for view in (header, self._mail, self._reply, self.hold):
            view.release()
        with contextlib.suppress(BufferError):  # a timing view still held: the map goes with the process
            self._map.close()
        if self.owner if unlink is None else unlink:
            self.path.unlink(missing_ok=True)

    # -- counts -----------------------------------------------------------------------------------
    @property
    def rows_committed(self) -> int:
        return int(self.header[COMMITTED_W])

    @property
    def rows_recorded(self) -> int:
        return int(self.header[RECORDED_W])

    @property
    def state(self) -> str:
        return STATES[int(self.header[STATE_W])]

    def set_state(self, state: str) -> None:
        self.header[STATE_W] = STATES.index(state)

    def health(self) -> dict[str, int]:
        """The run's health while it runs (:data:`HEALTH_WORDS`, as the loop last wrote them)."""
        return {name: int(self.header[word]) for name, word in HEALTH_WORDS.items()}

    def timing(self, rate_hz: float) -> TimingStats:
        """The loop's :class:`~sashil.runtime.timing.TimingStats` over the stream's shared rings."""
        view = memoryview(self._map)[self._timing_at : self._timing_at + shared_size(self.window)]
        return TimingStats(rate_hz, self.window, shared=view)

    # -- the reader's side ------------------------------------------------------------------------
    #: readers in the session process share no interpreter with the loop: no window to wait for
    window_end_ns = None

    def block(self, start: int, stop: int) -> np.ndarray:
        """A copy of committed rows ``start .. stop - 1`` (row numbers as :attr:`rows_committed`
        counts them) as a ``(n, width)`` array; the caller keeps within the last ``capacity``."""
        stop = min(stop, self.rows_committed)
        if stop <= start or not self.rows.size:
            return np.empty((0, self.width))
        return self.rows[np.arange(start, stop) % self.capacity]

    def copy_rows(self, start: int, stop: int, step: int = 1) -> list[tuple[Any, ...]]:
        """Rows ``start, start + step, ... < stop`` as tuples (the recorder's reader interface:
        :meth:`sashil.recording.recorder.Recorder.copy_rows`)."""
        return [tuple(row) for row in self.block(max(start, 0), stop)[::step].tolist()]

    def frame_view(self) -> memoryview:
        """The CAN frame ring's bytes (:class:`FrameWriter`, :meth:`read_frames`)."""
        return memoryview(self._map)[self._frames_at : self._frames_at + FRAME.size * self.frames_capacity]

    def read_frames(self) -> list[tuple[float, int, int, int, bytes]]:
        """The frames committed since the last call, as ``(timestamp, id, dlc, flags, data)``, and
        tells the writer they are taken (one reader: the session's trace)."""
        start, stop = int(self.header[FRAMES_READ_W]), int(self.header[FRAMES_W])
        if stop <= start:
            return []
        view, cap = self.frame_view(), self.frames_capacity
        frames = [FRAME.unpack_from(view, FRAME.size * (k % cap)) for k in range(start, stop)]
        view.release()
        self.header[FRAMES_READ_W] = stop
        return [(stamp, ident, dlc, flags, data[:dlc]) for stamp, ident, dlc, flags, data in frames]

    # -- the mailbox --------------------------------------------------------------------------------
    def post(self, message: dict[str, Any]) -> int:
        """Put a request in the mailbox for the loop; returns its number (its answer's)."""
        data = json.dumps(message).encode()
        if len(data) > MAIL_BYTES:
            raise ValueError(f"request of {len(data)} bytes; the mailbox holds {MAIL_BYTES}")
        self._mail[: len(data)] = data
        self.header[MAIL_LEN_W] = len(data)
        number = int(self.header[MAIL_POSTED_W]) + 1
        self.header[MAIL_POSTED_W] = number  # last: the loop reads the request once it sees the number
        return number

    @property
    def mail_pending(self) -> bool:
        """A request the loop has not answered (one word compared: the loop asks every cycle)."""
        return self.header[MAIL_POSTED_W] != self.header[MAIL_ANSWERED_W]

    def take_mail(self) -> Any:
        """The pending request (decoded JSON; None when there is none)."""
        if not self.mail_pending:
            return None
        return json.loads(bytes(self._mail[: int(self.header[MAIL_LEN_W])]).decode())

    def answer(self, reply: dict[str, Any]) -> None:
        """The loop's answer to the pending request."""
        data = json.dumps(reply, default=str).encode()[:MAIL_BYTES]
        self._reply[: len(data)] = data
        self.header[REPLY_LEN_W] = len(data)
        self.header[MAIL_ANSWERED_W] = self.header[MAIL_POSTED_W]

    def reply(self, number: int) -> Any:
        """The answer to request ``number`` once the loop gave it (None until then)."""
        if self.header[MAIL_ANSWERED_W] < number:
            return None
        return json.loads(bytes(self._reply[: int(self.header[REPLY_LEN_W])]).decode())


class StreamWriter:
    """The loop's side of a :class:`Stream`: the recorder interface the loop fills rows through
    (``begin_row``/``commit_row``). ``begin_row`` gives the ring's own slot (a float64 memoryview
    the cycle writes in place: no copy, no allocation), ``commit_row`` publishes it."""

    #: rows are float64 slots: values are stored as floats, a stage signal of None as NaN
    typed_rows = True

    def __init__(self, stream: Stream):
        self.stream = stream
        self.path = stream.path
        self.columns = stream.columns
        self.capacity = stream.capacity
        self.window_end_ns: int | None = None
        self.error: BaseException | None = None
        width = stream.width
        flat = memoryview(stream.rows.data).cast("B").cast("d")
        self._slots = [flat[k * width : (k + 1) * width] for k in range(stream.capacity)]
        self._scratch = memoryview(bytearray(8 * width)).cast("d")
        self._header = stream.header
        self._head = stream.rows_committed
        self._slot_ok = True
        self._lossless = bool(stream.header[RECORDER_W])

    def begin_row(self) -> Any:
        head = self._head
        if self._lossless and head - self._header[RECORDED_W] >= self.capacity:
            self._slot_ok = False
            if self.error is None:
                self.error = StreamFull(
                    f"the recorder fell {self.capacity} rows behind (the stream is full): the run stopped "
                    "at 0 A; the rows recorded so far are kept"
                )
            return self._scratch
        self._slot_ok = True
        return self._slots[head % self.capacity]

    def commit_row(self) -> None:
        if self._slot_ok:
            self._head += 1
            self._header[COMMITTED_W] = self._head  # last: the row is complete for every reader

    @property
    def rows_committed(self) -> int:
        return self._head

    def release(self) -> None:
        """Drop the views on the map (before the stream is closed)."""
        for slot in self._slots:
            slot.release()
        self._slots = []


#: one CAN frame in the ring: timestamp [s], identifier, length, flags (FRAME_* bits), 8 data bytes
FRAME = struct.Struct("<dIBB2x8s")
FRAME_RX, FRAME_EXTENDED, FRAME_ERROR, FRAME_REMOTE = 1, 2, 4, 8


class FrameWriter:
    """The loop process's CAN frame sink (the backend's ``frame_sink``): each frame sent or received
    into the stream's frame ring, never waiting. A frame the reader has no room for is counted in
    ``FRAMES_DROPPED_W`` and left out (a trace is a view of the link, not what stops a run)."""

    def __init__(self, stream: Stream):
        self._header = stream.header
        self._view = stream.frame_view()
        self._cap = stream.frames_capacity
        self._head = int(stream.header[FRAMES_W])

    def put(self, frame: Any) -> None:
        head = self._head
        header = self._header
        if head - header[FRAMES_READ_W] >= self._cap:
            header[FRAMES_DROPPED_W] += 1
            return
        flags = (
            (FRAME_RX if frame.is_rx else 0)
            | (FRAME_EXTENDED if frame.is_extended_id else 0)
            | (FRAME_ERROR if frame.is_error_frame else 0)
            | (FRAME_REMOTE if frame.is_remote_frame else 0)
        )
        FRAME.pack_into(
            self._view,
            FRAME.size * (head % self._cap),
            frame.timestamp,
            frame.arbitration_id,
            frame.dlc,
            flags,
            bytes(frame.data),
        )
        self._head = head + 1
        header[FRAMES_W] = self._head  # last: the frame is whole for the reader

    def release(self) -> None:
        self._view.release()


def remove_stale(folder: Path | None = None) -> list[Path]:
    """Remove stream files whose processes are all gone: the one that created it (its name's pid,
    alive while it fills the header) and the session and loop processes the header names; and a
    planner's plan files whose loop process (its name's pid) is gone; returns them."""
    folder = STREAM_DIR if folder is None else Path(folder)
    removed = []
    for path in folder.glob("sashil-*.stream"):
        creator = path.name.split("-")[1]
        pids = [int(creator)] if creator.isdigit() else []
        try:
            with open(path, "rb") as handle:
                words = np.frombuffer(handle.read(8 * HEADER_WORDS), dtype=np.int64)
            if words.size == HEADER_WORDS:
                pids += [int(words[SESSION_PID_W]), int(words[LOOP_PID_W])]
        except OSError:
            continue
        if not any(pid > 0 and pid_alive(pid) for pid in pids):
            with contextlib.suppress(OSError):
                path.unlink()
                removed.append(path)
    for path in folder.glob("sashil-planner-*"):  # a preview law's plans (runtime.planner): its loop's pid
        creator = path.name.split("-")[2]
        if creator.isdigit() and not pid_alive(int(creator)):
            with contextlib.suppress(OSError):
                path.unlink()
                removed.append(path)
    return removed


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (another user's too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True

"""A loop whose session died: how it knows at once, and how it ends the run alone.

Knowing. Two signs, both the session process's own, whichever process is the loop's parent (the
loop server it was forked from, or the session for a fresh interpreter):

* **The hold** (:class:`SessionHold`, the session's side). For the run a thread of the session
  holds a process-shared robust mutex that lives in the stream's header page (``pthread_mutexattr_setrobust(3)``,
  Linux ``set_robust_list(2)``). When that thread dies, as every thread of a killed process does,
  the kernel marks the mutex's futex word ``FUTEX_OWNER_DIED`` while the thread exits, before it
  frees the process's memory, which on a loaded machine takes tens of milliseconds more for a
  session with numba loaded. The loop compares the word with the holder's thread id at the top
  of every cycle (:class:`~sashil.runtime.mailbox.LoopStop`): a memory read, no system call.
  The word is the mutex's first (glibc's ``__lock``); a C library that keeps it elsewhere is
  found out when the hold is taken, and the run goes without it.
* **The job's pipe** (:class:`SessionWatch`, the loop's side). The loop process's stdin is the read
  end of its job's pipe, whose write end the session keeps for the whole run, so the pipe's end is
  the session's end (its descriptors are closed as it exits, after its memory is freed). The read
  end is armed for signal-driven I/O (``O_ASYNC``, ``F_SETOWN``: ``fcntl(2)``, ``pipe(7)``): the
  kernel sends ``SIGIO`` when the last writer closes, and the handler sets the loop's stop flag.

Ending. The loop process stops as it does for a signal (0 A with the road at rest, read on until
the coil's current has decayed, deactivate, close). The session's recorder wrote rows up to the
stream's ``recorded`` word; the rest, down to the safe state's row, is appended to ``data.csv``
here in the same format, ``timing.npz`` is written and ``summary.json`` through the folder's writer (the
:class:`~sashil.writer.folder_writer.FolderWriter`, as the session would have: ``exit_status:
error``, ``stop_reason``: the session died). The stream file stays, marked ``died``, until the
next run's :func:`~sashil.runtime.stream.remove_stale`.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import logging
import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import SashilError
from sashil.runtime.runner import end_summary
from sashil.runtime.stream import HOLD_BYTES, HOLDER_W, RECORDED_W, Stream
from sashil.runtime.stream_recorder import append, format_block
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

log = logging.getLogger(__name__)

#: how long the session waits for its holding thread to take or let go of the hold [s]
HOLD_WAIT_S = 5.0


class SessionHold:
    """The session's hold on its stream (module doc): :meth:`take` before the loop is told to go,
    :meth:`release` once the loop has ended (before the stream is unmapped: the holding thread's
    robust list points into it until then). ``held`` says whether the loop can watch it."""

    def __init__(self, stream: Stream):
        self._stream = stream
        self._mutex: Any = None
        self._thread: threading.Thread | None = None
        self._taken = threading.Event()
        self._let_go = threading.Event()
        self._error: str | None = None
        self._holder = 0
        #: the holding thread holds the hold, and the loop can read it (``HOLDER_W`` set)
        self.held = False

    def take(self) -> SessionHold:
        """Make the mutex and have a thread of this process hold it; on a system where that cannot
        be done (no such C functions, another layout) the stream says there is no hold."""
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            attr = ctypes.create_string_buffer(64)  # pthread_mutexattr_t: 4 bytes with glibc
            mutex = (ctypes.c_char * HOLD_BYTES).from_buffer(self._stream.hold)
            calls = (
                ("pthread_mutexattr_init", (attr,)),
                ("pthread_mutexattr_setpshared", (attr, 1)),  # PTHREAD_PROCESS_SHARED
                ("pthread_mutexattr_setrobust", (attr, 1)),  # PTHREAD_MUTEX_ROBUST
                ("pthread_mutex_init", (mutex, attr)),
            )
            for name, args in calls:
                if code := getattr(libc, name)(*args):
                    raise OSError(code, f"{name}: {os.strerror(code)}")
        except (OSError, AttributeError) as err:
            log.debug("no session hold (%s): the loop watches the job's pipe alone", err)
            return self
        self._mutex = mutex
        self._thread = threading.Thread(target=self._hold, args=(libc,), name="sashil-session-hold", daemon=True)
        self._thread.start()
        self._taken.wait(HOLD_WAIT_S)
        if self.held:
            self._stream.header[HOLDER_W] = self._holder
        else:
            log.debug("no session hold (%s): the loop watches the job's pipe alone", self._error)
        return self

    def _hold(self, libc: Any) -> None:
        """The holding thread: lock, tell, wait for :meth:`release`, unlock (the owner must)."""
        mutex = self._mutex
        if code := libc.pthread_mutex_lock(mutex):
            self._error = f"pthread_mutex_lock: {os.strerror(code)}"
            self._taken.set()
            return
        self._holder = threading.get_native_id()
        word = self._stream.hold.cast("i")
        try:
            self.held = word[0] == self._holder  # the futex word first, as glibc lays the mutex out
        finally:
            word.release()
        if not self.held:
            self._error = "the mutex's first word is not its owner's thread id"
        self._taken.set()
        self._let_go.wait()
        libc.pthread_mutex_unlock(mutex)

    def release(self) -> None:
        """Let go of the hold (the loop has ended), before the stream is unmapped."""
        if self._thread is None:
            return
        if self.held:
            self._stream.header[HOLDER_W] = 0
        self._let_go.set()
        self._thread.join(HOLD_WAIT_S)
        self._thread = None
        self._mutex = None  # the ctypes view of the stream's map, which the map's close needs gone


class SessionWatch:
    """The loop process's watch on its session (module doc): :attr:`gone` turns True, and
    ``on_gone`` is called once, when the session lets go of its hold on ``stream`` (its holding
    thread died, or it released the hold) or its end of the pipe ``fd`` closes. :meth:`start` arms
    it; the loop reads :attr:`hold` against :attr:`holder` every cycle and calls :meth:`lost` when
    they differ; :meth:`check` looks at both without blocking; :meth:`stop` disarms it."""

    __slots__ = ("_armed", "_fd", "_on_gone", "_previous", "_stream", "gone", "hold", "holder")

    def __init__(self, fd: int, stream: Stream | None, on_gone: Callable[[], None] = lambda: None):
        self._fd = fd
        self._stream = stream
        self._on_gone = on_gone
        self._previous: Any = None
        self._armed = False
        #: the session has ended: nobody records the stream or writes the run's summary
        self.gone = False
        #: the hold's futex word (None: the session holds none) and its value while held
        self.hold: Any = None
        self.holder = 0

    def start(self) -> SessionWatch:
        """Arm the watch (main thread): the hold's word mapped when the session holds it, ``SIGIO``
        handled (its default action ends the process) before the pipe is set to signal its end;
        a last look catches a session that ended before."""
        if self._stream is not None and self._stream.header[HOLDER_W]:
            self.holder = int(self._stream.header[HOLDER_W])
            self.hold = self._stream.hold.cast("i")
        self._previous = signal.signal(signal.SIGIO, self._signalled)
        fcntl.fcntl(self._fd, fcntl.F_SETOWN, os.getpid())
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_ASYNC | os.O_NONBLOCK)
        self._armed = True
        self.check()
        return self

    def _signalled(self, signum: int, frame: object) -> None:
        self.check()

    def lost(self) -> None:
        """The session is gone (once: ``on_gone``)."""
        if not self.gone:
            self.gone = True
            self._on_gone()

    def check(self) -> bool:
        """Whether the session has ended: its hold let go, or its pipe ended (read without
        blocking: no bytes; the session sends none while the loop runs, and any it did are dropped)."""
        if self.gone:
            return True
        ended = self.hold is not None and self.hold[0] != self.holder
        if not ended:
            try:
                ended = not os.read(self._fd, 4096)
            except OSError:  # BlockingIOError: open, nothing to read (the session holds its end)
                pass
        if ended:
            self.lost()
        return self.gone

    def stop(self) -> None:
        """Disarm: the pipe signals no more, then ``SIGIO``'s previous handler is back."""
        if self._armed:
            self._armed = False
            with contextlib.suppress(OSError):
                flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
                fcntl.fcntl(self._fd, fcntl.F_SETFL, flags & ~os.O_ASYNC)
            signal.signal(signal.SIGIO, self._previous if self._previous is not None else signal.SIG_DFL)
        if self.hold is not None:
            self.hold.release()
            self.hold = None


def finish_alone(
    stream: Stream,
    writer: Any,
    data: Path,
    spec: RunSpec,
    end: dict[str, Any],
    timing: Any,
    verb: str = "run",
) -> None:
    """Append the unrecorded rows to ``data`` (the run's data.csv, or a drop's cycles file) and
    write the documents of its folder for ``verb`` (module doc)."""
    start, stop = int(stream.header[RECORDED_W]), writer.rows_committed
    folder = data.parent
    fd = os.open(data, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        if os.fstat(fd).st_size == 0:
            append(fd, ",".join(stream.columns) + "\n")
        append(fd, format_block(stream.columns, stream.block(start, stop)))
        os.fsync(fd)
    finally:
        os.close(fd)
    stream.header[RECORDED_W] = stop
    stream.set_state("died")
    run = RunFolder(folder, verb)
    run.write_timing(timing)
    error = SashilError(f"{end['stop_reason']}: the loop stopped at 0 A and wrote the rest of the data itself")
    writer = Documents([FolderWriter(run, verb, {}, several=False)])  # the folder's one writer of summary.json
    writer.summary(
        None,
        {
            "verb": verb,
            **end_summary(
                end,
                exit_status="error",
                timing=timing.summary(),
                error=error,
                realtime=end["realtime"],
                recording={"rows_written": stop, "rows_dropped": 0, "written_by": "the loop process"},
            ),
            "controller": spec.stage.law,
            "driver": spec.rig.backend,
            "tuning": end["tuning"],
            "loop_process": {
                "pid": os.getpid(),
                "threads": end["threads"],
                "start_ns": end.get("start_ns"),
                "session_died": True,
            },
        },
    )

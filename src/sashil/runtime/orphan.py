"""A loop whose session died: how it notices at once, and how it ends the run alone.

Noticing (:class:`SessionWatch`). The loop process holds the read end of its job's pipe (its stdin)
and the session holds the write end for the whole run, so the pipe's end is the session's end,
whichever process is the loop's parent (the loop server it was forked from, or the session for a
fresh interpreter). The read end is armed for signal-driven I/O (``O_ASYNC``, ``F_SETOWN``: Linux
``fcntl(2)``, ``pipe(7)``): the kernel sends ``SIGIO`` the moment the last writer closes, and the
handler sets the loop's stop flag, which the loop reads at the top of its next cycle like any
stop, with no system call of its own per cycle. A ``pidfd`` of the session (``pidfd_open(2)``),
looked at about ten times a second with the run's health, backs it up: a session whose pipe end a
child of its own still holds (a ``fork`` that kept it) is seen gone all the same.

Ending. The loop process stops as it does for a signal (0 A with the road at rest, read on until
the coil's current has decayed, deactivate, close). The session's recorder wrote rows up to the
stream's ``recorded`` word; the rest, down to the safe state's row, is appended to ``data.csv``
here in the same format, and ``timing.npz`` and ``summary.json`` are written (``exit_status:
error``, ``stop_reason``: the session died). The stream file stays, marked ``died``, until the
next run's :func:`~sashil.runtime.stream.remove_stale`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import signal
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import SashilError
from sashil.recording.run_folder import RunFolder
from sashil.recording.summary_writer import write_summary
from sashil.runtime.runner import end_summary
from sashil.runtime.stream import RECORDED_W, Stream
from sashil.runtime.stream_recorder import append, format_block

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec


class SessionWatch:
    """The loop process's watch on its session (module doc): :attr:`gone` turns True, and
    ``on_gone`` is called once, when the pipe ``fd`` ends or the process ``session_pid`` has
    ended. :meth:`start` arms it, :meth:`check` looks without blocking, :meth:`stop` disarms it."""

    __slots__ = ("_armed", "_fd", "_on_gone", "_pidfd", "_previous", "_session_pid", "gone")

    def __init__(self, fd: int, session_pid: int | None, on_gone: Callable[[], None] = lambda: None):
        self._fd = fd
        self._session_pid = session_pid
        self._on_gone = on_gone
        self._pidfd = -1
        self._previous: Any = None
        self._armed = False
        #: the session has ended: nobody records the stream or writes the run's summary
        self.gone = False

    def start(self) -> SessionWatch:
        """Arm the watch (main thread): ``SIGIO`` handled first (its default action ends the
        process), then the pipe set to signal its end; a last look catches a session that ended before."""
        if self._session_pid is not None:
            with contextlib.suppress(OSError):  # no pidfd (a kernel before 5.3): the pipe alone
                self._pidfd = os.pidfd_open(self._session_pid)
        self._previous = signal.signal(signal.SIGIO, self._signalled)
        fcntl.fcntl(self._fd, fcntl.F_SETOWN, os.getpid())
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_ASYNC | os.O_NONBLOCK)
        self._armed = True
        self.check()
        return self

    def _signalled(self, signum: int, frame: object) -> None:
        self.check()

    def check(self) -> bool:
        """Whether the session has ended: the pipe read without blocking (its end: no bytes; the
        session sends none while the loop runs, and any it did are dropped) and the pidfd polled."""
        if self.gone:
            return True
        ended = False
        try:
            ended = not os.read(self._fd, 4096)
        except BlockingIOError:  # open, nothing to read: the session holds its end
            pass
        except OSError:  # a descriptor that cannot be read says nothing of the session
            pass
        if not ended and self._pidfd >= 0:
            ended = bool(select.select([self._pidfd], [], [], 0.0)[0])
        if ended:
            self.gone = True
            self._on_gone()
        return self.gone

    def stop(self) -> None:
        """Disarm: the pipe signals no more, then ``SIGIO``'s previous handler is back."""
        if self._armed:
            self._armed = False
            with contextlib.suppress(OSError):
                flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
                fcntl.fcntl(self._fd, fcntl.F_SETFL, flags & ~os.O_ASYNC)
            signal.signal(signal.SIGIO, self._previous if self._previous is not None else signal.SIG_DFL)
        if self._pidfd >= 0:
            os.close(self._pidfd)
            self._pidfd = -1


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
    write_summary(
        run,
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

"""The session's side of a loop in its own process: start it, feed its views, end the run's documents.

The loop process (:mod:`sashil.runtime.worker`) is a fork of this process's loop server
(:mod:`sashil.runtime.loop_server`), a fresh interpreter started once with its imports and kernels
loaded: no fork of this process's threads and locks, no re-import of the caller's ``__main__`` (a
script or notebook that calls ``sashil.run(MyLaw)`` runs once), and the law crosses as its name in
the run's assembled spec, never pickled. sashil's real-time loop is Linux-only (``SCHED_FIFO``,
``/dev/shm``, robust futexes, a pipe's ``O_ASYNC``).

The session process keeps everything that is not the cycle: the recorder
(:class:`~sashil.runtime.stream_recorder.StreamRecorder`), the views (the live view, progress,
a bench page), the tuning socket (its requests go to the loop through the stream's mailbox), and
``summary.json``, written once at the end (:func:`end_summary`).

Who stops the loop: a Ctrl-C on the terminal reaches both processes (one process group); the loop
stops on its own signal, and the session, which catches SIGINT, SIGTERM and SIGHUP for the run,
writes the signal into the stream's stop word, so a signal sent to the session alone stops the
loop too. A caller's :class:`~sashil.runtime.signals.StopFlag` is passed on the same way.

Faults: if the loop process dies (``kill -9``), the coil is left to the board until the session
acts: sashil's board cuts it when its watchdog expires, the RT-DAC/USB2 has no watchdog and keeps
its last outputs. The session keeps every committed row, then reopens the link, commands 0 A and
confirms the current it reads (:func:`confirm_safe`) rather than assume it, and ``summary.json``
says the loop died. If the session dies, the loop sees it at its next cycle, whichever process
is its parent: a thread of the session holds a robust mutex in the stream for the run, whose word
the kernel marks as the thread dies, and the session's write end of the job's pipe (the loop's
stdin) closes as the process ends (both held from :meth:`LoopProcess.go` to :meth:`LoopProcess.close`).
The loop then stops at 0 A as a stop signal would and ends the run itself
(:mod:`sashil.runtime.orphan`).
"""

from __future__ import annotations

import json
import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil import errors
from sashil.drivers import open_rig
from sashil.drivers.interface import FLAG_WATCHDOG, SAFE_COMMAND, capabilities_of
from sashil.errors import error_of
from sashil.runtime import loop_server
from sashil.runtime.loop_server import ForkedLoop
from sashil.runtime.mailbox import CALLER_STOP
from sashil.runtime.orphan import SessionHold
from sashil.runtime.runner import LoopHooks, RunOutcome, check_disk, losses, outcome_of
from sashil.runtime.signals import STOP_SIGNALS, StopFlag
from sashil.runtime.stream import (
    FRAME_ERROR,
    FRAME_EXTENDED,
    FRAME_REMOTE,
    FRAME_RX,
    FRAMES_DROPPED_W,
    MISSED_W,
    STOP_BY_CALLER,
    STOP_W,
    Stream,
    remove_stale,
)
from sashil.runtime.stream_recorder import StreamRecorder
from sashil.runtime.tune_socket import TuneServer

if TYPE_CHECKING:
    from sashil.config.parts import RigParts, RunSpec
    from sashil.writer.run_folder import RunFolder

#: the most a tuning request waits for the loop's answer [s] (a 1 Hz loop answers within 1 s)
REPLY_WAIT_S = 30.0
#: how often the session looks at its messages, the caller's stop flag and the loop's health [s]
POLL_S = 0.02
#: the loop process's messages the session passes on to the caller as they come
SAID = ("progress", "warning", "prompt")
#: current at or below which a reopened rig counts as safe [A]
SAFE_CURRENT_A = 0.05
#: how long a reopened rig's coil may take to reach it [s] (the watchdog's 50 ms and the coil's lag)
CONFIRM_S = 1.0


def raise_error(fields: Mapping[str, Any]) -> None:
    """Raise :func:`error_of` the loop process's report."""
    raise error_of(fields)


class LiveTiming:
    """The loop's counts as the session's views read them while it runs (``cycles``,
    ``missed_deadlines``, ``value_ns``): from the stream, never from the loop's objects."""

    def __init__(self, stream: Stream, rate_hz: float):
        self._stream = stream
        self._stats = stream.timing(rate_hz)

    @property
    def cycles(self) -> int:
        return self._stream.rows_committed

    @property
    def missed_deadlines(self) -> int:
        return int(self._stream.header[MISSED_W])

    def value_ns(self, name: str, cycle: int) -> int | None:
        self._stats.cycles = self.cycles
        return self._stats.value_ns(name, cycle)


class LoopProcess:
    """One loop process: :meth:`start`, :meth:`wait_ready`, :meth:`go`, :meth:`wait_end`."""

    def __init__(
        self,
        spec: RunSpec,
        duration_s: float | None,
        *,
        realtime: bool = True,
        tune: bool = True,
        can_trace: bool = False,
    ):
        """``spec``: the assembled run, all the loop process is sent of it, with its ``plan`` (the
        plan's ``kind`` and values, which the loop process builds the plan from: the
        built-in plans of :mod:`sashil.plans` or the ``sashil.plans`` entry points). ``can_trace``: the loop process puts
        every CAN frame into the stream (:meth:`can_frames`)."""
        if not spec.plan:
            raise ValueError("LoopProcess: the spec names no plan (assemble it with one)")
        self.job = {
            "can_trace": can_trace,
            "spec": spec.to_json(),
            "duration_s": duration_s,
            "realtime": realtime,
            "tune": tune,
            "log_level": _log_level(),
            "sys_path": list(sys.path),  # a law's module imports there as it does here
        }
        self.spec = spec
        self.rate_hz = spec.loop.rate_hz
        #: the CPU the loop pins itself to (``loop.rt.cpu``; None: no pinning)
        self.loop_cpu: int | None = spec.loop.rt.cpu if realtime else None
        self.process: ForkedLoop | subprocess.Popen[bytes] | None = None
        #: what the loop server said while it prepared, before this loop's messages began
        self._early: list[str] = []
        self.stream: Stream | None = None
        self.ready: dict[str, Any] = {}
        self._messages = -1
        self._buffer = b""
        self._lock = threading.Lock()  # one tuning request in the mailbox at a time
        self._started = self._spawned = 0.0
        #: seconds from the job to ready: what the run waited for (the law imported and warmed, the
        #: board greeted; the rest was done ahead when the process was started ahead)
        self.startup_s: float | None = None
        #: seconds from the spawn to ready: the interpreter, the imports, the warm-up, the greeting
        self.since_spawn_s: float | None = None
        #: each thread's CPUs before the session kept off the loop's (``loop.rt.cpu``)
        self._affinity: dict[int, set[int]] = {}
        #: what the session did about the loop's CPU, for the summary's ``realtime``
        self.session_affinity: str | None = None
        #: this process's hold on the stream while the loop runs (:meth:`go` to :meth:`close`)
        self._hold: SessionHold | None = None

    # -- start ------------------------------------------------------------------------------------
    def start(self) -> LoopProcess:
        """Give the job to a new loop process (:func:`_spawn`)."""
        self._started = time.perf_counter()
        remove_stale()
        self.process, self._messages, self._spawned = _spawn(self._early)
        self._keep_off(self.loop_cpu)
        assert self.process.stdin is not None
        self.process.stdin.write((json.dumps(self.job) + "\n").encode())
        self.process.stdin.flush()
        return self

    def _keep_off(self, cpu: int | None) -> None:
        """Move every thread of this process off ``cpu`` (the loop's, ``loop.rt.cpu``), after the
        loop process was started (it pins itself there); :meth:`close` moves them back."""
        if cpu is None:
            return
        try:
            for tid in (int(name) for name in os.listdir("/proc/self/task")):
                allowed = os.sched_getaffinity(tid)
                if cpu in allowed and len(allowed) > 1:
                    os.sched_setaffinity(tid, allowed - {cpu})
                    self._affinity[tid] = allowed
            self.session_affinity = f"kept off CPU {cpu}"
        except OSError as err:
            self.session_affinity = f"could not keep off CPU {cpu}: {err.strerror or err}"

    def _read(self, timeout_s: float) -> list[dict[str, Any]]:
        """The messages that arrived within ``timeout_s`` (an empty list at the end of the pipe too)."""
        if self._messages < 0:
            return []
        ready, _, _ = select.select([self._messages], [], [], timeout_s)
        if not ready:
            return []
        chunk = os.read(self._messages, 65536)
        if not chunk:
            os.close(self._messages)
            self._messages = -1
            return []
        self._buffer += chunk
        *lines, self._buffer = self._buffer.split(b"\n")
        return [json.loads(line) for line in lines if line.strip()]

    def wait_ready(self, say: Callable[[str, str], None]) -> dict[str, Any]:
        """Forward the warm-up's progress (``say(kind, text)``) until the loop is ready; raise the
        loop's error (a port that cannot be opened: ConfigError) if it fails first."""
        assert self.process is not None
        for line in self._early:
            say("progress", line)
        self._early.clear()
        while True:
            for message in self._read(POLL_S):
                kind = message["kind"]
                if kind == "ready":
                    self.startup_s = time.perf_counter() - self._started
                    self.since_spawn_s = time.perf_counter() - self._spawned
                    self.ready = message
                    self.stream = Stream.attach(message["stream"])
                    self.stream.owner = True
                    return message
                if kind == "error":
                    self.process.wait()
                    raise_error(message)
                if kind in SAID:
                    say(kind, message["text"])
            if self._messages < 0:
                code = self.process.wait()
                raise errors.SashilError(f"the loop process ended before it was ready (exit status {code})")

    def go(self, data_path: Path, verb: str = "run") -> None:
        """Start the loop (the run folder is made and the recorder writing ``data_path``, where the
        loop appends the rest of the rows itself if the session dies, with the ``verb``'s summary),
        this process's hold on the stream taken first (:class:`~sashil.runtime.orphan.SessionHold`)."""
        assert self.process is not None and self.process.stdin is not None and self.stream is not None
        self._hold = SessionHold(self.stream).take()
        message = {"folder": str(data_path.parent), "data": data_path.name, "verb": verb}
        self.process.stdin.write((json.dumps(message) + "\n").encode())
        self.process.stdin.flush()

    def abort(self) -> None:
        """End a loop process that was never told to go (nothing was energised)."""
        if self.process is not None and self.process.stdin is not None:
            self.process.stdin.close()
            self.process.wait()
        self.close()

    # -- run ----------------------------------------------------------------------------------------
    def wait_end(self, stop: StopFlag | None, say: Callable[[str, str], None]) -> dict[str, Any] | None:
        """Pass stop requests on and messages up until the loop process ends; its ``end`` message,
        or None if it died without one."""
        assert self.process is not None and self.stream is not None
        header = self.stream.header
        end = None
        while True:
            for message in self._read(POLL_S):
                if message["kind"] == "end":
                    end = message
                elif message["kind"] in SAID:
                    say(message["kind"], message["text"])
            if stop is not None and stop.requested and not header[STOP_W]:
                header[STOP_W] = _stop_code(stop)
            if self._messages < 0 and self.process.poll() is not None:
                return end

    def run(self, folder: RunFolder, duration_s: float | None, hooks: LoopHooks) -> RunOutcome:
        """The ready loop's run for a session (:func:`~sashil.runtime.session.run_session`): the
        stream recorded into ``folder``'s ``data.csv`` (:func:`drive`), the tuning socket served
        there with ``tune``, and the loop's end read into the keys of every loop run's summary."""
        ended = drive(
            self,
            folder.file("data.csv"),
            duration_s,
            say=lambda kind, text: hooks.say(text),
            live=hooks.live,
            tune_folder=folder.path if hooks.tune else None,
            stop=hooks.stop,
            verb=hooks.verb,
        )
        affinity = {"session": self.session_affinity} if self.session_affinity else {}
        since_spawn_s = None if self.since_spawn_s is None else round(self.since_spawn_s, 3)
        pid = self.process.pid if self.process else None
        timing = ended.timing.copy()  # the stream's shared rings end with the process
        return ended.outcome(
            timing,
            recording=ended.recording,
            realtime={**ended.end.get("realtime", {}), **affinity},
            facts=ended.facts(pid, self.startup_s, since_spawn_s=since_spawn_s),
        )

    def pass_stop(self, stop: StopFlag) -> Callable[[], None]:
        """What passes a request of ``stop`` to the loop: its code into the stream's stop word."""
        header = self.stream.header if self.stream is not None else None

        def tell() -> None:
            if header is not None and not header[STOP_W]:
                header[STOP_W] = _stop_code(stop)

        return tell

    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """A tuning request answered by the loop between two cycles (the tuning socket's handler)."""
        assert self.stream is not None and self.process is not None
        with self._lock:
            number = self.stream.post(message)
            deadline = time.monotonic() + REPLY_WAIT_S
            while time.monotonic() < deadline:
                reply = self.stream.reply(number)
                if reply is not None:
                    return dict(reply)
                if self.process.poll() is not None:
                    return {"ok": False, "error": "not applied: the run has ended"}
                time.sleep(0.001)
            return {"ok": False, "error": f"not applied: the loop did not reach a cycle within {REPLY_WAIT_S:g} s"}

    def can_frames(self) -> list[Any]:
        """The CAN frames the loop process sent and received since the last call, as ``can.Message``."""
        import can

        if self.stream is None:
            return []
        return [
            can.Message(
                timestamp=stamp,
                arbitration_id=ident,
                dlc=dlc,
                data=data,
                is_rx=bool(flags & FRAME_RX),
                is_extended_id=bool(flags & FRAME_EXTENDED),
                is_error_frame=bool(flags & FRAME_ERROR),
                is_remote_frame=bool(flags & FRAME_REMOTE),
            )
            for stamp, ident, dlc, flags, data in self.stream.read_frames()
        ]

    def frames_dropped(self) -> int:
        """CAN frames the loop process left out because the trace's ring was full."""

        return 0 if self.stream is None else int(self.stream.header[FRAMES_DROPPED_W])

    def close(self) -> None:
        """Give the session's CPUs back and let go of the loop process: the hold on its stream and
        its job's pipe (either let go while the loop still runs stops it at 0 A to end the run
        alone: :mod:`sashil.runtime.orphan`), its messages and the stream."""
        for tid, allowed in self._affinity.items():
            try:
                os.sched_setaffinity(tid, allowed)
            except OSError:  # a thread that has ended since
                pass
        self._affinity.clear()
        if self._hold is not None:  # before the stream is unmapped
            self._hold.release()
            self._hold = None
        if self._messages >= 0:
            os.close(self._messages)
            self._messages = -1
        if self.process is not None and self.process.stdin is not None and not self.process.stdin.closed:
            self.process.stdin.close()
        if self.stream is not None:
            self.stream.close()
            self.stream = None


def _spawn(early: list[str]) -> tuple[ForkedLoop | subprocess.Popen[bytes], int, float]:
    """A new loop process, forked by this process's loop server (:mod:`sashil.runtime.loop_server`;
    the server's progress while it prepares is appended to ``early``), or a fresh interpreter when
    no server can be had; the descriptor its messages arrive on, and when it was asked for
    (``time.perf_counter``). Either way it has imported and warmed its kernels, or does so, and
    waits for its job on stdin."""
    started = time.perf_counter()
    read_fd, write_fd = os.pipe()
    try:
        try:
            process: ForkedLoop | subprocess.Popen[bytes] = loop_server.server().fork(write_fd, early.append)
        except OSError as err:
            logging.getLogger(__name__).warning("no loop server (%s): the loop process starts afresh", err)
            process = subprocess.Popen(
                [sys.executable, "-m", "sashil.runtime.worker", "--messages", str(write_fd)],
                stdin=subprocess.PIPE,
                pass_fds=(write_fd,),
                close_fds=True,
            )
    except BaseException:
        os.close(read_fd)
        raise
    finally:
        os.close(write_fd)
    return process, read_fd, started


def start_ahead() -> None:
    """Start this process's loop server now: its interpreter, imports and kernels are ready by the
    time the session has resolved the config (``sashil run`` calls this first; a bench page at its
    start and after each run, which starts a new one only if it has ended), and each run's loop
    process is a fork of it. The server serves this process's later runs too (an in-process
    session: a lab's script, a test worker) and ends with it: the process's end closes the control
    socket (:mod:`sashil.runtime.loop_server`)."""
    loop_server.server()


def _log_level() -> int | None:
    """The ``sashil`` logger's level when the command line set it up (the loop logs as the session
    would, to the same stderr), else None (a library caller's logging is its own)."""
    logger = logging.getLogger("sashil")
    if any(getattr(handler, "_sashil", False) for handler in logger.handlers):
        return logger.getEffectiveLevel()
    return None


def _stop_code(stop: StopFlag) -> int:
    name = stop.signal_name or ""
    return int(getattr(signal, name, STOP_BY_CALLER)) if name.startswith("SIG") else STOP_BY_CALLER


class SessionSignals:
    """SIGINT, SIGTERM and SIGHUP caught by the session for the run: each writes its number into
    the stream's stop word (the loop stops at its next cycle) and is remembered for the exit code.
    A third one ends a loop process that does not stop (``kill``: the session then reopens the rig,
    commands 0 A and confirms it, as after any death of the loop)."""

    #: stop signals after which a loop process that has not ended is killed
    KILL_AFTER = 3

    def __init__(self, flag: StopFlag, process: LoopProcess | None = None):
        self.flag = flag
        self.process = process
        self.count = 0
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> SessionSignals:
        if threading.current_thread() is threading.main_thread():

            def handler(signum: int, frame: object) -> None:
                self.count += 1
                self.flag.request(signal.Signals(signum).name)
                child = self.process.process if self.process is not None else None
                if self.count >= self.KILL_AFTER and child is not None and child.poll() is None:
                    child.kill()

            self._previous = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._previous.items():
            signal.signal(sig, old)


def confirm_safe(parts: RigParts, say: Callable[[str, str], None]) -> dict[str, Any]:
    """After the loop process died: reopen the rig, command 0 A and read the coil current until it
    is at most :data:`SAFE_CURRENT_A` (for up to :data:`CONFIRM_S`), then leave the rig
    deactivated, with what its deactivation confirmed (``safe_state_confirmed``: a board that keeps
    its last outputs reads them back at rest). Says what was found; a simulated rig ended with the
    process that held it. Every backend that declares a link is reopened: sashil's board with its
    watchdog, and the RT-DAC/USB2, which has none."""

    found: dict[str, Any] = {"reopened": False}
    rig = open_rig(parts)
    if not capabilities_of(rig).link:
        found["note"] = "the simulated rig ended with the loop process"
        return found
    try:
        rig.configure()
        sample = rig.read(time.monotonic_ns(), 0)
        found.update(reopened=True, first_current_a=round(float(sample.current_a), 4))
        found["watchdog"] = bool(sample.flags & FLAG_WATCHDOG)
        rig.activate()
        deadline = time.monotonic() + CONFIRM_S
        while abs(float(sample.current_a)) > SAFE_CURRENT_A and time.monotonic() < deadline:
            rig.write(SAFE_COMMAND, time.monotonic_ns(), 0)
            sample = rig.read(time.monotonic_ns(), 0)
        found["current_a"] = round(float(sample.current_a), 4)
        found["safe"] = abs(float(sample.current_a)) <= SAFE_CURRENT_A
        rig.write(SAFE_COMMAND, time.monotonic_ns(), 0)
        rig.deactivate()
        # a backend that reads back its outputs (a board with no watchdog of its own) says whether they rest
        found.update(getattr(rig, "safe_state", {}))
    except Exception as err:
        found["error"] = f"{type(err).__name__}: {err}"
    finally:
        rig.close()
    if found.get("reopened") and "current_a" in found:
        watchdog = " (its watchdog had cut the current)" if found["watchdog"] else ""
        line = f"the rig reopened{watchdog}: coil at {found['current_a']:.3f} A"
    else:
        line = f"the rig could not be reopened to confirm 0 A: {found.get('error')}"
    say("warning", line)
    return found


@dataclass
class LoopEnd:
    """How a run in a loop process ended, as the session saw it (:func:`drive`)."""

    #: the loop's ``end`` message (exit status, trips, timing counters, link statistics, the plan's
    #: facts, ...); when the loop process died, what the session found instead (``loop_died``)
    end: dict[str, Any]
    error: BaseException | None
    exit_status: str
    #: the loop's timing, read from the stream's shared rings (valid until :meth:`LoopProcess.close`)
    timing: Any
    #: the recorder's rows written and dropped
    recording: dict[str, Any]
    stop: StopFlag

    def facts(self, pid: int | None, startup_s: float | None, **more: Any) -> dict[str, Any]:
        """The loop process's facts for summary.json: its pid, threads, start-up and the loop's
        start on CLOCK_MONOTONIC (``start_ns``: the record's ``time_s`` counts from it, so another
        process's clock can be laid beside the record) (and ``more``); ``died`` when it died."""
        end = self.end
        facts = {
            "pid": pid,
            "threads": end.get("threads"),
            "startup_s": None if startup_s is None else round(startup_s, 3),
            "start_ns": end.get("start_ns"),
            **more,
        }
        if "loop_died" in end:
            facts["died"] = end["loop_died"]
        return facts

    def outcome(
        self,
        timing: Any,
        *,
        recording: dict[str, Any] | None,
        realtime: dict[str, Any],
        facts: dict[str, Any],
        stream: dict[str, Any] | None = None,
        can_trace: dict[str, Any] | None = None,
    ) -> RunOutcome:
        """The :class:`~sashil.runtime.runner.RunOutcome` of the run, wherever a session ran it in a
        loop process (a session's run, a verb's plan): ``timing`` copied before the process closed,
        ``recording`` None for a temporary stream file, which is no recording."""
        return outcome_of(
            self.end,
            error=self.error,
            exit_status=self.exit_status,
            stop=self.stop,
            timing=timing,
            realtime=realtime,
            recording=recording,
            stream=stream,
            can_trace=can_trace,
            loop_process=facts,
        )


def drive(
    process: LoopProcess,
    data_path: Path,
    duration_s: float | None,
    *,
    say: Callable[[str, str], None],
    live: Any = None,
    tune_folder: Path | None = None,
    stop: StopFlag | None = None,
    verb: str = "run",
) -> LoopEnd:
    """The session's part of a run in the ready loop ``process``: check the disk, record the stream
    into ``data_path``, serve the views (``live``: ``start(stream, timing)``) and, with
    ``tune_folder``, the tuning socket there; tell the loop to go, pass stop requests and signals
    on, and pass its messages up (``say(kind, text)``: progress, warning, prompt) until it ends.
    If it died, keep its rows and reopen the rig to confirm 0 A (:func:`confirm_safe`). A run that
    lost more than the run's loop parts allow ends ``lossy``. A failure before the go ends the loop process
    with nothing energised and raises."""

    stream = process.stream
    assert stream is not None
    rate = process.rate_hz
    recorder, server = _before_go(process, data_path, duration_s, say, live, tune_folder)
    flag = stop if stop is not None else StopFlag()
    flag.on_request = process.pass_stop(flag)  # a stop reaches the loop's next cycle, not the next poll
    try:
        with SessionSignals(flag, process):
            process.go(data_path, verb)
            end = process.wait_end(flag, say)
    finally:
        flag.on_request = None
        if server is not None:
            server.stop()
    error: BaseException | None = None
    try:
        recorder.close()
    except OSError as err:
        error = err
    timing = stream.timing(rate)
    end, error, status = _ending(process, end, error, timing, flag, say)
    lost = losses(process.spec.loop, timing, end.get("link")) if error is None and status == "ok" else None
    if lost is not None:
        error, status = lost, "lossy"
        say("warning", str(lost))
    return LoopEnd(end, error, status, timing, recorder.summary(), flag)


def _before_go(
    process: LoopProcess,
    data_path: Path,
    duration_s: float | None,
    say: Callable[[str, str], None],
    live: Any,
    tune_folder: Path | None,
) -> tuple[StreamRecorder, Any]:
    """What runs before the loop is told to go: the disk checked, the recorder started, the tuning
    socket served (with ``tune_folder``, when the law can be tuned), the views started. A failure
    ends the loop process with nothing energised and raises."""
    stream = process.stream
    assert stream is not None
    rate = process.rate_hz
    recorder: StreamRecorder | None = None
    server = None
    try:
        check_disk(data_path.parent, len(stream.columns), rate, duration_s)
        recorder = StreamRecorder(stream, data_path).start()
        if tune_folder is not None and process.ready.get("tunable"):
            try:
                server = TuneServer(tune_folder, handler=process.request).start()
                say("progress", f"live tuning: sashil tune {tune_folder} controller.<param>=VALUE")
            except OSError as err:
                say(
                    "warning",
                    f"live tuning: off ({tune_folder}: cannot listen on a Unix socket: {err.strerror or err})",
                )
        if live is not None:
            live.start(stream, LiveTiming(stream, rate))
    except BaseException:
        if server is not None:
            server.stop()
        if recorder is not None:
            recorder.close()
        process.abort()
        raise
    return recorder, server


def _ending(
    process: LoopProcess,
    end: dict[str, Any] | None,
    error: BaseException | None,
    timing: Any,
    flag: StopFlag,
    say: Callable[[str, str], None],
) -> tuple[dict[str, Any], BaseException | None, str]:
    """How the loop ended, from its ``end`` message, or, when it died, from the rows it committed
    and the rig reopened to confirm 0 A: the end's keys, the error and the exit status."""
    stream = process.stream
    assert stream is not None
    if end is not None:
        timing.restore(end["timing"])
        if end.get("clip_warning"):
            say("warning", end["clip_warning"])
        if end.get("error") is not None:
            error = error_of(end["error"])
        status = end["exit_status"]
        if end.get("stop_reason") == CALLER_STOP and flag.signal_name:
            end["stop_reason"] = flag.signal_name
    else:  # the loop process died: its rows are kept, the rig is reopened and checked
        timing.cycles = stream.rows_committed
        code = process.process.returncode if process.process is not None else None
        end = {"exit_status": "error", "stop_reason": None, "trips": [], "shutdown_errors": []}
        found = confirm_safe(process.spec.rig, say)
        error = errors.SashilError(
            f"the loop process died (exit status {code}); the data up to its last committed row are kept"
        )
        end.update(loop_died={"exit_status": code, "rig": found})
        status = "error"
    if error is not None and status == "ok":
        status = "error"
    return end, error, status

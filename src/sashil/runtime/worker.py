"""The loop process: a fork of the loop server (``python -m sashil.runtime.worker --serve FD``,
:mod:`sashil.runtime.loop_server`), or a fresh ``python -m sashil.runtime.worker --messages FD``
where no server can be had, started by the session.

It runs the cycle and nothing else: the rig's I/O, the safety supervisor, the plan, the
controller and the lab's law, each cycle's row into the run's stream (:mod:`sashil.runtime.stream`).
No other Python thread runs in it. What it does, in order:

0. imports the loop's modules and loads every numba kernel (:func:`prepare`): the server once,
   before its first fork, so a fork has done it when the job arrives;
1. reads its job from stdin, one JSON line: the assembled run (:class:`~sashil.config.parts.RunSpec`:
   the rig's, the stage's, the safety supervisor's and the loop's parts and the plan's values; the
   law named by its spec, a registered name, ``package.module:Class`` or ``file.py:Class``, imported
   here, never unpickled), the duration, and whether to apply ``loop.rt`` and serve live tuning;
2. builds the rig and the stage, warms every numba kernel and the law
   (:func:`~sashil.runtime.warmup.warm_up`, its progress sent to the session), opens the port and
   greets the board, then creates the stream for the stage's columns and says ``ready``;
3. waits for the session's ``go`` line (the session has made the run folder and started the
   recorder), watches its session from then on (:class:`~sashil.runtime.orphan.SessionWatch`: the
   session's hold in the stream and its end of stdin), applies ``loop.rt`` and runs
   :class:`~sashil.runtime.loop.ControlLoop`;
4. sends ``end``: how the loop ended, the timing counters, the rig's facts (link statistics), the
   tuning events. If the session died, the watch has stopped the loop at its next cycle, at 0 A
   with the road at rest, as a stop signal does; the loop process then appends the rows the
   recorder had not written to ``data.csv`` and writes ``summary.json`` and ``timing.npz``
   itself, saying so (:mod:`sashil.runtime.orphan`).

Messages to the session are JSON lines on the descriptor ``--messages``: ``{"kind": "progress" |
"warning" | "ready" | "error" | "end", ...}``. An error before the loop (a port that cannot be
opened, a law that does not import) is one ``error`` message with its exit code; nothing was
energised.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn, Protocol

from sashil.config.parts import RunSpec
from sashil.errors import ConfigError, DiskSpaceError, error_fields, exit_code_of
from sashil.plans import BUILT_IN, drop
from sashil.plugins import PLANS_GROUP, built_in_or_registered, load_target
from sashil.runtime.serve import serve
from sashil.runtime.signals import catch_stop_signals

#: rows of the stream per second of the loop's rate: how far the recorder may fall behind
STREAM_SECONDS = 30.0
#: the fewest rows a stream holds
MIN_ROWS = 4096
#: CAN frames the stream holds for the session's trace writer (a 1 kHz link sends about 3 per cycle)
FRAME_ROWS = 1 << 16


def stream_rows(rate_hz: float) -> int:
    """The stream's capacity for a loop at ``rate_hz``: :data:`STREAM_SECONDS` of rows, a power of two."""
    need = max(MIN_ROWS, int(rate_hz * STREAM_SECONDS))
    return 1 << (need - 1).bit_length()


class Messages:
    """JSON lines to the session on one descriptor; a session gone makes them no-ops."""

    def __init__(self, fd: int):
        self.fd = fd
        self.gone = False

    def send(self, kind: str, **fields: Any) -> None:
        if self.gone:
            return
        data = (json.dumps({"kind": kind, **fields}, default=str) + "\n").encode()
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view) :]
        except OSError:
            self.gone = True


#: plans whose board is greeted when the loop starts, not before ``ready``: an operator (a person, or
#: an emulator's ``--hold-deg``) holds the arm from the greeting and lets go a while after it, so a
#: drop's hold must start with its loop (a port that cannot be opened then ends the run at once,
#: with nothing energised, and the drop test leaves no folder)
GREET_AT_START = frozenset({drop.KIND})


def plan_builder(kind: str) -> Callable[..., tuple[Any, str, str]]:
    """The function that builds a plan of ``kind`` in this process (``build(spec, rig, prompt) ->
    (stage, label, road_text)``, ``spec`` the assembled run with the plan's values): a built-in plan
    of :mod:`sashil.plans`, else the ``sashil.plans`` entry point of that name (a lab's own), so the
    runtime imports no experiment."""
    return built_in_or_registered(
        "plan",
        kind,
        BUILT_IN,
        PLANS_GROUP,
        load_target,  # type: ignore[arg-type]  # a registered builder
        lambda kind, known: f"the loop process cannot run a plan of kind {kind!r} (it runs {known})",
    )


class Sender(Protocol):
    """Where a loop's build tells its progress and prompts: a loop process's :class:`Messages`, or
    the session's own when the loop runs in its process."""

    def send(self, kind: str, **fields: Any) -> None: ...


def build(spec: RunSpec, messages: Sender) -> tuple[Any, Any, str, str]:
    """The rig (built, configured: its port open and the board greeted) and the warmed plan of the
    run ``spec`` (:func:`plan_builder` of its plan's kind), its label and the road's text; the
    plan's operator prompts go to the session as ``prompt`` messages."""
    from sashil.drivers import open_rig
    from sashil.runtime.warmup import warm_up

    kind = str(spec.plan.get("kind"))
    make = plan_builder(kind)
    rig = open_rig(spec.rig)
    try:
        stage, label, road_text = make(spec, rig, lambda line: messages.send("prompt", text=line))
        warm_up(stage, lambda line: messages.send("progress", text=line))
        if kind not in GREET_AT_START:
            rig.configure()
    except BaseException:
        rig.close()
        raise
    return rig, stage, label, road_text


def prepare(progress: Callable[[str], None]) -> None:
    """What every run needs, done before the job arrives (a process started ahead of its run does
    it while the session resolves the config; the loop server once for all its forks): the loop's
    modules imported and every numba kernel compiled or loaded from the cache, its progress told
    ``progress`` on an empty cache."""
    import sashil.control.registry
    import sashil.drivers
    import sashil.runtime.loop
    import sashil.safety  # noqa: F401 - imported now, used by run()
    from sashil.runtime.warmup import warm_kernels

    plan_builder("run")  # sashil run's plan and its road profiles, the run a process is started ahead for
    warm_kernels(progress)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sashil.runtime.worker", description=__doc__.split("\n\n")[0])
    parser.add_argument("--messages", type=int, help="descriptor for the messages to the session")
    parser.add_argument(
        "--serve", type=int, help="be the loop server on this control socket (sashil.runtime.loop_server)"
    )
    args = parser.parse_args(argv)
    if args.serve is not None:
        code = serve(args.serve, prepare, lambda fd: take_job(Messages(fd)))
        _exit_at_once(code)
    if args.messages is None:
        parser.error("one of --messages and --serve is required")
    messages = Messages(args.messages)
    return take_job(messages, lambda: prepare(lambda line: messages.send("progress", text=line)))


def _exit_at_once(code: int) -> NoReturn:
    """End the loop server with ``code`` without the interpreter's teardown (its loaded kernels and
    libraries take tenths of a second to finalise): a session that died is seen gone by its loops
    on their own (:mod:`sashil.runtime.orphan`), and the server holds nothing to flush but its
    standard output and error."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def take_job(messages: Messages, before: Callable[[], None] = lambda: None) -> int:
    """Do ``before`` (the preparation of a fresh process), read the job from stdin and run it; the
    exit code."""
    with catch_stop_signals() as flag:
        try:
            before()
            job = sys.stdin.readline()
            if not job.strip():  # a process started ahead that was never given a run
                return 0
            return run(json.loads(job), messages, flag)
        except BaseException as err:
            messages.send("error", **error_fields(err))
            return exit_code_of("error", err) or 1


def run(job: dict[str, Any], messages: Messages, flag: Any) -> int:
    """The loop process's work (module doc), its exit code."""
    from sashil.runtime.clock import RealClock
    from sashil.runtime.mailbox import SESSION_DIED, HealthWriter, LoopStop, MailboxTuning
    from sashil.runtime.orphan import SessionWatch, finish_alone
    from sashil.runtime.rt_setup import RealtimeSetup
    from sashil.runtime.runner import control_loop, loop_end, run_realtime
    from sashil.runtime.stream import MISSED_W, THREADS_W, StreamWriter

    _as_the_session(job)
    spec = RunSpec.from_json(job["spec"])  # read-only here too, as the session assembled it
    rate = spec.loop.rate_hz
    rig, stage, label, road_text = build(spec, messages)
    if flag.requested:  # a signal during the warm-up: nothing energised
        rig.close()
        messages.send(
            "error", type="Stopped", text=f"stopped by {flag.signal_name} before the run started", exit_code=130
        )
        return 130
    stream = _create_stream(job, spec.rig.backend, rig, stage, rate)
    stream.set_state("ready")
    law = getattr(stage, "law", None)
    tunable = bool(job.get("tune")) and law is not None and hasattr(law, "check_parameters")
    messages.send(
        "ready", stream=str(stream.path), columns=list(stream.columns), label=label, road=road_text, tunable=tunable
    )
    go = sys.stdin.readline()
    if not go.strip():  # the session went away (or aborted) before the run: nothing energised
        rig.close()
        stream.close(unlink=True)
        return 1
    started = json.loads(go)
    folder = Path(started["folder"])
    # the session's end stops the loop the moment it happens: its hold let go, its end of stdin closed
    session = SessionWatch(sys.stdin.fileno(), stream, lambda: flag.request(SESSION_DIED)).start()
    try:
        # the run's health for the views about ten times a second (samples lost, bad frames, watchdog, clipping)
        stop = LoopStop(flag, stream, session, HealthWriter(stream, rig, stage), every=max(1, round(rate / 10)))
        tuning = None
        if tunable:
            tuning = MailboxTuning(law, rate, spec.stage.controller.tune_ramp_s, stream)
        writer = StreamWriter(stream)
        loop = control_loop(
            spec,
            rig,
            stage,
            RealClock.for_rate(spec.loop.spin_margin_us, rate),
            job.get("duration_s"),
            warn=lambda line: messages.send("warning", text=line),
            recorder=writer,
            tuning=tuning,
            stop=stop,
            timing=stream.timing(rate),
        )
        loop.on_overrun = lambda timing: stream.header.__setitem__(MISSED_W, timing.missed_deadlines)
        rt = RealtimeSetup.from_parts(spec.loop.rt) if job.get("realtime", True) else None
        stream.set_state("running")
        stream.header[THREADS_W] = threading.active_count()
        error = run_realtime(loop, rt, lambda line: messages.send("progress", text=line))
        session.check()  # a session that ended during the shutdown has no one to record the rest either
    finally:
        session.stop()
    if writer.error is not None and error is None:
        error = writer.error
    stream.header[THREADS_W] = max(int(stream.header[THREADS_W]), threading.active_count())
    if tuning is not None:
        tuning.close()
    end = loop_end(loop, error, stage, rt, rig, tuning, int(stream.header[THREADS_W]))
    stream.set_state("ended")
    if stop.orphaned:  # nobody records the rest: the loop process writes it and the summary itself
        data = folder / started.get("data", "data.csv")
        finish_alone(stream, writer, data, spec, end, loop.timing, started.get("verb", "run"))
    else:
        messages.send("end", **end)
    writer.release()
    return 0


def _as_the_session(job: dict[str, Any]) -> None:
    """The session's logging and import path, here too: its command line set its logging up, and a
    law named as ``module:Class`` imports as it did there."""
    if job.get("log_level") is not None:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger = logging.getLogger("sashil")
        logger.addHandler(handler)
        logger.setLevel(int(job["log_level"]))
    if job.get("sys_path"):
        sys.path[:] = [entry for entry in job["sys_path"] if isinstance(entry, str)]


def _create_stream(job: dict[str, Any], backend: str, rig: Any, stage: Any, rate: float) -> Any:
    """The run's stream for the stage's columns (and a CAN frame ring when the job traces frames),
    this process's pid in its header; the rig closed when it cannot be made (nothing energised)."""
    from sashil.drivers.interface import capabilities_of
    from sashil.runtime.loop import record_columns
    from sashil.runtime.stream import LOOP_PID_W, STREAM_DIR, FrameWriter, Stream

    frames = FRAME_ROWS if job.get("can_trace") else 0
    if frames and not capabilities_of(rig).can_frames:
        rig.close()
        raise ConfigError(f"--format: the {backend} backend has no CAN frames to trace")
    try:
        stream = Stream.create(record_columns(stage), stream_rows(rate), folder=job.get("stream_dir"), frames=frames)
    except OSError as err:  # before anything is energised
        rig.close()
        raise DiskSpaceError(f"{STREAM_DIR}: cannot hold the run's stream: {err.strerror or err}") from None
    if frames:
        rig.frame_sink = FrameWriter(stream).put
    stream.header[LOOP_PID_W] = os.getpid()
    return stream


if __name__ == "__main__":
    raise SystemExit(main())

"""The loop process: ``python -m sashil.runtime.worker --messages FD``, started by the session.

It runs the cycle and nothing else: the rig's I/O, the safety supervisor, the plan, the
controller and the lab's law, each cycle's row into the run's stream (:mod:`sashil.runtime.stream`).
No other Python thread runs in it. What it does, in order:

0. imports the loop's modules and loads every numba kernel (:func:`prepare`), so a process
   started ahead of its run (:func:`sashil.runtime.loop_process.start_ahead`) has done it when
   the job arrives;
1. reads its job from stdin, one JSON line: the resolved config (the law named by its spec in
   ``controller.law``: a registered name, ``package.module:Class`` or ``file.py:Class``, imported
   here, never unpickled), the duration, and whether to apply ``loop.rt`` and serve live tuning;
2. builds the rig and the stage, warms every numba kernel and the law
   (:func:`~sashil.runtime.warmup.warm_up`, its progress sent to the session), opens the port and
   greets the board, then creates the stream for the stage's columns and says ``ready``;
3. waits for the session's ``go`` line (the session has made the run folder and started the
   recorder), applies ``loop.rt`` and runs :class:`~sashil.runtime.loop.ControlLoop`;
4. sends ``end``: how the loop ended, the timing counters, the rig's facts (link statistics), the
   tuning events. If the session died (:class:`~sashil.runtime.mailbox.LoopStop`) the loop ends
   at 0 A with the road at rest, appends the rows the recorder had not written to ``data.csv``,
   and writes ``summary.json`` and ``timing.npz`` itself, saying so.

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
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.config.frozen import freeze_config
from sashil.errors import ConfigError, DiskSpaceError, exit_code_of
from sashil.runtime.signals import catch_stop_signals

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

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


def error_fields(err: BaseException) -> dict[str, Any]:
    """An error as the session re-raises it: its class name, its line and its exit code."""
    return {"type": type(err).__name__, "text": str(err) or type(err).__name__, "exit_code": exit_code_of("error", err)}


def run_stage(config: RunConfig, spec: dict[str, Any], rig: Any, messages: Messages) -> tuple[Any, str, str]:
    """``sashil run``'s stage: the config's law on its road (the rig's road motor gets the profile's
    speed); its label and the road's text."""
    from sashil.control.registry import make_stage
    from sashil.experiments.road_option import RoadStage, parse_road

    label, stage = make_stage(config)
    road, road_text = parse_road(config["run"]["road"], config)
    if road is not None:
        stage = RoadStage(stage, road, config["run"]["duration_s"])
    return stage, label, road_text


def drop_test_plan(config: RunConfig, spec: dict[str, Any], rig: Any, messages: Messages) -> tuple[Any, str, str]:
    """One drop of a drop test (:func:`sashil.experiments.drop_test.plan_drop`), its operator
    prompts sent to the session as they come; the stage that takes over at the release is the
    config's law, none, or one of :data:`STAGES` built from its spec."""
    from sashil.experiments.drop_test import CONFIG_LAW, plan_drop

    controller = spec.get("controller", CONFIG_LAW)
    if isinstance(controller, dict):
        controller = STAGES[str(controller.get("kind"))](controller)
    plan = plan_drop(config, spec, rig, lambda line: messages.send("prompt", text=line), controller)
    return plan, str(config["controller"]["law"]), "none"


def calibration_step(spec: dict[str, Any]) -> Any:
    """A calibration step's stage (:class:`sashil.calibrate.rig.StepStage`) from its spec."""
    from sashil.calibrate.rig import StepStage

    return StepStage.from_spec(spec)


#: the stages a drop's plan can hand over to at the release, by the ``kind`` of their spec
STAGES = {"calibration-step": calibration_step}


def sweep_plan(config: RunConfig, spec: dict[str, Any], rig: Any, messages: Messages) -> tuple[Any, str, str]:
    """One run of a sweep (a chirp, or one frequency of a stepped sine): the config's law on the road
    of the spec (:func:`sashil.experiments.sweep.sweep_stage`)."""
    from sashil.experiments.sweep import sweep_stage

    return sweep_stage(config, spec, rig), str(config["controller"]["law"]), str(spec["road"].get("shape"))


#: what a loop process can run: a plan's ``kind`` (its ``spec()``) and the function that builds it
#: in the loop process from the config, the spec, the rig and the message channel
PLANS = {"run": run_stage, "drop-test": drop_test_plan, "sweep": sweep_plan}
#: plans whose board is greeted when the loop starts, not before ``ready``: an operator (a person, or
#: an emulator's ``--hold-deg``) holds the arm from the greeting and lets go a while after it, so a
#: drop's hold must start with its loop (a port that cannot be opened then ends the run at once,
#: with nothing energised, and the drop test leaves no folder)
GREET_AT_START = frozenset({"drop-test"})


def build(config: RunConfig, spec: dict[str, Any], messages: Messages) -> tuple[Any, Any, str, str]:
    """The rig (built, configured: its port open and the board greeted) and the warmed plan of
    ``spec`` (:data:`PLANS`), its label and the road's text."""
    from sashil.drivers import open_rig
    from sashil.runtime.warmup import warm_up

    make = PLANS.get(str(spec.get("kind")))
    if make is None:
        raise ConfigError(
            f"the loop process cannot run a plan of kind {spec.get('kind')!r} (it runs {', '.join(PLANS)})"
        )
    rig = open_rig(config)
    try:
        stage, label, road_text = make(config, spec, rig, messages)
        warm_up(stage, lambda line: messages.send("progress", text=line))
        if spec.get("kind") not in GREET_AT_START:
            rig.configure()
    except BaseException:
        rig.close()
        raise
    return rig, stage, label, road_text


def prepare(messages: Messages) -> None:
    """What every run needs, done before the job arrives (a process started ahead of its run does
    it while the session resolves the config): the loop's modules imported and every numba kernel
    compiled or loaded from the cache, its progress sent on an empty cache."""
    import sashil.control.registry
    import sashil.drivers
    import sashil.experiments.road_option
    import sashil.runtime.loop
    import sashil.safety  # noqa: F401 - imported now, used by run()
    from sashil.runtime.warmup import warm_kernels

    warm_kernels(lambda line: messages.send("progress", text=line))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sashil.runtime.worker", description=__doc__.split("\n\n")[0])
    parser.add_argument("--messages", type=int, required=True, help="descriptor for the messages to the session")
    args = parser.parse_args(argv)
    messages = Messages(args.messages)

    with catch_stop_signals() as flag:
        try:
            prepare(messages)
            job = sys.stdin.readline()
            if not job.strip():  # a process started ahead that was never given a run
                return 0
            return run(json.loads(job), messages, flag)
        except BaseException as err:
            messages.send("error", **error_fields(err))
            return exit_code_of("error", err) or 1


def run(job: dict[str, Any], messages: Messages, flag: Any) -> int:
    """The loop process's work (module doc); returns its exit code."""
    from sashil.drivers.interface import capabilities_of
    from sashil.runtime.clock import RealClock
    from sashil.runtime.loop import ControlLoop, record_columns
    from sashil.runtime.mailbox import HealthWriter, LoopStop, MailboxTuning
    from sashil.runtime.rt_setup import RealtimeSetup
    from sashil.runtime.runner import run_realtime
    from sashil.runtime.stream import LOOP_PID_W, MISSED_W, STREAM_DIR, THREADS_W, FrameWriter, Stream, StreamWriter
    from sashil.runtime.tuning import RAMP_KEY
    from sashil.safety import SafetySupervisor

    if job.get("log_level") is not None:  # the session's command line set its logging up: the same here
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger = logging.getLogger("sashil")
        logger.addHandler(handler)
        logger.setLevel(int(job["log_level"]))
    if job.get("sys_path"):  # the session's import path: a law named as module:Class imports as it did there
        sys.path[:] = [entry for entry in job["sys_path"] if isinstance(entry, str)]
    config = freeze_config(job["config"])  # read-only here too, as the session resolved it
    loop_cfg = config["loop"]
    rate = float(loop_cfg["rate_hz"])
    rig, stage, label, road_text = build(config, job.get("plan") or {"kind": "run"}, messages)
    if flag.requested:  # a signal during the warm-up: nothing energised
        rig.close()
        messages.send(
            "error", type="Stopped", text=f"stopped by {flag.signal_name} before the run started", exit_code=130
        )
        return 130
    frames = FRAME_ROWS if job.get("can_trace") else 0
    if frames and not capabilities_of(rig).can_frames:
        rig.close()
        raise ConfigError(f"--format: the {config['driver']['name']} backend has no CAN frames to trace")
    try:
        stream = Stream.create(record_columns(stage), stream_rows(rate), folder=job.get("stream_dir"), frames=frames)
    except OSError as err:  # before anything is energised
        rig.close()
        raise DiskSpaceError(f"{STREAM_DIR}: cannot hold the run's stream: {err.strerror or err}") from None
    if frames:
        rig.frame_sink = FrameWriter(stream).put
    stream.header[LOOP_PID_W] = os.getpid()
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
    session_pid = int(job["session_pid"])
    # the run's health for the views about ten times a second (samples lost, bad frames, watchdog, clipping)
    stop = LoopStop(flag, stream, session_pid, HealthWriter(stream, rig, stage), every=max(1, round(rate / 10)))
    tuning = None
    if tunable:
        tuning = MailboxTuning(law, rate, float(config["controller"].get(RAMP_KEY, 0.0)), stream)
    writer = StreamWriter(stream)
    loop = ControlLoop(
        rig,
        stage,
        RealClock.for_rate(loop_cfg["spin_margin_us"], rate),
        rate,
        job.get("duration_s"),
        safety=SafetySupervisor.from_config(config),
        recorder=writer,
        overrun_policy=loop_cfg["overrun_policy"],
        warn_interval_s=loop_cfg["warn_interval_s"],
        warn=lambda line: messages.send("warning", text=line),
        tuning=tuning,
        stop=stop,
        timing=stream.timing(rate),
    )
    loop.on_overrun = lambda timing: stream.header.__setitem__(MISSED_W, timing.missed_deadlines)
    rt = RealtimeSetup.from_config(loop_cfg) if job.get("realtime", True) else None
    stream.set_state("running")
    stream.header[THREADS_W] = threading.active_count()
    error = run_realtime(loop, rt, lambda line: messages.send("progress", text=line))
    if writer.error is not None and error is None:
        error = writer.error
    stream.header[THREADS_W] = max(int(stream.header[THREADS_W]), threading.active_count())
    result = loop.result
    controller = stage if hasattr(stage, "clip_warning") else getattr(stage, "controller", None)
    clipped = getattr(controller, "clip_warning", None)
    if tuning is not None:
        tuning.close()
    end = {
        "exit_status": result.exit_status,
        "error": error_fields(error) if error is not None else None,
        "stop_reason": result.stop_reason,
        "trips": result.trips,
        "shutdown_errors": result.shutdown_errors,
        "safe_state": result.safe_state,
        "timing": loop.timing.counters(),
        "controller_stats": stage.stats() if hasattr(stage, "stats") else None,
        "safety": loop.safety.summary() if loop.safety is not None else None,
        "realtime": rt.report() if rt is not None else {},
        "link": rig.link_stats() if capabilities_of(rig).link else None,
        "clip_warning": clipped() if callable(clipped) else None,
        "tuning": tuning.summary() if tuning is not None else None,
        "tuning_notes": tuning.notes() if tuning is not None else [],
        "threads": int(stream.header[THREADS_W]),
        "start_ns": loop.start_ns,
        "plan": stage.facts() if hasattr(stage, "facts") else None,
    }
    stream.set_state("ended")
    if stop.orphaned:
        from sashil.runtime.orphan import finish_alone

        finish_alone(
            stream,
            writer,
            folder / started.get("data", "data.csv"),
            config,
            end,
            loop.timing,
            started.get("verb", "run"),
        )
    else:
        messages.send("end", **end)
    writer.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

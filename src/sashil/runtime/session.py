"""One closed-loop session into a run folder: RT set-up, signals, safety, recorder, loop, summary.

``run_session`` is what ``sashil run`` (and ``tools/bench_loop.py``) call: it writes
``config.yaml`` first, records ``data.csv`` through the threaded recorder while the loop runs, and
always writes ``summary.json`` at the end, whatever ended the loop (a signal, a trip, an error).
The rig is already in the safe state (0 A, deactivated, closed) when the summary is written.

summary.json (DESIGN.md fixed keys first): ``exit_status`` (ok | stopped | safety_trip |
deadline_missed | error), ``timing`` ({rate_hz, cycles, missed_deadlines, lateness_us,
compute_us} each with p50/p99/p99_9/max, plus overruns, read_us, write_us, cycle_us), ``trips``,
then ``exit_code``, ``error``, ``stop_reason``, ``safety``, ``realtime`` (each set-up step's
outcome), ``recording`` (rows written/dropped) and ``controller``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sashil.errors import exit_code_of
from sashil.recording.recorder import Recorder
from sashil.recording.run_folder import RunFolder
from sashil.runtime.clock import Clock
from sashil.runtime.loop import ControlLoop, LoopResult, record_columns
from sashil.runtime.rt_setup import RealtimeSetup
from sashil.runtime.signals import catch_stop_signals
from sashil.safety import SafetySupervisor


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@dataclass
class SessionOutcome:
    result: LoopResult
    summary: dict[str, Any]
    error: BaseException | None
    exit_code: int


def run_session(
    config: dict[str, Any],
    rig: Any,
    stage: Any,
    folder: RunFolder,
    clock: Clock,
    duration_s: float | None,
    *,
    controller: str = "passive",
    verb: str = "run",
    say: Callable[[str], None] = _stderr,
    realtime: bool = True,
    live: Any = None,
) -> SessionOutcome:
    """Run ``stage`` on ``rig`` in closed loop, recording into ``folder`` (see module doc)."""
    loop_cfg = config["loop"]
    folder.write_config(config)
    safety = SafetySupervisor.from_config(config)
    recorder = Recorder(folder.file("data.csv"), record_columns(stage))
    rt = RealtimeSetup.from_config(loop_cfg) if realtime else None
    if rt is not None and live is not None:
        rt.current_only = True  # the live view allocates beside the loop (see RealtimeSetup._mlockall)
    loop = ControlLoop(
        rig,
        stage,
        clock,
        loop_cfg["rate_hz"],
        duration_s,
        safety=safety,
        recorder=recorder,
        overrun_policy=loop_cfg["overrun_policy"],
        warn_interval_s=loop_cfg["warn_interval_s"],
        warn=say,
    )
    error: BaseException | None = None
    with catch_stop_signals() as stop:
        loop.stop = stop
        recorder.start()
        if live is not None:  # the rerun live view (sashil.recording.rerun_log.LiveTap)
            live.start(recorder, loop.timing)
        try:
            if rt is not None:
                rt.apply()
                for line in rt.lines():
                    say(line)
            try:
                loop.run()
            except BaseException as err:
                error = err
            finally:
                if rt is not None:
                    rt.restore()
        finally:
            try:
                recorder.close()
            except OSError as err:
                if error is None:
                    error = err
                    loop.result.exit_status = "error"
                    loop.result.error = str(err)
        result = loop.result
        live_stats = live.close(result.trips) if live is not None else None
        folder.write_timing(loop.timing)
        status = result.exit_status
        code = exit_code_of(status, error)
        summary: dict[str, Any] = {
            "verb": verb,
            "exit_status": status,
            "timing": loop.timing.summary(),
            "trips": result.trips,
            "exit_code": code,
            "error": result.error if error is not None else None,
            "stop_reason": result.stop_reason,
            "controller": controller,
            "controller_stats": stage.stats() if hasattr(stage, "stats") else None,
            "duration_s": duration_s,
            "driver": config["driver"]["name"],
            "safety": safety.summary(),
            "realtime": rt.report() if rt is not None else {},
            "recording": recorder.summary(),
            "live_view": live_stats,
            "link": rig.link_stats() if hasattr(rig, "link_stats") else None,
            "shutdown_errors": result.shutdown_errors,
        }
        folder.write_summary(summary)
    return SessionOutcome(result, summary, error, code)

"""One closed-loop session into a run folder: RT set-up, signals, safety, recorder, loop, summary.

``run_session`` is what ``sashil run`` (and ``tools/bench_loop.py``) call: it writes
``config.yaml`` first, records ``data.csv`` through the threaded recorder while the loop runs, and
always writes ``summary.json`` at the end, whatever ended the loop (a signal, a trip, an error).
The rig is already in the safe state (0 A, deactivated, closed) when the summary is written.

summary.json (docs/architecture.md fixed keys first): ``exit_status`` (ok | stopped | safety_trip |
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

from sashil.recording.run_folder import RunFolder
from sashil.runtime.clock import Clock
from sashil.runtime.loop import LoopResult
from sashil.runtime.runner import run_plan


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
    """Run ``stage`` on ``rig`` in closed loop through the one runner
    (:func:`~sashil.runtime.runner.run_plan`), streaming ``data.csv`` into ``folder``; then the
    timing file and ``summary.json`` (see module doc)."""
    folder.write_config(config)
    outcome = run_plan(
        config, rig, stage, clock, duration_s, data_path=folder.file("data.csv"), say=say, realtime=realtime, live=live
    )
    result = outcome.result
    live_stats = live.close(result.trips) if live is not None else None
    folder.write_timing(outcome.loop.timing)
    summary: dict[str, Any] = {
        "verb": verb,
        **outcome.summary(),
        "controller": controller,
        "duration_s": duration_s,
        "driver": config["driver"]["name"],
        "live_view": live_stats,
    }
    folder.write_summary(summary)
    return SessionOutcome(result, summary, outcome.error, outcome.exit_code)

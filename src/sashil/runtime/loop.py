"""The fixed-rate control loop: absolute deadlines, measured period, safe state on any exit.

One cycle: ``sample = rig.read(t, dt)`` -> ``cmd = stage.step(sample, t, dt)`` ->
``rig.write(cmd, t, dt)``. ``stage.step`` returning ``None`` ends the run (a finished plan). The
loop owns time and I/O; the stage owns the math. Whatever ends the loop (the end of the duration,
the stage, an exception) the rig gets the safe command (0 A), ``deactivate()`` and ``close()``, in
that order, before the loop returns or re-raises.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from sashil.drivers.interface import SAFE_COMMAND, RigCommand, RigInterface, RigSample
from sashil.runtime.clock import Clock


class CycleStage(Protocol):
    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None: ...


@dataclass
class LoopResult:
    cycles: int = 0
    missed_deadlines: int = 0
    exit_status: str = "ok"
    error: str | None = None
    trips: list[dict] = field(default_factory=list)


def _safe_shutdown(rig: RigInterface, t_ns: int) -> None:
    try:
        rig.write(SAFE_COMMAND, t_ns, 0)
    except Exception:  # noqa: BLE001 - the link may be dead; deactivate still commands 0 A
        pass
    try:
        rig.deactivate()
    finally:
        rig.close()


def run_loop(
    rig: RigInterface,
    stage: CycleStage,
    clock: Clock,
    rate_hz: float,
    duration_s: float | None = None,
) -> LoopResult:
    """Run ``stage`` on ``rig`` at ``rate_hz`` until ``duration_s`` or the stage ends."""
    period = round(1e9 / rate_hz)
    max_cycles = None if duration_s is None else int(round(duration_s * rate_hz))
    result = LoopResult()
    rig.configure()
    t = clock.now_ns()
    try:
        rig.activate()
        start = last = clock.now_ns()
        deadline = start
        while max_cycles is None or result.cycles < max_cycles:
            clock.sleep_until(deadline)
            t = clock.now_ns()
            dt = t - last
            last = t
            sample = rig.read(t, dt)
            cmd = stage.step(sample, t, dt)
            if cmd is None:
                break
            rig.write(cmd, t, dt)
            result.cycles += 1
            deadline += period
            late = clock.now_ns() - deadline
            if late > period:
                skipped = late // period
                result.missed_deadlines += skipped
                deadline += skipped * period
    except BaseException as err:
        _safe_shutdown(rig, t)
        result.exit_status = "error"
        result.error = str(err)
        raise
    _safe_shutdown(rig, t)
    return result

"""A compared law's run again when the host paused in it, so that every law meets the same road.

On a rig that is not simulated on the virtual clock the road is the host's: each cycle's command
carries the road speed θ̇1(t), and the road motor holds it until the next command. A host that
pauses for Δ holds the road's speed for Δ, and the road the arm meets is no longer the profile:
the road falls behind by about θ̈1·Δ²/2 and its speed steps by about θ̈1·Δ when the host comes
back, a kick that a lightly damped arm rings with for seconds. On the simulated rig, one pause on
``iso8608:C`` moves a law's RMS travel and RMS θ̈2 by up to 1.9 % at Δ = 10 ms, 5 % at 20 ms and 10 %
at 40 ms (the worst over 8 dampers, 3 laws and 6 moments of an 8 s run; the median 0.1–0.4 %:
``tools/bench_compare_pause.py``); ``compare.max_pause_ms`` is 20 ms.

A run's pause is its loop's longest lateness (``timing.lateness_us.max`` of its summary): how long
a cycle, hence the road's speed, waited beyond its period. A law whose pause passed
``compare.max_pause_ms`` is run again, after the rig's rest, up to ``compare.repeats`` times; its
folder keeps the last run, and its summary every run's pause (``pauses_ms``). One whose every run
paused keeps its metrics, and the comparison says that its road was not the others'.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sashil.engine.events import Event, Listener
from sashil.lab.compare_metrics import LawResult

__all__ = ["PausePolicy", "pause_ms", "paused_note", "run_unpaused"]


@dataclass(frozen=True)
class PausePolicy:
    """How long the host may pause in a law's run (``max_pause_ms``) before it is run again, and how
    many times it may be (``repeats``, 0: never)."""

    max_pause_ms: float
    repeats: int

    @classmethod
    def of(cls, section: Mapping[str, Any]) -> PausePolicy:
        """The policy of a run's ``compare`` options."""
        return cls(float(section["max_pause_ms"]), int(section["repeats"]))

    def too_long(self, pause_ms: float) -> bool:
        """Whether a run whose host paused ``pause_ms`` did not meet the others' road (NaN: no)."""
        return pause_ms > self.max_pause_ms


def pause_ms(summary: Mapping[str, Any]) -> float:
    """A run's longest host pause [ms]: its loop's worst lateness (NaN when its summary has none)."""
    try:
        return float(summary["timing"]["lateness_us"]["max"]) / 1e3
    except (KeyError, TypeError, ValueError):
        return math.nan


def run_unpaused(
    run: Callable[[], LawResult],
    rest: Callable[[], None],
    policy: PausePolicy,
    on_event: Listener,
) -> LawResult:
    """``run`` a law, and again after ``rest`` while its host paused longer than the policy allows
    (at most ``policy.repeats`` more times): the last result, with every run's pause [ms] as its
    ``pauses_ms``. A law that did not finish is not run again: its status already says why."""
    pauses: list[float] = []
    while True:
        result = run()
        pause = pause_ms(result.summary)
        pauses.append(pause)
        if not result.ok or not policy.too_long(pause) or len(pauses) > policy.repeats:
            result.pauses_ms = pauses
            return result
        on_event(
            Event(
                "progress",
                f"sashil compare: {result.label}: the host paused {pause:.0f} ms (compare.max_pause_ms "
                f"{policy.max_pause_ms:g}), which held the road's speed: run again ({len(pauses)} of "
                f"{policy.repeats})",
                {"law": result.label, "pause_ms": pause},
            )
        )
        rest()


def paused_note(results: Sequence[LawResult], policy: PausePolicy) -> str | None:
    """The line under ``compare.md``'s table for the laws run again, or whose every run paused (None:
    every law ran unpaused the first time)."""
    again = {r.label: r.pauses_ms for r in results if len(r.pauses_ms) > 1}
    still = [r.label for r in results if r.pauses_ms and policy.too_long(r.pauses_ms[-1])]
    if not again and not still:
        return None
    parts = []
    if again:
        runs = "; ".join(f"{law}: {', '.join(f'{p:.0f}' for p in r)} ms" for law, r in again.items())
        parts.append(f"Run again, the host having paused longer than {policy.max_pause_ms:g} ms: {runs}.")
    if still:
        parts.append(
            f"Not the others' road: {', '.join(still)}, whose last run paused too (a held road speed kicks the arm)."
        )
    return " ".join(parts) + " compare.max_pause_ms and compare.repeats set this."

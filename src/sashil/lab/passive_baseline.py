"""The passive baseline of every share and gain ``sashil compare`` reports: the best constant current
on the same road, the 0 % of its scale.

A constant current is the passive damper the rig has without any law; the best of them, by the
metric itself (RMS θ̈2 after ``compare.settle_s``), is the baseline a law must beat. How it is found
depends on what a candidate costs:

* on a simulated rig (a run is seconds of CPU): a bounded scalar search over [0, i_max]
  (``scipy.optimize.minimize_scalar``, Brent's method on the bounded interval, Forsythe, Malcolm &
  Moler 1977, ``fminbound``) to :data:`XATOL_SHARE` of i_max, each evaluation a run of the same road
  and seed, the currents rounded to :data:`CURRENT_STEP_A` (a label and a config.yaml that rerun
  it); the ends 0 A and i_max are evaluated too, since the search never reaches them exactly and the
  best current often is one;
* on a real rig (each candidate costs rig time): the constant currents the config lists
  (``compare.passive_currents_a``), one run each, and the best of them.

:func:`best_constant_current` is the one function; it takes the run of a current as a callable, so
``sashil compare``, :func:`sashil.testing.compare_with_passive` and the tools that compute a share
all find the baseline the same way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from sashil.lab.compare_metrics import LawResult

__all__ = ["CURRENT_STEP_A", "XATOL_SHARE", "Baseline", "best_constant_current", "passive_label"]

#: the search's tolerance on the current, as a share of i_max (1 %: the metric moves by well under a
#: per cent over it near the optimum, where it is flat)
XATOL_SHARE = 0.01
#: the resolution of a searched current [A]: each evaluated current is rounded to it
CURRENT_STEP_A = 1e-3


def passive_label(current_a: float) -> str:
    """The row of the passive damper at ``current_a`` in compare's table: ``passive 0.742 A``."""
    return f"passive {current_a:g} A"


@dataclass(frozen=True)
class Baseline:
    """The best constant current [A] and its run (``result``: its metrics), how it was found
    (``method``: ``"search"`` or ``"listed"``) and every current run to find it, with its result."""

    current_a: float
    result: LawResult
    method: str
    evaluated: dict[float, LawResult] = field(default_factory=dict)
    xatol_a: float = math.nan

    @property
    def rms_accel(self) -> float:
        """The baseline's RMS θ̈2 [rad/s²]: the 0 % of compare's scale."""
        return float(self.result.metrics["rms_accel_rad_s2"])

    @property
    def label(self) -> str:
        return passive_label(self.current_a)

    def describe(self, current_max_a: float) -> str:
        """How the baseline was found, for compare.md's header and a tool's report."""
        runs = len(self.evaluated)
        if self.method == "search":
            return (
                f"{self.current_a:g} A, the best constant current on this road: a bounded search over "
                f"[0, {current_max_a:g}] A (scipy minimize_scalar, xatol {self.xatol_a:g} A, the ends too), "
                f"{runs} simulated runs of this road and seed"
            )
        listed = ", ".join(f"{c:g}" for c in sorted(self.evaluated))
        return (
            f"{self.current_a:g} A, the best of the constant currents compare.passive_currents_a lists "
            f"({listed} A), one run each on this rig"
        )


def _rms(result: LawResult) -> float:
    value = result.metrics.get("rms_accel_rad_s2", math.nan) if result.ok else math.nan
    return float(value) if math.isfinite(value) else math.inf


def best_constant_current(
    run_current: Callable[[float], LawResult],
    current_max_a: float,
    listed: Sequence[float] | None = None,
    known: dict[float, LawResult] | None = None,
) -> Baseline:
    """The best constant current (module docstring): with ``listed`` None a bounded search over
    [0, ``current_max_a``], else the best of the ``listed`` currents. ``run_current(i)`` runs the
    passive damper at ``i`` on the road and returns its result; ``known`` holds runs already made,
    by current (compare's reference rows), which are not run again. RuntimeError when no candidate
    finished."""
    from scipy.optimize import minimize_scalar

    evaluated: dict[float, LawResult] = dict(known or {})

    def run(current: float) -> LawResult:
        current = round(min(max(current, 0.0), current_max_a) / CURRENT_STEP_A) * CURRENT_STEP_A
        current = round(current, 6)
        if current not in evaluated:
            evaluated[current] = run_current(current)
        return evaluated[current]

    xatol = math.nan
    if listed is None:
        for end in (0.0, current_max_a):
            run(end)
        if current_max_a > 0.0:
            xatol = XATOL_SHARE * current_max_a
            minimize_scalar(
                lambda i: _rms(run(i)), bounds=(0.0, current_max_a), method="bounded", options={"xatol": xatol}
            )
        candidates = evaluated
    else:
        candidates = {float(c): run(float(c)) for c in listed}
    finished = {c: r for c, r in candidates.items() if math.isfinite(_rms(r))}
    if not finished:
        why = "; ".join(f"{c:g} A: {r.status}" for c, r in sorted(candidates.items()))
        raise RuntimeError(f"no constant current finished: {why}")
    best = min(finished, key=lambda c: (_rms(finished[c]), c))
    return Baseline(best, finished[best], "search" if listed is None else "listed", evaluated, xatol)

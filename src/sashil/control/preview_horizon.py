"""The receding-horizon plan of a preview law: from the estimated state, over the road a finite
preview shows, the optimal semi-active current of the next horizon, re-planned every few cycles.

Semi-active model predictive control with road preview (Göhrle, Schindler, Wagner & Sawodny,
"Road profile estimation and preview control for low-bandwidth active suspension systems",
IEEE/ASME Trans. Mechatronics 2014; Giorgetti, Bemporad, Tseng & Hrovat, "Hybrid model predictive
control application towards optimal semi-active suspension", Int. J. Control 79(5), 2006): each
re-plan starts from the state the controller's observer estimates (θ, θ̇2, ẑ and the measured
coil current) and minimises the mean of θ̈2² over ``slots`` slots of ``slot_cycles`` loop cycles,
on the plan's Bouc-Wen model (:mod:`sashil.control.plan_boucwen`) stepped at the slot's length,
the road speed of each slot the mean of the commanded speeds over it. The road is known only over
the preview (``preview_cycles`` cycles ahead); past it the plan takes the road at rest, its mean
speed. The commands are bounded to [0, i_max]; L-BFGS-B (box bounds) from the previous plan,
shifted to the new start, with the model's exact gradient (the discrete adjoint).

A plan is made while the loop runs on: the request of cycle k is answered by the cycle
k + ``delay_cycles``, so the slots that cover the cycles between are the commands already in
force, fixed in the optimisation (the plan is made for the state the loop will reach under them).
A plan is a start cycle and its slots' commands; :meth:`HorizonPlan.command_at` reads the command
of a cycle, and past its last slot holds the last.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.models.hysteresis import BoucWenParams

__all__ = ["HorizonPlan", "HorizonPlanner", "HorizonSpec", "InlinePlanner", "PlanSource"]


@dataclass(frozen=True)
class HorizonSpec:
    """What a re-plan is: ``slots`` slots of ``slot_cycles`` cycles of ``dt_s``, the road known over
    ``preview_cycles`` cycles, answered ``delay_cycles`` after its request (a multiple of
    ``slot_cycles``), at most ``iterations`` of L-BFGS-B."""

    dt_s: float
    slot_cycles: int
    slots: int
    preview_cycles: int
    delay_cycles: int
    iterations: int = 30

    @property
    def fixed_slots(self) -> int:
        """The slots in force while the plan is made (the delay, in slots)."""
        return min(self.slots, -(-self.delay_cycles // self.slot_cycles))


@dataclass
class HorizonPlan:
    """The commands [A] of ``slot_cycles``-cycle slots from the cycle ``start``."""

    start: int
    slot_cycles: int
    command_a: np.ndarray

    def command_at(self, cycle: int) -> float:
        """The command of ``cycle``: its slot's; before the start the first, past the end the last."""
        slot = (cycle - self.start) // self.slot_cycles
        last = self.command_a.size - 1
        return float(self.command_a[min(max(slot, 0), last)])


class HorizonPlanner:
    """Makes the plans of the module docstring on the model ``params`` with the coil's lag
    ``coil_tau_s`` and the range [0, ``i_max``]; keeps its last plan to start the next from."""

    def __init__(self, params: BoucWenParams, coil_tau_s: float, i_max: float, spec: HorizonSpec):
        self.spec = spec
        self.params = params
        self.coil_tau_s = float(coil_tau_s)
        self.i_max = float(i_max)
        self.h = spec.slot_cycles * spec.dt_s
        model = BoucWenPlanModel.of(params, coil_tau_s, self.h)
        self.forward, self.adjoint, self.m = model.forward, model.adjoint, model.vector()
        self.authority = model.authority and self.i_max > 0.0
        n = spec.slots
        self._bufs = [np.empty(n) for _ in range(5)]
        self._grad = np.empty(n)
        self._road = np.zeros(n)
        self._x0 = np.zeros(4)
        self.last: HorizonPlan | None = None

    def restart(self) -> None:
        """Forget the last plan (a run's start)."""
        self.last = None

    def road_slots(self, road_ahead: np.ndarray) -> np.ndarray:
        """The slots' road speeds: the means of ``road_ahead`` (the speeds of the cycles to come, the
        first this one's) over each slot, within the preview; 0 past it."""
        spec = self.spec
        known = np.asarray(road_ahead[: spec.preview_cycles], dtype=float)
        self._road[:] = 0.0
        whole = min(spec.slots, known.size // spec.slot_cycles)
        if whole:
            self._road[:whole] = known[: whole * spec.slot_cycles].reshape(whole, spec.slot_cycles).mean(axis=1)
        rest = known.size - whole * spec.slot_cycles
        if whole < spec.slots and rest > 0:  # a slot the preview covers in part: its known cycles' share
            self._road[whole] = known[whole * spec.slot_cycles :].sum() / spec.slot_cycles
        return self._road

    def plan(
        self,
        cycle: int,
        state: tuple[float, float, float, float],
        road_ahead: np.ndarray,
        at_once: bool = False,
    ) -> HorizonPlan:
        """The plan of the request of ``cycle`` from the estimated ``state`` (θ, θ̇2, ẑ, i) on the
        speeds ``road_ahead`` of the cycles from ``cycle`` on (module docstring); ``at_once``: a plan
        in force from ``cycle`` itself (before the run), no slot fixed."""
        spec = self.spec
        n = spec.slots
        w = self.road_slots(road_ahead)
        u0 = self._start(cycle)
        if not self.authority:
            plan = HorizonPlan(cycle, spec.slot_cycles, np.zeros(n))
            self.last = plan
            return plan
        self._x0[:] = state
        fixed = 0 if at_once else spec.fixed_slots
        bounds = [(float(u0[j]), float(u0[j])) if j < fixed else (0.0, self.i_max) for j in range(n)]
        from scipy.optimize import minimize

        found = minimize(
            self._cost,
            u0,
            args=(w,),
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": spec.iterations, "maxfun": 2 * spec.iterations},
        )
        u = np.clip(np.asarray(found.x, dtype=float), 0.0, self.i_max)
        u[:fixed] = u0[:fixed]
        plan = HorizonPlan(cycle, spec.slot_cycles, u)
        self.last = plan
        return plan

    def _start(self, cycle: int) -> np.ndarray:
        """The last plan's commands from ``cycle``'s slot on, its last held to fill the horizon (no
        plan yet: all at half the range)."""
        n = self.spec.slots
        last = self.last
        if last is None:
            return np.full(n, 0.5 * self.i_max)
        return np.array([last.command_at(cycle + j * self.spec.slot_cycles) for j in range(n)])

    def _cost(self, u: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """The mean of θ̈2² over the horizon under ``u`` and its gradient (the model's adjoint)."""
        b, n = self._bufs, u.size
        cost = self.forward(u, w, self.m, self.h, self._x0, *b)
        self.adjoint(u, w, self.m, self.h, b[0], b[1], b[2], b[3], (2.0 / n) * b[4], self._grad)
        return float(cost), self._grad.copy()


class PlanSource(Protocol):
    """Where a preview law's plans come from: :class:`InlinePlanner`, or a planner beside the loop
    (:class:`sashil.runtime.planner.PlannerProcess`)."""

    def start(self, plan: HorizonPlan) -> None: ...

    def request(self, cycle: int, state: tuple[float, float, float, float], road_ahead: np.ndarray) -> None: ...

    def latest(self, cycle: int) -> HorizonPlan | None: ...

    def close(self) -> None: ...


class InlinePlanner:
    """Plans in the loop's own cycle and hands the plan over ``delay_cycles`` later, the cycle a
    planner beside the loop answers by at the latest: on simulated time the loop's results are then
    deterministic and the same as with the plan made beside it on time. The loop on the real clock
    plans in a process of its own instead (:mod:`sashil.runtime.planner`), with the same two calls."""

    def __init__(self, planner: HorizonPlanner):
        self.planner = planner
        self.delay = int(planner.spec.delay_cycles)
        self._current: HorizonPlan | None = None
        self._pending: HorizonPlan | None = None

    def start(self, plan: HorizonPlan) -> None:
        """The plan in force from the run's first cycle (made before it), the next made from it."""
        self._current, self._pending = plan, None
        self.planner.last = plan

    def request(self, cycle: int, state: tuple[float, float, float, float], road_ahead: np.ndarray) -> None:
        """Plan from ``state`` at ``cycle`` on ``road_ahead`` (in force from ``cycle`` + the delay); a
        plan due by ``cycle`` comes into force first, so the new one starts from it."""
        self.latest(cycle)
        self._pending = self.planner.plan(cycle, state, road_ahead)

    def latest(self, cycle: int) -> HorizonPlan | None:
        """The plan in force at ``cycle``: the newest whose delay has passed."""
        pending = self._pending
        if pending is not None and cycle >= pending.start + self.delay:
            self._current, self._pending = pending, None
        return self._current

    def close(self) -> None:
        """Nothing to release (a planner process ends here)."""

"""Re-planning the road ahead from the measured state, a little each cycle: the real-time
iteration scheme of nonlinear MPC (Diehl, Bock & Schlöder, SIAM J. Control Optim. 43(5), 2005):
instead of solving each horizon's problem to the end, every cycle takes one step of its optimiser
from the previous cycle's solution, shifted, and the command is always the latest iterate's.

The horizon is ``slots`` slots of ``cycles`` loop cycles each (the plan's model stepped at
h_c = cycles·h, :mod:`sashil.control.preview_plan` or :mod:`sashil.control.plan_boucwen`). At each
slot's first cycle the horizon moves on by one slot, starts from the state measured then
(θ, θ̇2, ẑ, i), and takes the road speeds commanded over its slots (their means); the slot that
enters at its end is the whole-road plan's. Each cycle then takes one step of projected gradient
on the mean of θ̈2² over the horizon: u ← clip(u − η·i_max·g/‖g‖∞, 0, i_max), the gradient g from
the model's adjoint; the step is kept where it lowers the cost and η grows by half, else η halves
(a backtracking line search spread over cycles; Nocedal & Wright 2006, §3.1 and the projected
gradient of §16.7). The law adds the horizon's first slot's change to the whole-road plan's
command of this cycle, so on the plan's own trajectory nothing changes.
"""

from __future__ import annotations

import numpy as np

from sashil.control.preview_plan import Model

__all__ = ["RecedingPlan"]


def _slot_means(x: np.ndarray, cycles: int, slots: int, pad: float) -> np.ndarray:
    """The means of ``x`` over consecutive runs of ``cycles``, then ``slots`` more of ``pad``."""
    whole = x.size // cycles
    means = x[: whole * cycles].reshape(whole, cycles).mean(axis=1) if whole else np.empty(0)
    return np.concatenate([means, np.full(slots + 1, pad)])


class RecedingPlan:
    """The horizon of the module docstring over a whole-road plan's commands ``plan_a`` on the road
    speeds ``road_rate`` (one per cycle), re-planned on ``model`` at ``h`` per cycle."""

    def __init__(
        self,
        model: Model,
        i_max: float,
        plan_a: np.ndarray,
        road_rate: np.ndarray,
        h: float,
        cycles: int,
        slots: int,
    ):
        self.model, self.i_max, self.cycles, self.slots = model, float(i_max), int(cycles), int(slots)
        self.h = h * self.cycles
        self.m = model.vector()
        self._plan = _slot_means(np.asarray(plan_a, dtype=float), self.cycles, self.slots, float(plan_a[-1]))
        self._road = _slot_means(np.asarray(road_rate, dtype=float), self.cycles, self.slots, 0.0)
        n = self.slots
        self.u, self.w, self.x0 = np.empty(n), np.empty(n), np.zeros(4)
        self._bufs = [np.empty(n) for _ in range(5)]
        self._trial_bufs = [np.empty(n) for _ in range(5)]
        self._grad, self._trial, self._direct = np.empty(n), np.empty(n), np.empty(n)
        self.restart()

    def restart(self) -> None:
        """Back to the road's start: the horizon the whole-road plan's first slots."""
        self.u[:] = self._plan[: self.slots]
        self.w[:] = self._road[: self.slots]
        self.x0[:] = 0.0
        self.eta = 0.05
        self.slot = 0

    def move_to(self, slot: int, theta: float, body_rate: float, z: float, current: float) -> None:
        """The horizon from ``slot`` on, from the state measured now; the slot entering at its end from
        the whole-road plan."""
        last = self._plan.size - self.slots
        slot = min(max(slot, 0), last)
        shift = slot - self.slot
        if 0 < shift < self.slots:
            self.u[:-shift] = self.u[shift:]
            self.u[-shift:] = self._plan[slot + self.slots - shift : slot + self.slots]
        elif shift != 0:
            self.u[:] = self._plan[slot : slot + self.slots]
        self.w[:] = self._road[slot : slot + self.slots]
        self.slot = slot
        self.x0[0], self.x0[1], self.x0[2], self.x0[3] = theta, body_rate, z, current

    def change(self) -> float:
        """The horizon's first slot's command less the whole-road plan's [A]."""
        return float(self.u[0] - self._plan[self.slot])

    def iterate(self) -> None:
        """One projected-gradient step with its line search (module docstring)."""
        model, n = self.model, self.slots
        b, t = self._bufs, self._trial_bufs
        cost = model.forward(self.u, self.w, self.m, self.h, self.x0, *b)
        np.multiply(b[4], 2.0 / n, out=self._direct)
        model.adjoint(self.u, self.w, self.m, self.h, b[0], b[1], b[2], b[3], self._direct, self._grad)
        largest = float(np.max(np.abs(self._grad)))
        if not largest > 0.0:
            return
        np.multiply(self._grad, -self.eta * self.i_max / largest, out=self._trial)
        np.add(self._trial, self.u, out=self._trial)
        np.clip(self._trial, 0.0, self.i_max, out=self._trial)
        if model.forward(self._trial, self.w, self.m, self.h, self.x0, *t) < cost:
            self.u[:] = self._trial
            self.eta = min(0.5, 1.5 * self.eta)
        else:
            self.eta = max(1e-4, 0.5 * self.eta)

"""``preview-optimal``: a law that knows the road to come plans the optimal damping before the run
and tracks it online.

Plan (before the run, :meth:`PreviewOptimal.plan_road`): the commanded road's speeds θ̇1 of every
cycle go to :func:`sashil.control.preview_plan.plan_damping`, the optimal bound's own optimiser
(direct transcription, the discrete adjoint, L-BFGS-B) over a receding horizon, on the law's model
(the controller's: ``--params`` sets it) in its viscous envelope. The plan gives, for every cycle k,
the damping c*_k in [c1, c1 + c2·i_max] and the envelope's state under it, θ*_k and θ̇2*_k. This is
the "optimal predictive control, assuming full knowledge of the disturbance" of Savaresi et al.
(mixed SH-ADD, ASME JDSMC) run as a law.

Track (each cycle, two list reads and a few multiplications):

    T* = c*_k·θ̇ − g·(k_θ·(θ − θ*_k) + k_v·(θ̇2 − θ̇2*_k))

the planned damping on the measured rate, plus a feedback on the state error with the LQR gains of
the rig's linear model (:mod:`sashil.control.lqr`, Dyke et al. 1996 eqs. 5-8, at 0 A, the default
weights) scaled by ``feedback_gain`` g. T* goes through the inverse, which clips it to the feasible
band (the clipping that makes the one-step case of the optimal semi-active law clipped LQR:
Giorgetti, Bemporad et al., IJC 2006). The inverse also accounts for the hysteretic part α(i)·ẑ the
plan left out. Past the planned road the law holds the plan's last damping.

The law reads the whole commanded road once, before the run; it reads no per-cycle window
(:meth:`preview_cycles` is 0), since the plan already holds the road of every cycle.
"""

from __future__ import annotations

from sashil.control.law_api import CommandedRoad, Law, LawState, Param
from sashil.control.lqr import scaled_lqr_gains
from sashil.control.preview_plan import plan_damping
from sashil.errors import ConfigError

__all__ = ["PreviewOptimal"]


class PreviewOptimal(Law):
    """Plans the optimal damping over the commanded road before the run (the bound's optimiser over a
    receding horizon, on the law's model) and tracks it: T* = c*_k·θ̇ plus an LQR feedback on the
    error from the planned state (Savaresi et al.; Giorgetti, Bemporad et al. 2006)."""

    name = "preview-optimal"
    reads_road_ahead = True

    block_s = Param(10.0, unit="s", low=0.05, high=600.0, doc="length of each planned block")
    tail_s = Param(2.0, unit="s", low=0.0, high=60.0, doc="road after a block that its optimisation also sees")
    plan_iterations = Param(400, low=1, high=100000, doc="L-BFGS-B iterations per block at most")
    feedback_gain = Param(1.0, low=0.0, high=10.0, doc="gain of the LQR feedback on the error from the planned state")

    def parameters_changed(self) -> None:
        if self.context is None:
            raise ConfigError(f"controller.block_s: law {self.name!r} needs the rig model (build it with a LawContext)")
        p = self.context.model
        design = scaled_lqr_gains(p.J, p.k, p.c1, 1.0, 0.5, 0.0, 0.0)
        self.k_theta = float(self.feedback_gain) * design.k_theta
        self.k_body = float(self.feedback_gain) * design.k_body
        self._c: list[float] = []
        self._theta: list[float] = []
        self._body: list[float] = []
        self._dt = 1.0 / float(self.context.rate_hz)
        self._last = p.c1

    def plan_road(self, road: CommandedRoad) -> None:
        """Plan the damping of every cycle of ``road`` (module docstring)."""
        assert self.context is not None
        plan = plan_damping(
            self.context.model,
            self.context.current_max_a,
            road.rate_rad_s,
            road.dt_s,
            block_s=float(self.block_s),
            tail_s=float(self.tail_s),
            max_iterations=int(self.plan_iterations),
        )
        self._dt = road.dt_s
        self._c = plan.damping.tolist()
        self._theta = plan.theta_rad.tolist()
        self._body = plan.body_dot_rad_s.tolist()
        self._last = self._c[-1] if self._c else self.context.model.c1

    def torque(self, state: LawState) -> float:
        k = int(state.time_s / self._dt + 0.5)
        if k >= len(self._c):  # past the planned road (or none planned): the last damping, no feedback
            return self._last * state.theta_dot_rad_s
        return (
            self._c[k] * state.theta_dot_rad_s
            - self.k_theta * (state.theta_rad - self._theta[k])
            - self.k_body * (state.body_dot_rad_s - self._body[k])
        )

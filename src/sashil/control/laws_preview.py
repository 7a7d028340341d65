"""``preview-optimal``: a law that knows the road to come plans the optimal damping over it.

Receding (``plan: receding``, the default): semi-active model predictive control with road preview
(Göhrle et al., IEEE/ASME Trans. Mechatronics 2014; Giorgetti, Bemporad et al., IJC 2006). Every
``replan_cycles`` cycles the law asks for a plan from the state its controller estimates (θ, θ̇2,
ẑ, the measured coil current) over ``horizon_s``, the road known for ``preview_s`` ahead (the
window of :meth:`preview_cycles` the controller fills each cycle; at rest past it), on the law's
Bouc-Wen model stepped every ``slot_cycles`` cycles (:mod:`sashil.control.preview_horizon`). The
plan comes into force ``replan_cycles`` after its request, its first slots the commands already
in force; the law commands the plan in force, each cycle a read of its slot. Before the run the
first plan is made from rest over the road's first preview. Where a plan is made: on simulated
time in the law's own cycle (deterministic), on the real clock in a planner process beside the loop
(:mod:`sashil.runtime.planner`), so the loop's cycle pays a request every re-plan period and one
read of shared memory each cycle.

Open loop (``plan: open-loop``): the whole road planned before the run and tracked. It keeps more
of the bound on a model that is the plant, and far less on one that is not; a lab's rig is never
its model, so the re-planned law is the default. Over the 18-damper spread on ISO 8608 C at
10 m/s (``tools/bench_preview.py --curve --previews 1 --dampers all --roads iso8608:C:10``), median /
worst share of the true plant's bound (compare's baseline and law-free bound), re-planned with 1 s
of preview against open loop: exact model 80.8 / 73.2 % against 89.6 / 85.2 %; 10 % off 75.9 / 43.3 %
against 48.4 / −43.9 %; 20 % off 60.4 / 31.4 % against −13.4 / −201.4 %; a Dahl plant 77.1 / −113.0 %
against 86.4 / 6.3 %. The re-planned law's gap on the exact model is the road past its preview:
over the manual's curve (``tools/figures.py --figure preview_curve``, 6 cases) 1, 2 and 3 s of
preview keep a median 74.5, 77.8 and 79.0 % against the open loop's 80.8 %: the gap narrows with
each second of preview (6.3, 3.0, 1.8 points), and the arm's free response decays to
e^(−ζω·1 s) = e^(−0.13·10.7) = 0.25 a second, so the road past a 1 s preview still moves the arm.

Plan (before the run, :meth:`PreviewOptimal.plan_road`): the commanded road's speeds θ̇1 of every
cycle go to :func:`sashil.control.preview_plan.plan_current`, the optimal bound's own optimiser
(direct transcription, the discrete adjoint, L-BFGS-B) over a receding horizon, on the law's model
(the controller's: ``--params`` sets it) and the coil's lag (``LawContext.coil_tau_s``). With
``plan_model: bouc-wen`` (the default) the plan is first made with the hysteresis as a friction
α(i)·z_u (smooth: found from the best constant current) and then refined from it on the model's own
Bouc-Wen state (:mod:`sashil.control.plan_boucwen`: at small travel the damper is a spring, which a
friction leaves out); ``friction`` stops after the first, ``envelope`` plans the viscous envelope.
The plan gives, for every cycle k, the command u*_k in [0, i_max] and the model's state under it,
the coil's current i*_k, θ*_k and θ̇2*_k. Its cost is the mean of θ̈2², or of θ̈2 low-passed at
``comfort_bandwidth_hz`` as ``sashil compare`` measures comfort (0, the default: unfiltered; over
the damper spread the filter changed the law's comfort by a median −0.1 % and cost up to 29 % on a
damper that locks). This is the "optimal predictive
control, assuming full knowledge of the disturbance" of Savaresi et al. (mixed SH-ADD, ASME JDSMC)
run as a law.

Track (each cycle, a few list reads and multiplications): the law commands the current

    i = clip(u*_k + ΔT / D, 0, i_max),   ΔT = −g·(k_θ·(θ − θ*_k) + k_v·(θ̇2 − θ̇2*_k)),
    D = ∂T/∂i = α2·ẑ + c2·θ̇ (seed 001 eq. 9)

the planned command, plus a feedback on the error from the planned state with the LQR gains of the
rig's linear model (:mod:`sashil.control.lqr`, Dyke et al. 1996 eqs. 5-8, at 0 A, the default
weights) scaled by ``feedback_gain`` g, turned into amperes through the torque's slope in the
current (left out where |D| < 10⁻³ N m/A: the current cannot move the torque) and clipped to the
coil's range (the clipping that makes the one-step case of the optimal semi-active law clipped LQR:
Giorgetti, Bemporad et al., IJC 2006). A current law: the plan already holds the coil's lag, so
the coil-lag lead is not applied (``controller.lead_current_laws`` false). Past the planned road
the law commands the plan's last current.

Re-plan (``replan_horizon_s`` > 0; 0, the default, for none): each cycle one step of the real-time
iteration of :mod:`sashil.control.preview_mpc` re-plans the next ``replan_horizon_s`` from the state
measured at each slot of ``replan_slot_cycles`` cycles (θ, θ̇2, ẑ and the coil's current), on the
plan's model at that coarser step, and the law adds the first slot's change to the planned
command. The open-loop plan drifts from a rig its model is not (the arm's phase, after a few
seconds on a spring and inertia 10 % off); the re-planned horizon starts from the rig's state. Its
cost per cycle grows with the horizon's slots (the model stepped three times over them).

The law reads the whole commanded road once, before the run; it reads no per-cycle window
(:meth:`preview_cycles` is 0), since the plan already holds the road of every cycle.
"""

from __future__ import annotations

import numpy as np

from sashil.control.law_api import CommandedRoad, Law, LawState, Param
from sashil.control.lqr import scaled_lqr_gains
from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview_horizon import HorizonPlanner, HorizonSpec, InlinePlanner, PlanSource
from sashil.control.preview_mpc import RecedingPlan
from sashil.control.preview_plan import Horizon, Model, PlanModel, plan_current
from sashil.errors import ConfigError

__all__ = ["PreviewOptimal"]


class PreviewOptimal(Law):
    """Re-plans the optimal current from the estimated state over the road a finite preview shows,
    every few cycles, and commands the plan in force (receding-horizon semi-active MPC: Göhrle et al.
    2014; Giorgetti, Bemporad et al. 2006); or, with ``plan: open-loop``, plans the whole commanded
    road before the run and tracks it with an LQR feedback on the error from the planned state
    (Savaresi et al.)."""

    name = "preview-optimal"
    reads_road_ahead = True

    plan = Param(
        "receding",
        choices=("receding", "open-loop"),
        doc="re-plan from the estimated state over the preview (receding), or plan the whole road before the run",
    )
    preview_s = Param(1.0, unit="s", low=0.0, high=4.0, doc="road known ahead of each re-plan (receding)")
    horizon_s = Param(
        2.0,
        unit="s",
        low=0.01,
        high=4.0,
        doc="time each re-plan looks ahead, the road at rest past the preview (receding)",
    )
    slot_cycles = Param(2, low=1, high=100, doc="cycles per step of the re-plan's model (receding)")
    replan_cycles = Param(
        50, low=1, high=1000, doc="cycles between re-plans, and from a request to its plan in force (receding)"
    )
    replan_iterations = Param(30, low=1, high=10000, doc="L-BFGS-B iterations per re-plan at most (receding)")
    block_s = Param(10.0, unit="s", low=0.05, high=600.0, doc="length of each planned block")
    tail_s = Param(2.0, unit="s", low=0.0, high=60.0, doc="road after a block that its optimisation also sees")
    plan_iterations = Param(400, low=1, high=100000, doc="L-BFGS-B iterations per block at most")
    feedback_gain = Param(0.0, low=0.0, high=10.0, doc="gain of the LQR feedback on the error from the planned state")
    plan_model = Param(
        "bouc-wen",
        choices=("bouc-wen", "friction", "envelope"),
        doc="the plan's damper: its Bouc-Wen state, the hysteresis as a friction α(i)·z_u, or the viscous envelope",
    )
    comfort_bandwidth_hz = Param(
        0.0,
        unit="Hz",
        low=0.0,
        high=500.0,
        doc="the plan's cost on θ̈2 low-passed here, as compare measures (0: unfiltered)",
    )
    replan_horizon_s = Param(
        0.0, unit="s", low=0.0, high=5.0, doc="horizon re-planned from the measured state each cycle (0: none)"
    )
    replan_slot_cycles = Param(5, low=1, high=100, doc="cycles per step of the re-planned horizon's model")
    friction_eps = Param(
        0.01, unit="rad/s", low=0.0, low_open=True, high=1.0, doc="rate over which the plan's friction turns"
    )

    def parameters_changed(self) -> None:
        if self.context is None:
            raise ConfigError(f"controller.block_s: law {self.name!r} needs the rig model (build it with a LawContext)")
        p = self.context.model
        design = scaled_lqr_gains(p.J, p.k, p.c1, 1.0, 0.5, 0.0, 0.0)
        self.k_theta = float(self.feedback_gain) * design.k_theta
        self.k_body = float(self.feedback_gain) * design.k_body
        self.c2, self.alpha2 = p.c2, p.alpha2
        self.i_max = float(self.context.current_max_a)
        self._i: list[float] = []
        self._theta: list[float] = []
        self._body: list[float] = []
        self._dt = 1.0 / float(self.context.rate_hz)
        self._last = 0.0
        self._receding: RecedingPlan | None = None
        self.planner: PlanSource | None = None
        self._replan = int(self.replan_cycles)
        if str(self.plan) == "receding":
            slot = int(self.slot_cycles)
            if self._replan % slot:
                raise ConfigError(
                    f"controller.replan_cycles: expected a multiple of controller.slot_cycles ({slot}), got {self._replan}"
                )
            self._spec = HorizonSpec(
                self._dt,
                slot,
                max(1, int(round(float(self.horizon_s) / (slot * self._dt)))),
                self.preview_cycles(),
                self._replan,
                int(self.replan_iterations),
            )

    def preview_cycles(self) -> int:
        """The cycles of road ahead each re-plan reads (receding; 0 for the plan of the whole road)."""
        if str(self.plan) != "receding":
            return 0
        return int(round(float(self.preview_s) / self._dt))

    def plan_road(self, road: CommandedRoad) -> None:
        """Receding: the first plan, from rest over the road's first preview; open-loop: plan the
        damping of every cycle of ``road`` (module docstring)."""
        assert self.context is not None
        ctx = self.context
        if str(self.plan) == "receding":
            planner = HorizonPlanner(ctx.model, ctx.coil_tau_s, ctx.current_max_a, self._spec)
            self._first = planner.plan(0, (0.0, 0.0, 0.0, 0.0), road.rate_rad_s, at_once=True)
            self.planner = InlinePlanner(planner)
            self.planner.start(self._first)
            return
        kind = str(self.plan_model)
        friction = PlanModel.of(ctx.model, kind != "envelope", float(self.friction_eps), ctx.coil_tau_s, road.dt_s)
        horizon = Horizon(
            float(self.block_s), float(self.tail_s), int(self.plan_iterations), float(self.comfort_bandwidth_hz) or None
        )
        plan = plan_current(friction, ctx.current_max_a, road.rate_rad_s, road.dt_s, horizon)
        if kind == "bouc-wen":  # refined on the rig's own hysteresis, from the friction's plan
            model = BoucWenPlanModel.of(ctx.model, ctx.coil_tau_s, road.dt_s)
            plan = plan_current(
                model,
                ctx.current_max_a,
                road.rate_rad_s,
                road.dt_s,
                horizon,
                initial=plan.command_a,
                from_constant=False,
            )
        self._dt = road.dt_s
        self._receding = self._receding_of(plan.command_a, road)
        self._i = plan.command_a.tolist()
        self._theta = plan.theta_rad.tolist()
        self._body = plan.body_dot_rad_s.tolist()
        self._last = self._i[-1] if self._i else 0.0

    def _receding_of(self, plan_a: np.ndarray, road: CommandedRoad) -> RecedingPlan | None:
        """The re-planned horizon over the plan ``plan_a`` (None: ``replan_horizon_s`` 0)."""
        assert self.context is not None
        ctx, kind, cycles = self.context, str(self.plan_model), int(self.replan_slot_cycles)
        slots = int(round(float(self.replan_horizon_s) / (cycles * road.dt_s)))
        if slots <= 0 or plan_a.size == 0:
            return None
        h = cycles * road.dt_s
        coarse: Model = (
            BoucWenPlanModel.of(ctx.model, ctx.coil_tau_s, h)
            if kind == "bouc-wen"
            else PlanModel.of(ctx.model, kind != "envelope", float(self.friction_eps), ctx.coil_tau_s, h)
        )
        return RecedingPlan(coarse, ctx.current_max_a, plan_a, road.rate_rad_s, road.dt_s, cycles, slots)

    def reset(self) -> None:
        if self._receding is not None:
            self._receding.restart()
        if self.planner is not None:
            self.planner.start(self._first)

    def current(self, state: LawState) -> float:
        k = int(state.time_s / self._dt + 0.5)
        planner = self.planner
        if planner is not None:
            if k % self._replan == 0 and k > 0:
                planner.request(
                    k, (state.theta_rad, state.body_dot_rad_s, state.z_hat, state.current_a), state.road_ahead_dot_rad_s
                )
            plan = planner.latest(k)
            return 0.0 if plan is None else plan.command_at(k)
        if k >= len(self._i):  # past the planned road (or none planned): the last current, no feedback
            return self._last
        u = self._i[k]
        receding = self._receding
        if receding is not None:
            if k % receding.cycles == 0:
                slot = k // receding.cycles
                receding.move_to(slot, state.theta_rad, state.body_dot_rad_s, state.z_hat, state.current_a)
            receding.iterate()
            u = min(self.i_max, max(0.0, u + receding.change()))
        if self.k_theta == 0.0 and self.k_body == 0.0:
            return u
        error = self.k_theta * (state.theta_rad - self._theta[k]) + self.k_body * (state.body_dot_rad_s - self._body[k])
        slope = self.alpha2 * state.z_hat + self.c2 * state.theta_dot_rad_s
        if -1e-3 < slope < 1e-3:
            return u
        return min(self.i_max, max(0.0, u - error / slope))

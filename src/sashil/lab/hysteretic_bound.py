"""The optimal bound on the rig's own model: the best comfort a damper could reach knowing the road
in advance, with its Bouc-Wen state and the coil's lag, rather than the viscous envelope of
:mod:`sashil.lab.optimal_bound`.

The envelope leaves out the hysteretic torque α(i)·z: where z sits at its bound z_u it is a friction
of α1·z_u at 0 A and (α1 + α2·i_max)·z_u at i_max, so the rig's hard end is harder than the
envelope's and a law on the rig can beat the envelope's bound; at small travel it is a spring of
stiffness α(i)·δ, which a friction leaves out too, and there the envelope's bound lies far below
anything the rig can do (a damper whose z never leaves that spring locks the arm to the road at any
current). This bound solves the same problem (direct transcription, the exact discrete adjoint,
L-BFGS-B) on the model of :mod:`sashil.control.plan_boucwen`, the whole road as one block, from
three starts: the best constant current, and the best plans of the hysteresis as a friction
α(i)·z_u (:mod:`sashil.control.preview_plan`, smooth, so its optimum is found from afar) over the
whole road and over ``preview-optimal``'s receding horizon (its default blocks). The problem is not
convex: each start ends in a local optimum of its own, and the bound is the best of them. Like the
envelope's, it is the best found, not a certificate. With ``bandwidth_hz`` its cost and its result
are θ̈2 low-passed as compare's metric is (a friction's switching adds θ̈2 above the metric's band,
which the metric never sees).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview import commanded_road
from sashil.control.preview_plan import Horizon, PlanModel, comfort_filter, lowpass, plan_current
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RoadProfile

__all__ = ["hysteretic_bound"]

#: preview-optimal's default blocks: a start of the bound is the plan it makes
RECEDING = Horizon()


def hysteretic_bound(
    params: BoucWenParams,
    current_max_a: float,
    coil_tau_s: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    max_iterations: int = 3000,
    bandwidth_hz: float | None = None,
) -> float:
    """RMS θ̈2 [rad/s²] after ``settle_s`` of the best plan found on ``road`` over ``duration_s``;
    ``bandwidth_hz``: θ̈2 low-passed there, in the cost and the result, as compare's metric is."""
    n = int(round(duration_s / h))
    rates = commanded_road(lambda t: road(t)[1], h, duration_s, 0).rate_rad_s[:n]
    sos, first = comfort_filter(bandwidth_hz, h), min(n - 1, int(round(settle_s / h)))
    friction = PlanModel.of(params, True, 0.01, coil_tau_s, h)
    whole = Horizon(duration_s, 0.0, max_iterations, bandwidth_hz)
    model = BoucWenPlanModel.of(params, coil_tau_s, h)
    found = []
    for horizon, from_constant in (
        (whole, True),
        (replace(whole, block_s=RECEDING.block_s, tail_s=RECEDING.tail_s), False),
    ):
        start = plan_current(friction, current_max_a, rates, h, horizon).command_a
        plan = plan_current(model, current_max_a, rates, h, whole, initial=start, from_constant=from_constant)
        a = lowpass(plan.accel_rad_s2, sos)[first:]
        found.append(math.sqrt(float(np.mean(a * a))))
    return min(found)

"""The optimal bound on the hysteretic model: the best comfort a damper could reach knowing the road
in advance, with the Bouc-Wen term as a friction α(i)·z_u and the coil's lag, rather than the
viscous envelope of :mod:`sashil.experiments.optimal_bound`.

The envelope leaves out the hysteretic torque α(i)·z, which with z at its bound z_u is a friction
of α1·z_u at 0 A and (α1 + α2·i_max)·z_u at i_max: the rig's hard end is harder than the envelope's,
and its soft end less soft. A law on the rig can then beat the envelope's bound. This bound solves
the same problem (direct transcription, the exact discrete adjoint, L-BFGS-B) on the model of
:mod:`sashil.control.preview_plan`, the whole road as one block, from the best constant current;
like the envelope's, it is the best found, not a certificate. With ``bandwidth_hz`` its cost and its
result are θ̈2 low-passed as compare's metric is (a friction's switching adds θ̈2 above the metric's
band, which the metric never sees).
"""

from __future__ import annotations

import math

import numpy as np

from sashil.control.preview import commanded_road
from sashil.control.preview_plan import PlanModel, comfort_filter, lowpass, plan_current
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RoadProfile

__all__ = ["hysteretic_bound"]


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
    model = PlanModel.of(params, True, 0.01, coil_tau_s, h)
    plan = plan_current(
        model,
        current_max_a,
        rates,
        h,
        block_s=duration_s,
        tail_s=0.0,
        max_iterations=max_iterations,
        bandwidth_hz=bandwidth_hz,
    )
    a = lowpass(plan.accel_rad_s2, comfort_filter(bandwidth_hz, h))[min(n - 1, int(round(settle_s / h))) :]
    return math.sqrt(float(np.mean(a * a)))

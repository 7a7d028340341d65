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

The bound is the model's own θ̈2, with no measurement in it; a run over a link is measured by its
encoders (:func:`sashil.lab.compare_metrics.arm_acceleration`). Through the samples' counts alone
their quantisation adds a floor of noise independent of the arm's motion, in quadrature (for a
4096-count encoder about 1 rad/s² RMS at 20 Hz, the same for every law). Through the arm encoder's
edges, as compare reads a stream that has them, that floor is gone, and the chain reads 0.1–2 % low
instead (the band's content where the edges lie further apart than its period, most at 1 A, where
the arm moves least). Both ends of a share's scale and the law must be on one chain:
:func:`bound_on_chain` puts the bound on the chain that measured the runs, with the floor measured as
the passive run's excess over the model's own passive run at the same current (:func:`model_passive`),
sqrt(b² + p_chain² − p_model²). On the edges' chain that excess is small and of either sign (the
chain's loss, and the road the link realised, ±1 %), and still wanted: a passive run read low
narrows the share's gap p − b, and the bound read alike keeps it (over serial, 30 s runs: shares
within a median 5 points of the simulated rig's with it, 8 without). On the simulated rig's own θ̈2
the floor is the model's discretisation alone (near 0).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview import commanded_road
from sashil.control.preview_plan import Horizon, PlanModel, comfort_filter, lowpass, plan_current, simulate_plan
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RoadProfile

__all__ = ["bound_on_chain", "hysteretic_bound", "model_passive"]

#: preview-optimal's default blocks: a start of the bound is the plan it makes
RECEDING = Horizon()


def _road_rates(road: RoadProfile, duration_s: float, h: float) -> np.ndarray:
    """The road speeds commanded at each cycle of ``h`` over ``duration_s``, as a run commands them."""
    n = int(round(duration_s / h))
    return commanded_road(lambda t: road(t)[1], h, duration_s, 0).rate_rad_s[:n]


def _rms_after(accel: np.ndarray, settle_s: float, h: float, bandwidth_hz: float | None) -> float:
    """RMS of ``accel`` low-passed at ``bandwidth_hz`` (None: unfiltered) after ``settle_s``."""
    first = min(accel.size - 1, int(round(settle_s / h)))
    a = lowpass(accel, comfort_filter(bandwidth_hz, h))[first:]
    return math.sqrt(float(np.mean(a * a)))


def model_passive(
    params: BoucWenParams,
    current_a: float,
    coil_tau_s: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    bandwidth_hz: float | None = None,
) -> float:
    """RMS θ̈2 [rad/s²] after ``settle_s`` of the bound's model at the constant current ``current_a``
    on ``road``: the passive run as the bound's model gives it, low-passed as compare's metric is."""
    rates = _road_rates(road, duration_s, h)
    plan = simulate_plan(BoucWenPlanModel.of(params, coil_tau_s, h), np.full(rates.size, float(current_a)), rates, h)
    return _rms_after(plan.accel_rad_s2, settle_s, h, bandwidth_hz)


def bound_on_chain(bound: float, passive_chain: float, passive_model: float) -> float:
    """The bound ``bound`` [rad/s²] as the chain that measured the passive run ``passive_chain`` would
    read it: sqrt(b² + f²), the chain's floor f² = ``passive_chain``² − ``passive_model``² (the model's
    passive run at the same current; module docstring). NaN where a value is missing or b² + f² ≤ 0."""
    floor2 = passive_chain * passive_chain - passive_model * passive_model
    total = bound * bound + floor2
    if not (math.isfinite(total) and total > 0.0):
        return math.nan
    return math.sqrt(total)


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
    rates = _road_rates(road, duration_s, h)
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
        found.append(_rms_after(plan.accel_rad_s2, settle_s, h, bandwidth_hz))
    return min(found)

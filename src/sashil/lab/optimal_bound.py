"""The optimal semi-active bound for a road record: the best comfort any damper inside the feasible
band could reach, knowing the whole road in advance (the benchmark idea of Poussot-Vassal, Savaresi
et al.: an offline optimal control of the damping, against which causal laws are measured).

The Bouc-Wen model's hysteretic torque makes the problem non-smooth, so the bound is computed for
the model's **viscous envelope**: the rig of seed 001 eq. 13 without the z term,

    J θ̈2 = −k θ − c(t) θ̇,   θ = θ2 − θ1,   c(t) ∈ [c1, c1 + c2·i_max]   (seed 001 eq. 11)

on the recorded road rate θ̇1(t). Direct transcription by single shooting: the damping c_k of every
step (h = 1 ms) is a decision variable with box bounds only, the state is stepped by semi-implicit
Euler, v_{k+1} = v_k + h·a_k, θ_{k+1} = θ_k + h·(v_{k+1} − θ̇1_k), and the cost is the mean of a_k²
after the settling time. Its exact gradient comes from the discrete adjoint, and L-BFGS-B
(scipy.optimize) solves it: box bounds are all it needs, and 30 000 variables cost it seconds.
The problem is not convex (the damping multiplies the state), so the result is the best found from
the starts tried (the best constant damping and the softest), a bound no causal law in this model
has been seen to beat, not a certificate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sashil.models._jit import jit
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RoadProfile

__all__ = ["BoundResult", "envelope_cost", "optimal_bound"]


@jit
def _forward(c, w, k_over_j, inv_j, h, first, accel):
    """Fill ``accel`` with θ̈2 of every step from rest; return the mean of accel² from ``first`` on."""
    theta = 0.0
    v = 0.0
    total = 0.0
    n = c.size
    for i in range(n):
        a = -k_over_j * theta - inv_j * c[i] * (v - w[i])
        accel[i] = a
        if i >= first:
            total += a * a
        v = v + h * a
        theta = theta + h * (v - w[i])
    return total / (n - first)


@jit
def _gradient(c, w, k_over_j, inv_j, h, first, accel, grad):
    """The discrete adjoint: d(cost)/d(c_k) into ``grad`` (``accel`` from :func:`_forward`)."""
    n = c.size
    # states along the trajectory (recomputed forward, then swept backward)
    thetas = np.empty(n)
    vs = np.empty(n)
    theta = 0.0
    v = 0.0
    for i in range(n):
        thetas[i] = theta
        vs[i] = v
        v = v + h * accel[i]
        theta = theta + h * (v - w[i])
    scale = 1.0 / (n - first)
    lam_theta = 0.0
    lam_v = 0.0
    for i in range(n - 1, -1, -1):
        direct = 2.0 * accel[i] * scale if i >= first else 0.0
        # a_i moves v_{i+1} by h and theta_{i+1} by h^2
        g_a = direct + h * (lam_v + h * lam_theta)
        grad[i] = -g_a * inv_j * (vs[i] - w[i])
        new_theta = -g_a * k_over_j + lam_theta
        lam_v = -g_a * inv_j * c[i] + lam_v + h * lam_theta
        lam_theta = new_theta
    return 0


def envelope_cost(c: np.ndarray, w: np.ndarray, params: BoucWenParams, h: float, first: int) -> float:
    """Mean θ̈2² after ``first`` steps of the viscous envelope under damping ``c`` on road rate ``w``."""
    accel = np.empty(c.size)
    return float(_forward(c, w, params.k / params.J, 1.0 / params.J, h, first, accel))


@dataclass(frozen=True)
class BoundResult:
    """RMS θ̈2 of the best constant damping and of the bound, both in the viscous envelope."""

    c_passive: float
    rms_accel_passive: float
    rms_accel_bound: float
    iterations: int
    #: the model the bound was found on: "envelope" (this module's) or "hysteretic"
    #: (:mod:`sashil.lab.hysteretic_bound`, where it lies lower)
    model: str = "envelope"

    @property
    def gain_pct(self) -> float:
        """How far the bound lies below the envelope's best constant damping [%]."""
        return 100.0 * (1.0 - self.rms_accel_bound / self.rms_accel_passive)


def optimal_bound(
    params: BoucWenParams,
    current_max_a: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    max_iterations: int = 3000,
) -> BoundResult:
    """The bound of the module docstring for ``road`` over ``duration_s`` (cost after ``settle_s``)."""
    from scipy.optimize import minimize, minimize_scalar

    n = int(round(duration_s / h))
    first = min(n - 1, int(round(settle_s / h)))
    w = np.array([road(i * h)[1] for i in range(n)])
    lo, hi = params.c1, params.c1 + params.c2 * current_max_a
    k_over_j, inv_j = params.k / params.J, 1.0 / params.J
    accel = np.empty(n)
    grad = np.empty(n)

    def constant(c: float) -> float:
        return float(_forward(np.full(n, c), w, k_over_j, inv_j, h, first, accel))

    if not hi > lo:  # no authority: the damper is passive
        rms = math.sqrt(constant(lo))
        return BoundResult(lo, rms, rms, 0)

    best = minimize_scalar(constant, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4 * (hi - lo)})
    c_best = float(best.x)
    passive = min((constant(lo), lo), (constant(hi), hi), (float(best.fun), c_best))

    def cost(c: np.ndarray) -> tuple[float, np.ndarray]:
        value = _forward(c, w, k_over_j, inv_j, h, first, accel)
        _gradient(c, w, k_over_j, inv_j, h, first, accel, grad)
        return float(value), grad.copy()

    results = []
    for start in (passive[1], lo):
        res = minimize(
            cost,
            np.full(n, start),
            jac=True,
            method="L-BFGS-B",
            bounds=[(lo, hi)] * n,
            options={"maxiter": max_iterations, "maxfun": 2 * max_iterations},
        )
        results.append(res)
    res = min(results, key=lambda r: float(r.fun))
    bound = min(float(res.fun), passive[0])
    return BoundResult(
        passive[1], math.sqrt(passive[0]), math.sqrt(bound), int(sum(getattr(r, "nit", 0) for r in results))
    )

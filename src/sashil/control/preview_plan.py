"""The damping plan of a preview law: the optimal semi-active damping over the road to come, on the
law's model, by the optimal bound's own method (:mod:`sashil.experiments.optimal_bound`) over a
receding horizon.

The model is the rig of seed 001 eq. 13 in its viscous envelope (the hysteretic term left out, as
the bound leaves it out),

    J θ̈2 = −k θ − c(t) θ̇,   θ = θ2 − θ1,   c(t) ∈ [c1, c1 + c2·i_max]   (seed 001 eq. 11)

stepped by semi-implicit Euler at the loop's period h on the commanded road speed w_k:
a_k = −(k/J)·θ_k − (c_k/J)·(v_k − w_k), v_{k+1} = v_k + h·a_k, θ_{k+1} = θ_k + h·(v_{k+1} − w_k).
The cost of a block is the mean of a_k² (comfort alone, the bound's cost). Savaresi et al. (the
mixed SH-ADD paper, ASME JDSMC) call the whole-road solution "optimal predictive control, assuming
full knowledge of the disturbance"; Giorgetti, Bemporad et al. (IJC 2006) show it is piecewise affine
in the state and that its one-step case is clipped LQR.

Receding horizon, planned before the run: the road is cut into blocks of ``block_s``; each block is
optimised over itself plus ``tail_s`` of the road after it (so the block's end is not planned as if
the road ended there), from the state the previous block's plan reaches, and only the block is
kept. L-BFGS-B (box bounds only) with the exact discrete adjoint gradient, from the best constant
damping. The cost of planning grows with the road's length, not with its square.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sashil.models._jit import jit
from sashil.models.hysteresis import BoucWenParams

__all__ = ["DampingPlan", "plan_damping", "simulate_envelope"]


@jit
def _forward(c, w, k_over_j, inv_j, h, theta0, v0, thetas, vs, accel):
    """Step the envelope from (theta0, v0) under ``c``: the states before each step into ``thetas``,
    ``vs`` and θ̈2 into ``accel``; return the mean of accel²."""
    theta = theta0
    v = v0
    total = 0.0
    n = c.size
    for i in range(n):
        thetas[i] = theta
        vs[i] = v
        a = -k_over_j * theta - inv_j * c[i] * (v - w[i])
        accel[i] = a
        total += a * a
        v = v + h * a
        theta = theta + h * (v - w[i])
    return total / n


@jit
def _adjoint(c, w, k_over_j, inv_j, h, thetas, vs, accel, grad):
    """The discrete adjoint of :func:`_forward`'s cost: d(cost)/d(c_k) into ``grad``."""
    n = c.size
    scale = 1.0 / n
    lam_theta = 0.0
    lam_v = 0.0
    for i in range(n - 1, -1, -1):
        g_a = 2.0 * accel[i] * scale + h * (lam_v + h * lam_theta)
        grad[i] = -g_a * inv_j * (vs[i] - w[i])
        new_theta = -g_a * k_over_j + lam_theta
        lam_v = -g_a * inv_j * c[i] + lam_v + h * lam_theta
        lam_theta = new_theta
    return 0


@dataclass(frozen=True)
class DampingPlan:
    """The planned damping c_k [N m s/rad] of every cycle, and the envelope's state the plan gives
    before each cycle: the relative angle θ_k [rad] and the arm's rate θ̇2_k [rad/s]."""

    damping: np.ndarray
    theta_rad: np.ndarray
    body_dot_rad_s: np.ndarray
    accel_rad_s2: np.ndarray


def simulate_envelope(
    params: BoucWenParams, damping: np.ndarray, road_rate: np.ndarray, h: float, theta0: float = 0.0, v0: float = 0.0
) -> DampingPlan:
    """The envelope's trajectory under ``damping`` on ``road_rate`` from (θ0, θ̇2_0)."""
    n = damping.size
    thetas, vs, accel = np.empty(n), np.empty(n), np.empty(n)
    c = np.ascontiguousarray(damping, dtype=float)
    w = np.ascontiguousarray(road_rate[:n], dtype=float)
    _forward(c, w, params.k / params.J, 1.0 / params.J, h, theta0, v0, thetas, vs, accel)
    return DampingPlan(c, thetas, vs, accel)


def _plan_block(
    params: BoucWenParams, lo: float, hi: float, w: np.ndarray, h: float, theta0: float, v0: float, max_iterations: int
) -> np.ndarray:
    """The damping of one block of road speeds ``w`` from the state (θ0, θ̇2_0), from the best constant."""
    from scipy.optimize import minimize, minimize_scalar

    m = w.size
    k_over_j, inv_j = params.k / params.J, 1.0 / params.J
    thetas, vs, accel, grad = np.empty(m), np.empty(m), np.empty(m), np.empty(m)

    def constant(c: float) -> float:
        return float(_forward(np.full(m, c), w, k_over_j, inv_j, h, theta0, v0, thetas, vs, accel))

    best = minimize_scalar(constant, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * (hi - lo)})

    def cost(c: np.ndarray) -> tuple[float, np.ndarray]:
        value = _forward(c, w, k_over_j, inv_j, h, theta0, v0, thetas, vs, accel)
        _adjoint(c, w, k_over_j, inv_j, h, thetas, vs, accel, grad)
        return float(value), grad.copy()

    res = minimize(
        cost,
        np.full(m, float(best.x)),
        jac=True,
        method="L-BFGS-B",
        bounds=[(lo, hi)] * m,
        options={"maxiter": max_iterations, "maxfun": 2 * max_iterations},
    )
    return np.clip(np.asarray(res.x, dtype=float), lo, hi)


def plan_damping(
    params: BoucWenParams,
    current_max_a: float,
    road_rate: np.ndarray,
    h: float,
    block_s: float = 10.0,
    tail_s: float = 2.0,
    max_iterations: int = 400,
) -> DampingPlan:
    """The receding-horizon plan of the module docstring for the road speeds ``road_rate`` (one per
    cycle of ``h``), from rest."""
    n = road_rate.size
    lo, hi = params.c1, params.c1 + params.c2 * current_max_a
    w_all = np.ascontiguousarray(road_rate, dtype=float)
    plan = np.full(n, lo)
    if not hi > lo or n == 0:  # no authority: the damper is passive
        return simulate_envelope(params, plan, w_all, h)
    block, tail = max(1, int(round(block_s / h))), max(0, int(round(tail_s / h)))
    theta0 = v0 = 0.0
    for start in range(0, n, block):
        stop = min(n, start + block)
        w = w_all[start : min(n, stop + tail)]
        c = _plan_block(params, lo, hi, w, h, theta0, v0, max_iterations)
        kept = stop - start
        plan[start:stop] = c[:kept]
        # the state the kept block ends at: where the next block starts
        seg = simulate_envelope(params, c[:kept], w[:kept], h, theta0, v0)
        v0 = float(seg.body_dot_rad_s[-1] + h * seg.accel_rad_s2[-1])
        theta0 = float(seg.theta_rad[-1] + h * (v0 - w[kept - 1]))
    return simulate_envelope(params, plan, w_all, h)

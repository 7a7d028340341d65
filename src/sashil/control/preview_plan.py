"""The current plan of a preview law: the optimal semi-active current over the road to come, on the
law's model, by the optimal bound's own method (:mod:`sashil.lab.optimal_bound`) over a
receding horizon.

The model is the rig of seed 001 eq. 13 with the damper torque of eq. 9 linear in the current i,

    J θ̈2 = −k θ − T,   T = c(i)·θ̇ + α(i)·z_u·tanh(θ̇/ε),   c(i) = c1 + c2·i,  α(i) = α1 + α2·i

(eqs. 11-12), θ = θ2 − θ1. The coil lags its command u ∈ [0, i_max] by τ (``rig.coil_tau_s``),
i_{k+1} = i_k + ρ·(u_k − i_k), ρ = 1 − exp(−h/τ) (a command acts from the next sample on, as the
loop's does). The Bouc-Wen state z is taken at its bound z_u =
(δ/(β + γ))^(1/n) with the sign of θ̇: with the seed's parameters z crosses from −z_u to z_u within
2·z_u/δ ≈ 3·10⁻⁴ rad of travel, so the hysteresis acts as a friction torque α(i)·z_u, smoothed over
ε (``friction_eps``) so the cost has a gradient. With ``hysteresis=False`` the friction is left out:
the viscous envelope the bound of ``sashil compare`` is computed on.

It is stepped by semi-implicit Euler at the loop's period h on the commanded road speed w_k:
a_k = −(k/J)·θ_k − T(i_k, v_k − w_k)/J, v_{k+1} = v_k + h·a_k, θ_{k+1} = θ_k + h·(v_{k+1} − w_k),
and the cost of a block is the mean of a_k² (comfort alone, the bound's cost), or of a_k low-passed
at the comfort metric's bandwidth (``bandwidth_hz``: what ``sashil compare`` measures; a friction's
switching adds θ̈2 above it that the metric never sees), the filter F applied forward and back
from rest, so that Fᵀ = F and the direct term of the gradient is 2·F(F a)/n. Its exact gradient is
the discrete adjoint: with g_k = ∂cost/∂a_k (direct and through the next state),
λθ_k = −(k/J)·g_k + λθ_{k+1}, λv_k = −(∂T/∂θ̇)/J·g_k + λv_{k+1} + h·λθ_{k+1},
λi_k = −(∂T/∂i)/J·g_k + (1 − ρ)·λi_{k+1}, and ∂cost/∂u_k = ρ·λi_{k+1}. Savaresi et al. (the mixed SH-ADD paper, ASME JDSMC) call the whole-road solution
"optimal predictive control, assuming full knowledge of the disturbance"; Giorgetti, Bemporad et
al. (IJC 2006) show the optimal semi-active law is piecewise affine in the state and that its
one-step case is clipped LQR.

Receding horizon, planned before the run: the road is cut into blocks of ``block_s``; each block is
optimised over itself plus ``tail_s`` of the road after it (so the block's end is not planned as if
the road ended there), from the state the previous block's plan reaches, and only the block is
kept. L-BFGS-B (box bounds only) from the best constant current. The cost of planning grows with
the road's length, not with its square.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sashil.models._jit import jit, loop_kernel
from sashil.models.hysteresis import BoucWenParams

__all__ = [
    "REST",
    "CurrentPlan",
    "Horizon",
    "Model",
    "PlanModel",
    "comfort_filter",
    "lowpass",
    "plan_current",
    "simulate_plan",
]


def _warm_forward() -> tuple[object, ...]:
    """A call of :func:`_forward`'s signature (float64 C arrays, a float64 step) on a tiny plan."""
    n = 4
    return (np.zeros(n), np.zeros(n), np.ones(8), 1e-3, np.zeros(4), *(np.zeros(n) for _ in range(5)))


def _warm_adjoint() -> tuple[object, ...]:
    """A call of :func:`_adjoint`'s signature."""
    n = 4
    return (np.zeros(n), np.zeros(n), np.ones(8), 1e-3, *(np.zeros(n) for _ in range(6)))


# the plan is made in the loop process before its first deadline: its kernels warm with the loop's
@loop_kernel(_warm_forward)
@jit
def _forward(u, w, m, h, x0, thetas, vs, zs, coil, accel):
    """Step the model ``m`` (k/J, 1/J, c1, c2, f1, f2, ε, ρ) from ``x0`` (θ, θ̇2, z, i; z unused)
    under the commands ``u``: the states before each step into ``thetas``, ``vs``, ``zs`` (0),
    ``coil``, θ̈2 into ``accel``; return the mean of accel²."""
    k_over_j, inv_j, c1, c2, f1, f2, eps, rho = m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7]
    theta = x0[0]
    v = x0[1]
    i = x0[3]
    total = 0.0
    n = u.size
    for k in range(n):
        thetas[k] = theta
        vs[k] = v
        zs[k] = 0.0
        coil[k] = i
        r = v - w[k]
        torque = (c1 + c2 * i) * r + (f1 + f2 * i) * math.tanh(r / eps)
        a = -k_over_j * theta - inv_j * torque
        accel[k] = a
        total += a * a
        v = v + h * a
        theta = theta + h * (v - w[k])
        i = i + rho * (u[k] - i)
    return total / n


@loop_kernel(_warm_adjoint)
@jit
def _adjoint(u, w, m, h, thetas, vs, zs, coil, direct, grad):
    """The discrete adjoint of a cost of the θ̈2 of :func:`_forward`: d(cost)/d(u_k) into ``grad``,
    given ``direct``, d(cost)/d(a_k) holding the later states fixed (2·a_k/n for the mean of a²)."""
    k_over_j, inv_j, c1, c2, f1, f2, eps, rho = m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7]
    n = u.size
    lam_theta = 0.0
    lam_v = 0.0
    lam_i = 0.0
    for k in range(n - 1, -1, -1):
        i = coil[k]
        r = vs[k] - w[k]
        s = math.tanh(r / eps)
        f = f1 + f2 * i
        d_rate = c1 + c2 * i + f * (1.0 - s * s) / eps  # dT/dθ̇
        d_current = c2 * r + f2 * s  # dT/di
        g_a = direct[k] + h * (lam_v + h * lam_theta)
        grad[k] = rho * lam_i  # u_k sets i_{k+1}
        lam_i = -g_a * inv_j * d_current + (1.0 - rho) * lam_i
        new_theta = -g_a * k_over_j + lam_theta
        lam_v = -g_a * inv_j * d_rate + lam_v + h * lam_theta
        lam_theta = new_theta
    return 0


@dataclass(frozen=True)
class PlanModel:
    """The plan's model: k/J, 1/J, the damping c1 + c2·i, the friction (f1 + f2·i)·tanh(θ̇/ε) and
    the coil's step ρ = 1 − exp(−h/τ) per cycle (1: no lag)."""

    k_over_j: float
    inv_j: float
    c1: float
    c2: float
    f1: float
    f2: float
    eps: float
    rho: float = 1.0

    @classmethod
    def of(
        cls, params: BoucWenParams, hysteresis: bool = True, eps: float = 0.01, coil_tau_s: float = 0.0, h: float = 1e-3
    ) -> PlanModel:
        """The plan's model of ``params``; ``hysteresis``: the friction α(i)·z_u, else the viscous
        envelope; ``coil_tau_s``: the coil's lag (0: none) at the step ``h``."""
        z_u = params.z_bound if hysteresis else 0.0
        rho = 1.0 - math.exp(-h / coil_tau_s) if coil_tau_s > 0.0 else 1.0
        return cls(
            params.k / params.J,
            1.0 / params.J,
            params.c1,
            params.c2,
            params.alpha1 * z_u,
            params.alpha2 * z_u,
            eps,
            rho,
        )

    @property
    def authority(self) -> bool:
        """Whether the current moves the torque at all (c2 or f2 non-zero)."""
        return self.c2 != 0.0 or self.f2 != 0.0

    def vector(self) -> np.ndarray:
        """The kernels' parameters: k/J, 1/J, c1, c2, f1, f2, ε, ρ."""
        return np.array([self.k_over_j, self.inv_j, self.c1, self.c2, self.f1, self.f2, self.eps, self.rho])

    #: the model's step and its adjoint (the kernels above)
    forward = staticmethod(_forward)
    adjoint = staticmethod(_adjoint)


class Model(Protocol):
    """A plan's model: :class:`PlanModel` (the hysteresis as a friction, or none) or
    :class:`sashil.control.plan_boucwen.BoucWenPlanModel` (the Bouc-Wen state itself). Its kernels
    step the state (θ, θ̇2, z, i) and take the adjoint of a cost of θ̈2 with one signature."""

    @property
    def authority(self) -> bool: ...

    def vector(self) -> np.ndarray: ...

    #: ``forward(u, w, m, h, x0, thetas, vs, zs, coil, accel)``: step from ``x0`` (θ, θ̇2, z, i)
    #: under ``u`` on ``w``, the states before each step and θ̈2 into the five arrays; the mean of θ̈2²
    forward: Callable[..., float]
    #: ``adjoint(u, w, m, h, thetas, vs, zs, coil, direct, grad)``: d(cost)/d(u_k) into ``grad``
    #: from the trajectory and d(cost)/d(a_k) (``direct``)
    adjoint: Callable[..., int]


#: the state a plan starts from: the arm at rest, z and the coil at 0
REST = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CurrentPlan:
    """The planned command u_k [A] of every cycle, and the model's state under it before each cycle:
    the coil's current i_k [A], the relative angle θ_k [rad], the arm's rate θ̇2_k [rad/s], the
    Bouc-Wen state z_k (0 in a model without it), its acceleration θ̈2_k [rad/s²]."""

    command_a: np.ndarray
    current_a: np.ndarray
    theta_rad: np.ndarray
    body_dot_rad_s: np.ndarray
    accel_rad_s2: np.ndarray
    z: np.ndarray

    @property
    def rms_accel(self) -> float:
        return float(np.sqrt(np.mean(self.accel_rad_s2**2))) if self.accel_rad_s2.size else 0.0


def simulate_plan(
    model: Model,
    command_a: np.ndarray,
    road_rate: np.ndarray,
    h: float,
    x0: tuple[float, float, float, float] = REST,
) -> CurrentPlan:
    """The model's trajectory under the commands ``command_a`` on ``road_rate`` from ``x0`` (θ, θ̇2, z, i)."""
    n = command_a.size
    thetas, vs, zs, coil, accel = (np.empty(n) for _ in range(5))
    u = np.ascontiguousarray(command_a, dtype=float)
    w = np.ascontiguousarray(road_rate[:n], dtype=float)
    model.forward(u, w, model.vector(), h, np.asarray(x0, dtype=float), thetas, vs, zs, coil, accel)
    return CurrentPlan(u, coil, thetas, vs, accel, zs)


def comfort_filter(bandwidth_hz: float | None, h: float) -> np.ndarray | None:
    """The low-pass of the comfort metric (4th-order Butterworth at ``bandwidth_hz``, second-order
    sections), None for none (``bandwidth_hz`` None or 0, or at or above 0.45 of the rate)."""
    from scipy.signal import butter

    if not bandwidth_hz or bandwidth_hz >= 0.45 / h:
        return None
    return np.asarray(butter(4, bandwidth_hz, fs=1.0 / h, output="sos"))


def lowpass(x: np.ndarray, sos: np.ndarray | None) -> np.ndarray:
    """``x`` filtered forward and back from rest (zero phase): R·H·R·H x, with H the causal filter
    and R the reversal. As a matrix it is its own transpose (Hᵀ = R·H·R), so the gradient of
    mean((F a)²) is 2·F(F a)/n."""
    if sos is None:
        return x
    from scipy.signal import sosfilt

    once = np.asarray(sosfilt(sos, x))
    return np.asarray(sosfilt(sos, once[::-1]))[::-1].copy()


def _plan_block(
    model: Model,
    i_max: float,
    w: np.ndarray,
    h: float,
    x0: tuple[float, float, float, float],
    max_iterations: int,
    sos: np.ndarray | None = None,
    initial: np.ndarray | None = None,
    from_constant: bool = True,
) -> np.ndarray:
    """The commands of one block of road speeds ``w`` from the state ``x0``: the best of L-BFGS-B
    from the best constant current (``from_constant``) and from ``initial``; the cost the mean of
    θ̈2² low-passed by ``sos`` (:func:`lowpass`; None: unfiltered)."""
    from scipy.optimize import minimize, minimize_scalar

    n = w.size
    m = model.vector()
    start = np.asarray(x0, dtype=float)
    bufs = [np.empty(n) for _ in range(5)]
    grad = np.empty(n)

    def cost(u: np.ndarray) -> tuple[float, np.ndarray]:
        model.forward(u, w, m, h, start, *bufs)
        filtered = lowpass(bufs[4], sos)
        model.adjoint(u, w, m, h, *bufs[:4], (2.0 / n) * lowpass(filtered, sos), grad)
        return float(np.mean(filtered * filtered)), grad.copy()

    starts = [] if initial is None else [np.clip(np.asarray(initial[:n], dtype=float), 0.0, i_max)]
    if from_constant or not starts:
        best = minimize_scalar(
            lambda i: cost(np.full(n, i))[0], bounds=(0.0, i_max), method="bounded", options={"xatol": 1e-3 * i_max}
        )
        starts.append(np.full(n, float(best.x)))
    options = {"maxiter": max_iterations, "maxfun": 2 * max_iterations}
    found = [
        minimize(cost, u0, jac=True, method="L-BFGS-B", bounds=[(0.0, i_max)] * n, options=options) for u0 in starts
    ]
    return np.clip(np.asarray(min(found, key=lambda r: float(r.fun)).x, dtype=float), 0.0, i_max)


@dataclass(frozen=True)
class Horizon:
    """How a road is planned: blocks of ``block_s`` [s], each optimised over ``tail_s`` [s] of road
    after it too, by at most ``max_iterations`` of L-BFGS-B; the cost on θ̈2 low-passed at
    ``bandwidth_hz`` as ``sashil compare`` measures comfort (None: unfiltered)."""

    block_s: float = 10.0
    tail_s: float = 2.0
    max_iterations: int = 400
    bandwidth_hz: float | None = None


def plan_current(
    model: Model,
    current_max_a: float,
    road_rate: np.ndarray,
    h: float,
    horizon: Horizon = Horizon(),
    initial: np.ndarray | None = None,
    from_constant: bool = True,
) -> CurrentPlan:
    """The receding-horizon plan of the module docstring for the road speeds ``road_rate`` (one per
    cycle of ``h``), from rest, over ``horizon``; ``initial``: a plan of the whole road each block
    also starts from (with ``from_constant`` false, the only start)."""
    block_s, tail_s, max_iterations = horizon.block_s, horizon.tail_s, horizon.max_iterations
    sos = comfort_filter(horizon.bandwidth_hz, h)
    n = road_rate.size
    w_all = np.ascontiguousarray(road_rate, dtype=float)
    plan = np.zeros(n)
    if not (current_max_a > 0.0 and model.authority) or n == 0:  # no authority: passive
        return simulate_plan(model, plan, w_all, h)
    block, tail = max(1, int(round(block_s / h))), max(0, int(round(tail_s / h)))
    x0 = REST
    for start in range(0, n, block):
        stop = min(n, start + block)
        end = min(n, stop + tail)
        guess = None if initial is None else initial[start:end]
        u = _plan_block(model, current_max_a, w_all[start:end], h, x0, max_iterations, sos, guess, from_constant)
        plan[start:stop] = u[: stop - start]
        if stop < n:  # the state the kept block ends at: where the next block starts
            seg = simulate_plan(model, plan[start : stop + 1], w_all[start : stop + 1], h, x0)
            x0 = (float(seg.theta_rad[-1]), float(seg.body_dot_rad_s[-1]), float(seg.z[-1]), float(seg.current_a[-1]))
    return simulate_plan(model, plan, w_all, h)

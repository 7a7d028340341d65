"""The preview plan's model of the rig with its Bouc-Wen state: the rig the simulated plant runs,
stepped at the loop's period, and the exact gradient of a plan's cost through it.

Seed 001 eqs. 9-17: J θ̈2 = −k θ − T, T = α(i)·z + c(i)·θ̇ (eq. 9), c(i) = c1 + c2·i,
α(i) = α1 + α2·i (eqs. 11-12), θ = θ2 − θ1, and z advanced over each step's angle increment Δθ
by :func:`sashil.models.hysteresis.advance_z` (eq. 17 in the angle: along the travel u = |Δθ|,
ζ = sign(Δθ)·z obeys dζ/du = φ(ζ), φ(ζ) = δ − |ζ|ⁿ·(β + γ·sign ζ)). The coil lags its command
u_k by τ: i_{k+1} = i_k + ρ·(u_k − i_k), ρ = 1 − exp(−h/τ). Semi-implicit Euler on the commanded
road speed w_k: a_k = −(k/J)·θ_k − T_k/J, v_{k+1} = v_k + h·a_k, Δθ_k = h·(v_{k+1} − w_k),
θ_{k+1} = θ_k + Δθ_k, z_{k+1} = Z(z_k, Δθ_k).

At small travel the damper is not a friction: z turns over 2·z_u/δ of travel and then approaches
its bound over z_u/(n·δ), so below that it is a spring of stiffness α(i)·δ (on the n = 1 dampers
z_u/δ ≈ 10⁻³ rad; with δ = 1500 at n ≈ 0.1, z_u ≈ 230 and the damper never leaves that spring).
A model that takes z at its bound promises what the rig cannot give there; this one is the rig's.

The gradient is the discrete adjoint of :mod:`sashil.control.preview_plan` with z as a fourth
state. Z is the flow of an autonomous scalar equation, so its derivatives need no sensitivity
equation: ∂Z/∂Δθ = φ(ζ_{k+1}) and ∂Z/∂z = φ(ζ_{k+1})/φ(ζ_k) (ζ taken with the sign of Δθ), and at
the bound, where φ = 0, ∂Z/∂z = exp(−n·δ·|Δθ|/z_u), the linearised approach (Hairer, Nørsett &
Wanner 1993, ch. I.14, the derivative of a flow with respect to its initial value). These are the
exact flow's derivatives, not those of ``advance_z``'s Runge-Kutta sub-steps: where z crosses 0
with n ≈ 0.1 (|ζ|ⁿ steep there) the cost's gradient is within a few per cent of its finite
differences, which L-BFGS-B's line search absorbs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sashil.models._jit import jit, loop_kernel
from sashil.models.hysteresis import BoucWenParams, advance_z

__all__ = ["BoucWenPlanModel"]


def _warm_forward() -> tuple[object, ...]:
    n = 4
    m = np.array([109.0, 1.0, 0.7, 1.5, 1.0, 1.0, 0.1, 873.0, 1.0, 700.0, 0.099, 0.1])
    return (np.zeros(n), np.zeros(n), m, 1e-3, np.zeros(4), *(np.zeros(n) for _ in range(5)))


def _warm_adjoint() -> tuple[object, ...]:
    n = 4
    m = np.array([109.0, 1.0, 0.7, 1.5, 1.0, 1.0, 0.1, 873.0, 1.0, 700.0, 0.099, 0.1])
    return (np.zeros(n), np.zeros(n), m, 1e-3, *(np.zeros(n) for _ in range(6)))


@loop_kernel(lambda: (0.05, 873.0, 1.0, 700.0, 0.099))
@jit
def _slope(zeta, beta, gamma, delta, n):
    """φ(ζ) = δ − |ζ|ⁿ·(β + γ·sign ζ), dζ/du along the travel (module docstring)."""
    if zeta == 0.0:
        return delta
    return delta - abs(zeta) ** n * (beta + (gamma if zeta > 0.0 else -gamma))


# the plan is made in the loop process before its first deadline: its kernels warm with the loop's
@loop_kernel(_warm_forward)
@jit
def _forward(u, w, m, h, x0, thetas, vs, zs, coil, accel):
    """Step the model ``m`` (:meth:`BoucWenPlanModel.vector`) from ``x0`` (θ, θ̇2, z, i) under the
    commands ``u`` on the road speeds ``w``: the states before each step into ``thetas``, ``vs``,
    ``zs``, ``coil``, θ̈2 into ``accel``; return the mean of accel²."""
    k_over_j, inv_j, c1, c2, a1, a2, rho = m[0], m[1], m[2], m[3], m[4], m[5], m[6]
    beta, gamma, delta, n_exp, z_u = m[7], m[8], m[9], m[10], m[11]
    theta, v, z, i = x0[0], x0[1], x0[2], x0[3]
    total = 0.0
    for k in range(u.size):
        thetas[k] = theta
        vs[k] = v
        zs[k] = z
        coil[k] = i
        a = -k_over_j * theta - inv_j * ((c1 + c2 * i) * (v - w[k]) + (a1 + a2 * i) * z)
        accel[k] = a
        total += a * a
        v = v + h * a
        step = h * (v - w[k])
        theta = theta + step
        z = advance_z(z, step, beta, gamma, delta, n_exp, z_u)
        i = i + rho * (u[k] - i)
    return total / u.size


@loop_kernel(_warm_adjoint)
@jit
def _adjoint(u, w, m, h, thetas, vs, zs, coil, direct, grad):
    """d(cost)/d(u_k) into ``grad`` for a cost of the θ̈2 of :func:`_forward`, given ``direct``,
    d(cost)/d(a_k) holding the later states fixed (module docstring)."""
    k_over_j, inv_j, c1, c2, a1, a2, rho = m[0], m[1], m[2], m[3], m[4], m[5], m[6]
    beta, gamma, delta, n_exp, z_u = m[7], m[8], m[9], m[10], m[11]
    last = u.size - 1
    lam_theta = 0.0
    lam_v = 0.0
    lam_z = 0.0
    lam_i = 0.0
    for k in range(last, -1, -1):
        i, z, r = coil[k], zs[k], vs[k] - w[k]
        if k < last:
            step, z_next = thetas[k + 1] - thetas[k], zs[k + 1]
        else:  # the last step's end is not stored: take it again
            a = -k_over_j * thetas[k] - inv_j * ((c1 + c2 * i) * r + (a1 + a2 * i) * z)
            step = h * (vs[k] + h * a - w[k])
            z_next = advance_z(z, step, beta, gamma, delta, n_exp, z_u)
        s = 1.0 if step >= 0.0 else -1.0
        after = _slope(s * z_next, beta, gamma, delta, n_exp)
        before = _slope(s * z, beta, gamma, delta, n_exp)
        dz_dz = after / before if before > 1e-12 * delta else math.exp(-(n_exp * delta / z_u) * abs(step))
        lam_step = lam_theta + lam_z * after  # d(cost)/d(Δθ_k)
        g_a = direct[k] + h * (lam_v + h * lam_step)
        grad[k] = rho * lam_i  # u_k sets i_{k+1}
        lam_i = -g_a * inv_j * (c2 * r + a2 * z) + (1.0 - rho) * lam_i
        new_theta = -g_a * k_over_j + lam_theta
        new_v = -g_a * inv_j * (c1 + c2 * i) + lam_v + h * lam_step
        lam_z = -g_a * inv_j * (a1 + a2 * i) + lam_z * dz_dz
        lam_theta, lam_v = new_theta, new_v
    return 0


@dataclass(frozen=True)
class BoucWenPlanModel:
    """The rig's parameters (:class:`BoucWenParams`) and the coil's step ρ = 1 − exp(−h/τ) (1: no lag)."""

    params: BoucWenParams
    rho: float = 1.0

    @classmethod
    def of(cls, params: BoucWenParams, coil_tau_s: float = 0.0, h: float = 1e-3) -> BoucWenPlanModel:
        return cls(params, 1.0 - math.exp(-h / coil_tau_s) if coil_tau_s > 0.0 else 1.0)

    @property
    def authority(self) -> bool:
        """Whether the current moves the torque at all (c2 or α2 non-zero)."""
        return self.params.c2 != 0.0 or self.params.alpha2 != 0.0

    def vector(self) -> np.ndarray:
        """The kernels' parameters: k/J, 1/J, c1, c2, α1, α2, ρ, β, γ, δ, n, z_u."""
        p = self.params
        return np.array(
            [p.k / p.J, 1.0 / p.J, p.c1, p.c2, p.alpha1, p.alpha2, self.rho, p.beta, p.gamma, p.delta, p.n, p.z_bound]
        )

    #: the model's step and its adjoint (the kernels above)
    forward = staticmethod(_forward)
    adjoint = staticmethod(_adjoint)

"""Bouc-Wen hysteresis of the rotary MR damper, with current-dependent alpha(i), c(i).

Seed 001 (Iskandarani & Karimi 2011), eqs. 9-12 and 15-17::

    T     = alpha(i) * z + c(i) * theta_dot                                  (eq. 9)
    c(i)  = c1 + c2 * i,   alpha(i) = alpha1 + alpha2 * i                    (eqs. 11-12, 15-16)
    z_dot = -gamma*|theta_dot|*z*|z|^(n-1) - beta*theta_dot*|z|^n + delta*theta_dot   (eq. 17)

The seed prints ``z|z|^n`` in the first term; we use the standard ``z|z|^(n-1) = sign(z)|z|^n``.

Numerics (docs/architecture.md, the model). The law is rate-independent: dividing
eq. 17 by theta_dot gives an ODE in the angle,

    dz/dtheta = delta - |z|^n * (beta + gamma * sign(dtheta) * sign(z)),

and with ``s = sign(dtheta)``, ``zeta = s*z`` and the travel ``u = |dtheta|`` both directions of
motion become one autonomous scalar ODE

    dzeta/du = phi(zeta) = delta - |zeta|^n * (beta + gamma * sign(zeta)),

whose stable equilibrium is the analytic bound ``z_u = (delta / (beta + gamma))^(1/n)``. From any
``|z| <= z_u`` the exact solution moves monotonically towards ``s*z_u`` and never crosses it. We
integrate it over each sample's angle increment (:func:`advance_z`) with classical Runge-Kutta in
the angle, sub-stepped so that z changes by at most z_u/16 and the local stiffness |dphi/dzeta|*h
stays below 1/2, stages clamped to the bound, and the exact solution of the linearised approach
near the bound. The result is finite and inside the bound for every increment and step size;
``|z|**(n-1)`` is never evaluated at 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from sashil.errors import ConfigError
from sashil.models._jit import jit, loop_kernel
from sashil.models.seed import BOUC_WEN_SEED

#: a float, or an array of them (the laws apply element-wise)
Value = TypeVar("Value", float, np.ndarray)


@dataclass(frozen=True)
class BoucWenParams:
    """Parameters of the Bouc-Wen rig model (docs/architecture.md names; seed 001 section 8 values)."""

    J: float = BOUC_WEN_SEED["J"]
    k: float = BOUC_WEN_SEED["k"]
    c1: float = BOUC_WEN_SEED["c1"]
    c2: float = BOUC_WEN_SEED["c2"]
    alpha1: float = BOUC_WEN_SEED["alpha1"]
    alpha2: float = BOUC_WEN_SEED["alpha2"]
    beta: float = BOUC_WEN_SEED["beta"]
    gamma: float = BOUC_WEN_SEED["gamma"]
    delta: float = BOUC_WEN_SEED["delta"]
    n: float = BOUC_WEN_SEED["n"]

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> BoucWenParams:
        """Build from a ``params`` mapping (config ``model.params`` or a parameter file)."""
        return cls(**{key: float(params[key]) for key in cls.__dataclass_fields__ if key in params})

    def as_dict(self) -> dict[str, float]:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}

    @property
    def z_bound(self) -> float:
        """Analytic bound of |z| for a record starting at |z| <= it: (delta/(beta+gamma))^(1/n)."""
        return (self.delta / (self.beta + self.gamma)) ** (1.0 / self.n)

    def damping(self, current_a: float) -> float:
        """c(i) = c1 + c2*i (seed 001 eq. 11)."""
        return self.c1 + self.c2 * current_a

    def hysteretic_gain(self, current_a: float) -> float:
        """alpha(i) = alpha1 + alpha2*i (seed 001 eq. 12)."""
        return self.alpha1 + self.alpha2 * current_a

    def torque(self, z: Value, theta_dot: Value, current_a: float) -> Value:
        """Damper torque T = alpha(i)*z + c(i)*theta_dot (seed 001 eq. 9)."""
        at_zero, per_ampere = self.torque_line(z, theta_dot)
        return at_zero + per_ampere * current_a

    def torque_line(self, z: Value, theta_dot: Value) -> tuple[Value, Value]:
        """Eq. 9 as the line in the current it is: T(i) = T(0) + D*i, returns (T(0), D).

        T(0) = alpha1*z + c1*theta_dot, D = dT/di = alpha2*z + c2*theta_dot (eqs. 9, 11-12); the
        inverse hysteresis solves this line for i, the feasible band is [T(0), T(i_max)].
        """
        return self.alpha1 * z + self.c1 * theta_dot, self.alpha2 * z + self.c2 * theta_dot


def rig_params(model_section: Mapping[str, Any]) -> BoucWenParams:
    """The Bouc-Wen parameters the simulated rig runs on (only Bouc-Wen drives the rig plant)."""
    if model_section.get("name", "bouc-wen") != "bouc-wen":
        raise ConfigError(f"model.name: the simulated rig runs the bouc-wen model, got {model_section['name']!r}")
    return BoucWenParams.from_mapping(model_section["params"])


@loop_kernel(lambda: (0.0, 1e-4, 1.0, 1.0, 2.0, 1.0, 1.0))
@jit
def advance_z(z: float, dtheta: float, beta: float, gamma: float, delta: float, n: float, z_u: float) -> float:
    """z after the arm turns by ``dtheta`` from ``z`` (seed 001 eq. 17 integrated in the angle).

    ``z_u = (delta/(beta+gamma))^(1/n)``. Classical Runge-Kutta in the travel u = |dtheta| on
    dzeta/du = phi(zeta) (module docstring), with sub-steps sized so that zeta changes by at most
    z_u/16 and |dphi/dzeta|*h <= 1/2 (floored at a change of 1e-4 z_u), stages clamped to the
    bound, and the exact solution of the linearised approach once within 1e-6 z_u of it. A plain
    function of floats: numba compiles it for the plant, the observer and identification.
    """
    if dtheta == 0.0 or dtheta != dtheta:
        return z
    s = 1.0 if dtheta > 0.0 else -1.0
    zeta = s * z
    if zeta > z_u:
        zeta = z_u
    elif zeta < -z_u:
        zeta = -z_u
    travel = abs(dtheta)
    dz_max = z_u / 16.0
    dz_min = z_u * 1e-4
    tail = z_u * 1e-6
    tol = z_u * 1e-9  # closer than this to the bound is the bound
    while travel > 0.0 and zeta < z_u:
        gap = z_u - zeta
        if gap <= tail:
            # linearised exact solution of the last approach: gap' = -n*delta/z_u * gap
            gap *= math.exp(-(n * delta / z_u) * travel)
            zeta = z_u - gap if gap > tol else z_u
            break
        a = abs(zeta)
        if a == 0.0:
            phi = delta
            stiff = math.inf
        else:
            c = beta + (gamma if zeta > 0.0 else -gamma)
            p = a**n
            phi = delta - p * c
            stiff = n * p * abs(c) / a  # |dphi/dzeta|
        if phi <= 0.0:
            break  # at -z_u with gamma <= 0: an equilibrium of the exact solution
        h = dz_max / phi
        # n > 1: |z|^n underflows to 0 for tiny |z|, so the stiffness is 0 there (no limit)
        limit = 0.5 / stiff if stiff > 0.0 else h
        if limit < h:
            h = max(limit, dz_min / phi)
        if h > travel:
            h = travel
        k1 = phi
        x = zeta + 0.5 * h * k1
        x = x if x < z_u else z_u
        k2 = delta if x == 0.0 else delta - abs(x) ** n * (beta + (gamma if x > 0.0 else -gamma))
        x = zeta + 0.5 * h * k2
        x = x if x < z_u else z_u
        k3 = delta if x == 0.0 else delta - abs(x) ** n * (beta + (gamma if x > 0.0 else -gamma))
        x = zeta + h * k3
        x = x if x < z_u else z_u
        k4 = delta if x == 0.0 else delta - abs(x) ** n * (beta + (gamma if x > 0.0 else -gamma))
        new = zeta + h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        zeta = new if new < z_u else z_u
        travel -= h
    return s * zeta


class BoucWenZ:
    """The hysteretic state update z(theta) of seed 001 eq. 17, integrated over angle increments.

    ``advance(z, dtheta)`` is the real-time step (plain Python floats, no allocation);
    ``trajectory(theta, z0)`` is the batch path over a whole record.
    """

    __slots__ = ("beta", "delta", "gamma", "n", "z_u")

    def __init__(self, beta: float, gamma: float, delta: float, n: float):
        if not (delta > 0.0 and n > 0.0 and beta + gamma > 0.0):
            raise ValueError(
                f"Bouc-Wen needs delta > 0, n > 0 and beta + gamma > 0 (got delta={delta}, n={n}, "
                f"beta+gamma={beta + gamma})"
            )
        self.beta = float(beta)
        self.gamma = float(gamma)
        self.delta = float(delta)
        self.n = float(n)
        self.z_u = (self.delta / (self.beta + self.gamma)) ** (1.0 / self.n)

    @classmethod
    def from_params(cls, params: BoucWenParams) -> BoucWenZ:
        return cls(params.beta, params.gamma, params.delta, params.n)

    def advance(self, z: float, dtheta: float) -> float:
        """z after the arm turns by ``dtheta`` [rad] from state ``z`` (any size, either sign)."""
        return advance_z(float(z), float(dtheta), self.beta, self.gamma, self.delta, self.n, self.z_u)

    def trajectory(self, theta: np.ndarray, z0: float = 0.0) -> np.ndarray:
        """Batch path: z at every sample of an angle record ``theta`` [rad], starting from ``z0``."""
        theta = np.asarray(theta, dtype=float)
        out = np.empty_like(theta)
        z = float(z0)
        previous = float(theta[0]) if theta.size else 0.0
        advance = self.advance
        for index, angle in enumerate(theta.tolist()):
            z = advance(z, angle - previous)
            previous = angle
            out[index] = z
        return out

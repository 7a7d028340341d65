"""LuGre model of the MR damper (seed 001 eqs. 7-8, current i in place of the voltage v).

    T     = sigma_a*z + sigma0*z*i + sigma1*z_dot + sigma2*theta_dot + sigma_b*theta_dot*i   (eq. 7)
    z_dot = theta_dot - sigma0*a0*|theta_dot|*z                                           (eq. 8)

With r = sigma0*a0 the internal state obeys dz/dtheta = 1 - r*sign(dtheta)*z, solved exactly over an
angle increment: ``z' = s/r + (z - s/r)*exp(-r*|dtheta|)``; |z| <= 1/r. Only r (not sigma0 and a0
apart) shapes z, so identification searches r and solves the torque coefficients linearly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sashil.models.seed import SEED_J, SEED_K


@dataclass(frozen=True)
class LuGreParams:
    """LuGre rig-model parameters (registry symbols J, k, sigma_a, sigma_b, sigma0, sigma1, sigma2, a0)."""

    J: float = SEED_J
    k: float = SEED_K
    sigma_a: float = 10.0
    sigma_b: float = 1.5
    sigma0: float = 10.0
    sigma1: float = 0.01
    sigma2: float = 0.7
    a0: float = 10.0

    @property
    def r(self) -> float:
        return self.sigma0 * self.a0

    def z_dot(self, z: float, theta_dot: float) -> float:
        """Seed 001 eq. 8."""
        return theta_dot - self.r * abs(theta_dot) * z

    def torque(self, z: float, theta_dot: float, current_a: float) -> float:
        """Seed 001 eq. 7."""
        return (
            self.sigma_a * z
            + self.sigma0 * z * current_a
            + self.sigma1 * self.z_dot(z, theta_dot)
            + self.sigma2 * theta_dot
            + self.sigma_b * theta_dot * current_a
        )


def lugre_z_advance(z: float, dtheta: float, r: float) -> float:
    """Exact LuGre state after an angle increment (seed 001 eq. 8 in the angle), r = sigma0*a0 > 0."""
    if dtheta == 0.0:
        return z
    s = 1.0 if dtheta > 0.0 else -1.0
    target = s / r
    return target + (z - target) * math.exp(-r * abs(dtheta))

"""Bingham model of the MR damper (seed 001 eq. 4), with current-dependent coefficients.

    T = fc(i)*sign(theta_dot) + c0(i)*theta_dot + f0,     fc(i) = fc + fc_i*i,  c0(i) = c0 + c0_i*i

In a simulation the Coulomb term is set-valued at theta_dot = 0 (the arm sticks while the other
torques stay within +-fc(i)); :func:`bingham_velocity_step` takes one implicit (Moreau) velocity
step that sticks or slips exactly, instead of a smoothed sign.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sashil.models.seed import SEED_J, SEED_K


@dataclass(frozen=True)
class BinghamParams:
    """Bingham rig-model parameters (registry symbols J, k, c0, c0_i, fc, fc_i, f0)."""

    J: float = SEED_J
    k: float = SEED_K
    c0: float = 0.7
    c0_i: float = 1.5
    fc: float = 0.1
    fc_i: float = 0.1
    f0: float = 0.0

    def torque(self, theta_dot: float, current_a: float) -> float:
        """Seed 001 eq. 4."""
        sgn = 0.0 if theta_dot == 0.0 else math.copysign(1.0, theta_dot)
        return (self.fc + self.fc_i * current_a) * sgn + (self.c0 + self.c0_i * current_a) * theta_dot + self.f0


def bingham_velocity_step(v: float, h: float, other_torque: float, J: float, c: float, fc: float) -> float:
    """Velocity after a step h of ``J*v' = other_torque - c*v - fc*sign(v)``, implicit in c and fc.

    Stick (v' = 0) when the free step cannot overcome the friction torque fc >= 0, else slip with
    the friction impulse opposing the new velocity (a Moreau time-stepping step).
    """
    denom = 1.0 + h * c / J
    free = (v + h * other_torque / J) / denom
    slip = h * fc / J / denom
    if abs(free) <= slip:
        return 0.0
    return free - slip if free > 0.0 else free + slip

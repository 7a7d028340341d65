"""Dahl model of the rotary MR damper (seed 001 eqs. 5-6 and 18-20, current in place of voltage).

    T_mr  = c(i)*theta_dot + (kwa + kwb*i) * w                         (eqs. 6, 18; c(i) = kx + c2*i)
    w_dot = rho * (theta_dot - |theta_dot| * w)                         (eqs. 5, 20)

The seed's viscous term ``kx*theta_dot`` is ``c1`` here; ``c2`` adds the current-dependent damping
the seed's conclusion asks for (set c2 = 0 for the seed's exact model). Like Bouc-Wen the Dahl law
is rate-independent: dw/dtheta = rho*(1 - sign(dtheta)*w), solved exactly over an angle increment
by ``w' = s + (w - s)*exp(-rho*|dtheta|)`` (s = sign(dtheta)); |w| <= 1 is kept for |w0| <= 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sashil.models.seed import SEED_J, SEED_K


@dataclass(frozen=True)
class DahlParams:
    """Dahl rig-model parameters (registry symbols J, k, c1, c2, kwa, kwb, rho)."""

    J: float = SEED_J
    k: float = SEED_K
    c1: float = 0.15  # seed 'kx'
    c2: float = 0.0
    kwa: float = 0.6
    kwb: float = 2.8
    rho: float = 10.0

    def torque(self, w: float, theta_dot: float, current_a: float) -> float:
        """Damper torque (seed 001 eq. 18 without the spring term)."""
        return (self.c1 + self.c2 * current_a) * theta_dot + (self.kwa + self.kwb * current_a) * w


def dahl_w_advance(w: float, dtheta: float, rho: float) -> float:
    """Exact Dahl state after an angle increment ``dtheta`` (seed 001 eq. 20 in the angle)."""
    if dtheta == 0.0:
        return w
    s = 1.0 if dtheta > 0.0 else -1.0
    return s + (w - s) * math.exp(-rho * abs(dtheta))

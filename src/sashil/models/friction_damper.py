"""The lubricated friction damper of seed 000 (Ok, Yoo, Sohn et al., KSME/Springer 2010).

2-DOF model (eqs. 1-2), jig displacement Y imposed by the test machine, sponge displacement X:

    M*Y'' + c1*Y' + k1*Y = F + c1*X' + k1*X                               (eq. 1)
    m*X'' + (c1 + c2)*X' + k1*X = c1*Y' + k1*Y + F_fric                   (eq. 2)

so the measured force is F = M*Y'' + c1*(Y' - X') + k1*(Y - X). Friction laws:

* Coulomb (eq. 9): F_fric = -sgn(X')*F_max;
* STV / MSTV (eqs. 3-6, eps = 0.001): slip when |X'| >= |Y' - X'| (eq. 3-4), F_fric = -sgn(X')*F_max;
  otherwise the transient force F_fric = -X'/(|Y' - X'| + eps)*F_max (eqs. 5-6);
* Bouc-Wen (eq. 8): F_fric = -alpha*z, z' = A*X' - beta*|X'|*z*|z|^(n-1) - gamma*X'*|z|^n.
  (The seed writes F_fric = alpha*z; the minus sign makes it oppose the sponge motion like eq. 9.)
  In the displacement: dz/dX = A - |z|^n*(beta*sign(dX*z) + gamma), the rig law of
  :mod:`sashil.models.hysteresis` with (delta, beta, gamma) = (A, gamma, beta); bound (A/(beta+gamma))^(1/n).

Units as in the seed's tables: N, mm, s (k1 in N/mm, c in N s/mm, masses in N s^2/mm = 1000 kg).
The seed gives no masses: we take M = 0 (force measured at the damper) and m = 1e-3 N s^2/mm (1 kg).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Table 1: harmonic test plan, frequency [Hz] -> displacement amplitudes [mm]
TABLE1: dict[float, tuple[float, ...]] = {
    1.0: (0.3, 0.5, 1.0, 5.0, 10.0),
    3.0: (0.3, 0.5, 1.0, 3.0, 5.0),
    6.67: (0.3, 0.5, 1.0, 1.5),
    10.0: (0.3, 0.5, 1.0, 1.5),
}

COULOMB, MSTV, BOUC_WEN = 0, 1, 2
LAWS = {"coulomb": COULOMB, "mstv": MSTV, "bouc-wen": BOUC_WEN}


@dataclass(frozen=True)
class FrictionDamperParams:
    """Linear part (Table 2) and friction parameters (Table 2 F_max, Table 3 Bouc-Wen)."""

    M: float = 0.0
    m: float = 1e-3
    k1: float = 114.67
    c1: float = 0.53
    c2: float = 0.49
    f_max: float = 44.32
    A: float = 188.34
    alpha: float = 35.91
    beta: float = 38.93
    gamma: float = 29.36
    n: float = 3.51
    eps: float = 0.001

    @property
    def z_bound(self) -> float:
        return (self.A / (self.beta + self.gamma)) ** (1.0 / self.n)


def coulomb_friction(x_dot: float, f_max: float) -> float:
    """Eq. 9."""
    return 0.0 if x_dot == 0.0 else -math.copysign(f_max, x_dot)


def stv_slipping(x_dot: float, y_dot: float) -> bool:
    """Eqs. 3-4: pure slip (maximum friction) when |X'| >= |Y' - X'|, else stick-slip (transient)."""
    return abs(y_dot - x_dot) - abs(x_dot) <= 0.0


def mstv_friction(x_dot: float, y_dot: float, f_max: float, eps: float = 0.001) -> float:
    """Eqs. 5-6 (MSTV): maximum friction in slip, transient -X'/(|Y'-X'|+eps)*F_max otherwise."""
    if stv_slipping(x_dot, y_dot):
        return coulomb_friction(x_dot, f_max)
    return -x_dot / (abs(y_dot - x_dot) + eps) * f_max


def bouc_wen_friction_rate(z: float, x_dot: float, A: float, beta: float, gamma: float, n: float) -> float:
    """z' of eq. 8."""
    a = abs(z)
    return A * x_dot - beta * abs(x_dot) * math.copysign(a**n, z) - gamma * x_dot * a**n

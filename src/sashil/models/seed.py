"""The seed parameters of the rig model, written once (seed 001, Iskandarani & Karimi 2011, section 8).

Bouc-Wen rig model ``J*theta2_ddot = -k*theta - c(i)*theta_dot - alpha(i)*z + T_in`` (eqs. 9-17)
with J redundant (= 1). The config defaults, :class:`~sashil.models.hysteresis.BoucWenParams` and the
rig constants (J, k) of the comparison models read these; ``configs/sim.yaml`` restates them as a file
(a test keeps it equal to the built-in defaults). Plain floats: importing this module costs nothing.
"""

from __future__ import annotations

#: Bouc-Wen rig model: passive n, gamma, beta, delta, c1, alpha1, k; active c2, alpha2 (per ampere)
BOUC_WEN_SEED: dict[str, float] = {
    "J": 1.0,
    "k": 109.0,
    "c1": 0.7,
    "c2": 1.5,
    "alpha1": 1.0,
    "alpha2": 1.0,
    "beta": 873.0,
    "gamma": 1.0,
    "delta": 700.0,
    "n": 0.099,
}

#: the rig's inertia and spring (shared by every damper model)
SEED_J = BOUC_WEN_SEED["J"]
SEED_K = BOUC_WEN_SEED["k"]

"""The candidate damper models of the rig, as identification sees them.

Each :class:`RigModel` knows its parameter symbols (``sashil.models.registry.MODEL_PARAMS``), what
is fixed and why (normalisation), the search space of the few parameters that shape its internal
state (``nonlinear``), and the regressors that make the rig torque balance linear in the rest:

    J*(theta_ddot + theta1_ddot) - T_in = -(k*theta + T_damper)                (seed 001 eq. 13)

so that, once the internal state path is known, (k, c1, c2, alpha1, alpha2) and their analogues
come from one linear least-squares solve (variable projection).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sashil.identify import kernels
from sashil.identify.data import Record

# --- Bouc-Wen, normalised to a unit z bound ------------------------------------------------------
# dz/dtheta = delta - |z|^n (beta + gamma*sign(dtheta*z)) is unchanged by z -> kappa*z when
# (delta, beta, gamma, alpha) -> (kappa*delta, kappa^(1-n)*beta, kappa^(1-n)*gamma, alpha/kappa):
# the scale of z is not identifiable. We fix it by delta = beta + gamma (z bound = 1), so alpha(i)
# is the saturated hysteretic torque [N m]; search S = delta (pre-sliding slope of z, 1/rad),
# b = beta/S (gamma = S - beta) and n.
BW_NORMALISATION = (
    "z scaled to a unit bound (delta = beta + gamma, so |z| <= 1 and alpha(i) is the saturated "
    "hysteretic torque in N m); J fixed (only ratios to J are identifiable from angles)"
)


def bouc_wen_rescale(params: dict[str, float], z_bound: float = 1.0) -> dict[str, float]:
    """The same Bouc-Wen rig model with z rescaled so that its bound is ``z_bound``."""
    p = dict(params)
    zu = (p["delta"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"])
    kappa = z_bound / zu
    scale = kappa ** (1.0 - p["n"])
    p.update(
        delta=p["delta"] * kappa,
        beta=p["beta"] * scale,
        gamma=p["gamma"] * scale,
        alpha1=p["alpha1"] / kappa,
        alpha2=p["alpha2"] / kappa,
    )
    return p


@dataclass(frozen=True)
class RigModel:
    """One candidate model: symbols, fixed values, nonlinear search space, linear regressors."""

    name: str
    symbols: tuple[str, ...]
    linear: tuple[str, ...]  # torque coefficients solved linearly (current-dependent ones last)
    current_terms: tuple[str, ...]  # linear symbols that need a current change
    nonlinear: tuple[str, ...]  # search coordinates of the internal-state shape
    nl_bounds: tuple[tuple[float, float], ...]
    nl_start: tuple[float, ...]
    expand: Callable[[dict[str, float]], dict[str, float]]  # search coords -> model symbols
    regressors: Callable[[dict[str, float], np.ndarray, Record], tuple[np.ndarray, ...]]
    normalisation: str
    nl_log: tuple[bool, ...] = ()  # search coordinates the global grid spaces geometrically

    @property
    def code(self) -> int:
        return kernels.MODEL_CODES[self.name]

    def array(self, params: dict[str, float]) -> np.ndarray:
        return np.array([params[s] for s in self.symbols], dtype=float)

    def full_params(self, nl: dict[str, float], lin: dict[str, float], J: float) -> dict[str, float]:
        out = {"J": J, **lin, **self.expand(nl)}
        if "_r" in out:
            out = lugre_finish(out)
        return {s: float(out[s]) for s in self.symbols}

    def state_path(self, params: dict[str, float], record: Record) -> np.ndarray:
        p = self.array(params)
        if self.code == kernels.BINGHAM:
            return np.zeros_like(record.theta)
        bound = kernels.state_bound(self.code, p)
        return kernels.state_path(self.code, p, record.theta_smooth, record.initial_state_sign() * bound)

    def simulate(
        self, params: dict[str, float], record: Record, max_step: float = 1e-3, initial_offset_rad: float = 0.0
    ) -> np.ndarray:
        """Output-error simulation of a record: theta [rad] from theta0 at rest-or-moving start
        (theta0 the record's first sample plus ``initial_offset_rad``, where the fit estimated it)."""
        p = self.array(params)
        bound = kernels.state_bound(self.code, p) if self.code != kernels.BINGHAM else 0.0
        return kernels.simulate_rig(
            self.code,
            p,
            record.time_s,
            record.current,
            record.acc_road,
            record.torque_in,
            float(record.theta[0]) + initial_offset_rad,
            record.v0,
            record.initial_state_sign() * bound,
            max_step,
        )


def _bw_expand(nl: dict[str, float]) -> dict[str, float]:
    S = 10.0 ** nl["log10_S"]
    return {"beta": S * nl["b"], "gamma": S * (1.0 - nl["b"]), "delta": S, "n": nl["n"]}


def _bw_regressors(nl, state, rec):
    v, i = rec.theta_dot, rec.current
    return rec.theta, v, i * v, state, i * state


def _dahl_regressors(nl, state, rec):
    v, i = rec.theta_dot, rec.current
    return rec.theta, v, i * v, state, i * state


def _lugre_expand(nl: dict[str, float]) -> dict[str, float]:
    return {"_r": 10.0 ** nl["log10_r"]}


def _lugre_regressors(nl, state, rec):
    # T = sigma_a z + sigma0 i z + sigma1 (v - r|v|z) + sigma2 v + sigma_b v i (seed 001 eqs. 7-8).
    # Columns for (k, sigma_a, sigma1, sigma2, sigma0, sigma_b); sigma0 also multiplies i*z.
    v, i = rec.theta_dot, rec.current
    r = 10.0 ** nl["log10_r"]
    return rec.theta, state, v - r * np.abs(v) * state, v, i * state, i * v


def _bingham_regressors(nl, state, rec):
    v, i = rec.theta_dot, rec.current
    sgn = np.sign(v)
    return rec.theta, v, sgn, np.ones_like(v), i * v, i * sgn


MODELS: dict[str, RigModel] = {
    "bouc-wen": RigModel(
        "bouc-wen",
        ("J", "k", "c1", "c2", "alpha1", "alpha2", "beta", "gamma", "delta", "n"),
        ("k", "c1", "c2", "alpha1", "alpha2"),
        ("c2", "alpha2"),
        ("log10_S", "b", "n"),
        # n <= 2: the exponent of a real MR damper's Bouc-Wen fit is well below; above 1 the law
        # approaches its bound ever more slowly and drop tests cannot tell such values apart
        ((1.0, 6.0), (0.0, 2.0), (0.05, 2.0)),
        (3.0, 0.9, 0.5),
        _bw_expand,
        _bw_regressors,
        BW_NORMALISATION,
        (False, False, True),
    ),
    "dahl": RigModel(
        "dahl",
        ("J", "k", "c1", "c2", "kwa", "kwb", "rho"),
        ("k", "c1", "c2", "kwa", "kwb"),
        ("c2", "kwb"),
        ("log10_rho",),
        ((0.0, 6.0),),
        (2.0,),
        lambda nl: {"rho": 10.0 ** nl["log10_rho"]},
        _dahl_regressors,
        "|w| <= 1 by the Dahl law itself (kwa, kwb carry the torque scale); J fixed",
    ),
    "lugre": RigModel(
        "lugre",
        ("J", "k", "sigma_a", "sigma_b", "sigma0", "sigma1", "sigma2", "a0"),
        ("k", "sigma_a", "sigma1", "sigma2", "sigma0", "sigma_b"),
        ("sigma0", "sigma_b"),
        ("log10_r",),
        ((0.0, 6.0),),
        (2.0,),
        _lugre_expand,
        _lugre_regressors,
        "z shaped by r = sigma0*a0 only; a0 = r/sigma0 (sigma0 from the current-dependent stiffness); J fixed",
    ),
    "bingham": RigModel(
        "bingham",
        ("J", "k", "c0", "c0_i", "fc", "fc_i", "f0"),
        ("k", "c0", "fc", "f0", "c0_i", "fc_i"),
        ("c0_i", "fc_i"),
        (),
        (),
        (),
        lambda nl: {},
        _bingham_regressors,
        "no internal state; J fixed",
    ),
}


def lugre_finish(params: dict[str, float]) -> dict[str, float]:
    """Turn the search coordinate r into a0 = r / sigma0 (sigma0 kept > 0)."""
    p = dict(params)
    r = p.pop("_r")
    sigma0 = max(p["sigma0"], 1e-9)
    p["sigma0"] = sigma0
    p["a0"] = r / sigma0
    return p

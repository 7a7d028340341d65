"""Fitting a rig model to records: global stage, local output-error refinement, uncertainties.

Objective (seed 000 eq. 10, on the rig's measured output): the RMS of the simulated minus the
recorded angle theta over all samples of all runs (output error, a simulation from each run's own
initial angle, driven by its recorded current, road-side motion and input torque).

Stages (default, ``fit_model``):
1. global: differential evolution (the modern form of the seed's genetic algorithm) over the few
   parameters that shape the internal state; for each candidate the torque coefficients come from
   one linear least-squares solve of the torque balance on smoothed derivatives (variable
   projection, equation error) - milliseconds per candidate;
2. local: trust-region least squares (scipy ``least_squares``) on the output error over all free
   parameters, from the best global candidate.
``two_stage=True`` is the seed 000 procedure instead: the linear part (k, c1, c2) with Coulomb
friction first (output error), then the hysteresis parameters by differential evolution on the
output error with the linear part fixed, then the same local refinement of everything.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution, least_squares, lsq_linear

from sashil.identify.data import Record
from sashil.identify.progress import Progress
from sashil.identify.rig_models import MODELS, RigModel

#: parameters a linear solve keeps >= 0 (physical torques and damping); Bingham's offset f0 is free
FREE_SIGN = {"f0"}


@dataclass
class FitOptions:
    passive: bool = False  # fix the current-dependent terms at 0 (runs at one current)
    two_stage: bool = False
    J: float = 1.0
    popsize: int = 12
    maxiter: int = 30
    starts: int = 8  # distinct global candidates screened by their output error
    refine: int = 1  # local refinements from the best screened candidates
    seed: int = 0
    max_step: float = 1e-3
    progress: bool = False
    local: bool = True


@dataclass
class FitResult:
    model: str
    params: dict[str, float]
    stderr: dict[str, float]
    correlations: dict[str, dict[str, float]]
    flagged: list[tuple[str, str, float]]
    rms_rad: list[float]
    nrmse: list[float]
    record_names: list[str]
    wall_s: float
    evaluations: int
    fixed: dict[str, float]
    normalisation: str
    stages: list[str] = field(default_factory=list)

    @property
    def rms_total(self) -> float:
        return float(math.sqrt(np.mean(np.square(self.rms_rad))))

    @property
    def nrmse_mean(self) -> float:
        return float(np.mean(self.nrmse))


def nrmse(simulated: np.ndarray, measured: np.ndarray) -> float:
    """RMS error over the standard deviation of the measured angle."""
    return float(np.sqrt(np.mean((simulated - measured) ** 2)) / max(np.std(measured), 1e-15))


class Problem:
    """A model, its free parameters and the records: the maps between search vectors and params."""

    def __init__(self, model: RigModel, records: Sequence[Record], options: FitOptions):
        self.model = model
        self.records = list(records)
        self.options = options
        self.linear = tuple(s for s in model.linear if not (options.passive and s in model.current_terms))
        self.fixed_linear = {s: 0.0 for s in model.linear if s not in self.linear}
        self.evaluations = 0
        trim = [slice(15, r.theta.size - 15) for r in self.records]
        self._target = np.concatenate(
            [
                (r.torque_in - options.J * (r.theta_ddot + r.acc_road))[s]
                for r, s in zip(self.records, trim, strict=True)
            ]
        )
        self._trim = trim

    # --- variable projection (equation error) ----------------------------------------------------
    def linear_solve(self, nl: dict[str, float]) -> tuple[dict[str, float], float]:
        """Torque coefficients for an internal-state shape, and the RMS torque residual."""
        model = self.model
        probe = model.full_params(nl, {s: 1.0 for s in model.linear}, self.options.J)
        blocks = []
        for record, s in zip(self.records, self._trim, strict=True):
            state = model.state_path(probe, record)
            cols = dict(zip(model.linear, model.regressors(nl, state, record), strict=True))
            blocks.append(np.column_stack([cols[name][s] for name in self.linear]))
        A = np.vstack(blocks)
        y = self._target
        self.evaluations += 1
        # normal equations on scaled columns (5-6 unknowns; rows in the tens of thousands)
        scale = np.sqrt(np.einsum("ij,ij->j", A, A))
        scale[scale == 0.0] = 1.0
        As = A / scale
        G = As.T @ As
        rhs = As.T @ y
        try:
            coef = np.linalg.solve(G, rhs) / scale
        except np.linalg.LinAlgError:
            coef = np.linalg.lstsq(A, y, rcond=None)[0]
        lower = np.array([-np.inf if n in FREE_SIGN else 0.0 for n in self.linear])
        if np.any(coef < lower):
            # the same problem through the Cholesky factor of the normal matrix: ||R x - b||, R^T b = rhs
            r = np.linalg.cholesky(G + 1e-12 * np.eye(G.shape[0])).T
            b = np.linalg.solve(r.T, rhs)
            coef = lsq_linear(r, b, bounds=(lower * scale, np.inf), method="bvls").x / scale
        resid = A @ coef - y
        lin = dict(zip(self.linear, map(float, coef), strict=True))
        return {**lin, **self.fixed_linear}, float(np.sqrt(np.mean(resid**2)))

    # --- output error ------------------------------------------------------------------------------
    @property
    def free(self) -> tuple[str, ...]:
        return self.linear + self.model.nonlinear

    def params_of(self, x: np.ndarray) -> dict[str, float]:
        nl_names = self.model.nonlinear
        lin = dict(zip(self.linear, x[: len(self.linear)], strict=True))
        nl = dict(zip(nl_names, x[len(self.linear) :], strict=True))
        return self.model.full_params(nl, {**lin, **self.fixed_linear}, self.options.J)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-np.inf if n in FREE_SIGN else 0.0 for n in self.linear] + [b[0] for b in self.model.nl_bounds]
        hi = [np.inf for _ in self.linear] + [b[1] for b in self.model.nl_bounds]
        return np.array(lo, float), np.array(hi, float)

    def simulate(self, params: dict[str, float]) -> list[np.ndarray]:
        self.evaluations += 1
        return [self.model.simulate(params, r, self.options.max_step) for r in self.records]

    def residuals(self, x: np.ndarray) -> np.ndarray:
        try:
            sims = self.simulate(self.params_of(x))
        except (ValueError, ZeroDivisionError, FloatingPointError):
            sims = None
        out = []
        for k, r in enumerate(self.records):
            e = sims[k] - r.theta if sims is not None else np.full(r.theta.size, 1.0)
            out.append(np.where(np.isfinite(e), e, 1.0))
        return np.concatenate(out)


def _inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """x moved strictly inside finite bounds (least_squares needs an interior start)."""
    with np.errstate(invalid="ignore"):
        lo_m = np.where(np.isfinite(lo), lo + 1e-7 * (1 + np.abs(lo)), lo)
        hi_m = np.where(np.isfinite(hi), hi - 1e-7 * (1 + np.abs(hi)), hi)
    return np.clip(x, lo_m, hi_m)


def _global_vp(problem: Problem, options: FitOptions, bar: Progress, starts: int = 1) -> list[np.ndarray]:
    """Best (and up to ``starts`` distinct good) candidates of the variable-projection search."""
    model = problem.model
    if not model.nonlinear:
        lin, _ = problem.linear_solve({})
        return [np.array([lin[s] for s in problem.linear])]

    def cost(v: np.ndarray) -> float:
        return problem.linear_solve(dict(zip(model.nonlinear, v, strict=True)))[1]

    result = differential_evolution(
        cost,
        model.nl_bounds,
        popsize=options.popsize,
        maxiter=options.maxiter,
        tol=1e-6,
        seed=options.seed,
        polish=False,
        init="sobol",
        callback=lambda *a, **k: bar.advance(1),
    )
    candidates = [result.x]
    population = getattr(result, "population", None)
    if population is not None and starts > 1:
        order = np.argsort(result.population_energies)
        span = np.array([b[1] - b[0] for b in model.nl_bounds])
        for index in order:
            v = population[index]
            if all(np.max(np.abs(v - c) / span) > 0.1 for c in candidates):
                candidates.append(v)
            if len(candidates) >= starts:
                break
    out = []
    for v in candidates:
        lin, _ = problem.linear_solve(dict(zip(model.nonlinear, v, strict=True)))
        out.append(np.array([lin[s] for s in problem.linear] + list(v)))
    return out


def _two_stage(problem: Problem, records: Sequence[Record], options: FitOptions, bar: Progress) -> np.ndarray:
    """Seed 000 section 4.2: linear part with Coulomb friction first, then the hysteresis."""
    coulomb = Problem(MODELS["bingham"], records, FitOptions(**{**options.__dict__, "passive": options.passive}))
    x0 = _global_vp(coulomb, options, bar)[0]
    lo, hi = coulomb.bounds()
    fit1 = least_squares(coulomb.residuals, _inside(x0, lo, hi), bounds=(lo, hi), x_scale="jac", max_nfev=60)
    stage1 = coulomb.params_of(fit1.x)
    linear_part = {"k": stage1["k"], "c1": stage1["c0"], "c2": stage1["c0_i"]}
    model = problem.model
    hyst = [s for s in problem.linear if s not in linear_part]
    x_lin = [linear_part.get(s, 0.0) for s in problem.linear if s in linear_part]

    def compose(v: np.ndarray) -> np.ndarray:
        lin = dict(zip(hyst, v[: len(hyst)], strict=True))
        full = [linear_part[s] if s in linear_part else lin[s] for s in problem.linear]
        return np.array(full + list(v[len(hyst) :]))

    fc = stage1["fc"]
    bounds = [(0.0, 4.0 * fc + 1e-3) for _ in hyst] + list(model.nl_bounds)

    def cost(v: np.ndarray) -> float:
        return float(np.sqrt(np.mean(problem.residuals(compose(v)) ** 2)))

    result = differential_evolution(
        cost,
        bounds,
        popsize=options.popsize,
        maxiter=options.maxiter,
        tol=1e-6,
        seed=options.seed,
        polish=False,
        init="sobol",
        callback=lambda *a, **k: bar.advance(1),
    )
    del x_lin
    return compose(result.x)


def _uncertainty(problem: Problem, fit) -> tuple[dict, dict, list]:
    """1-sigma standard errors and correlations of the free parameters from the Jacobian."""
    J = fit.jac
    m, p = J.shape
    s2 = 2.0 * fit.cost / max(m - p, 1)
    cov_x = s2 * np.linalg.pinv(J.T @ J)
    names = [s for s in problem.model.symbols if s != "J" and s not in problem.fixed_linear]
    base = problem.params_of(fit.x)
    G = np.zeros((len(names), p))
    for j in range(p):
        step = 1e-6 * max(abs(fit.x[j]), 1e-3)
        xp, xm = fit.x.copy(), fit.x.copy()
        xp[j] += step
        xm[j] -= step
        pp, pm = problem.params_of(xp), problem.params_of(xm)
        G[:, j] = [(pp[n] - pm[n]) / (2 * step) for n in names]
    cov = G @ cov_x @ G.T
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    stderr = {n: float(s) for n, s in zip(names, sd, strict=True)}
    corr: dict[str, dict[str, float]] = {}
    flagged = []
    for a, na in enumerate(names):
        corr[na] = {}
        for b, nb in enumerate(names):
            c = cov[a, b] / (sd[a] * sd[b]) if sd[a] > 0 and sd[b] > 0 else 0.0
            corr[na][nb] = float(c)
            if b > a and abs(c) > 0.95:
                flagged.append((na, nb, float(c)))
    del base
    return stderr, corr, flagged


def fit_model(name: str, records: Sequence[Record], options: FitOptions | None = None) -> FitResult:
    """Identify model ``name`` jointly on ``records`` (see the module docstring)."""
    options = options or FitOptions()
    started = time.perf_counter()
    model = MODELS[name]
    problem = Problem(model, records, options)
    total = options.maxiter * (2 if options.two_stage else 1) + 1
    bar = Progress(total, f"identify {name}", enabled=options.progress)
    stages = []
    if options.two_stage and name == "bouc-wen":
        starts = [_two_stage(problem, records, options, bar)]
        stages.append("two-stage: Coulomb linear part (output error), then hysteresis by DE (output error)")
    else:
        starts = _global_vp(problem, options, bar, options.starts)
        stages.append("global: differential evolution, variable projection on the torque balance")
    lo, hi = problem.bounds()
    if len(starts) > options.refine:
        # screen the global candidates by their output error, refine the best few
        scores = [float(np.sum(problem.residuals(_inside(x, lo, hi)) ** 2)) for x in starts]
        starts = [starts[j] for j in np.argsort(scores)[: options.refine]]
    fit = None
    for x0 in starts:
        trial = least_squares(
            problem.residuals, _inside(x0, lo, hi), bounds=(lo, hi), x_scale="jac", max_nfev=100 if options.local else 1
        )
        if fit is None or trial.cost < fit.cost:
            fit = trial
    assert fit is not None  # at least one start
    stages.append(
        f"local: least_squares on the output error from the best of {options.starts} screened start(s) (best: {fit.nfev} evaluations, status {fit.status})"
    )
    bar.advance(1)
    bar.close()
    params = problem.params_of(fit.x)
    stderr, corr, flagged = _uncertainty(problem, fit)
    sims = problem.simulate(params)
    rms = [float(np.sqrt(np.mean((s - r.theta) ** 2))) for s, r in zip(sims, records, strict=True)]
    nr = [nrmse(s, r.theta) for s, r in zip(sims, records, strict=True)]
    return FitResult(
        model=name,
        params=params,
        stderr=stderr,
        correlations=corr,
        flagged=flagged,
        rms_rad=rms,
        nrmse=nr,
        record_names=[r.name for r in records],
        wall_s=time.perf_counter() - started,
        evaluations=problem.evaluations,
        fixed={"J": options.J, **problem.fixed_linear},
        normalisation=model.normalisation,
        stages=stages,
    )

"""Fitting a rig model to records: global stage, local output-error refinement, uncertainties.

Objective (seed 000 eq. 10, on the rig's measured output): the RMS of the simulated minus the
recorded angle theta over all samples of all runs (output error, a simulation from each run's own
initial angle, driven by its recorded current, road-side motion and input torque).

Stages (default, ``fit_model``):
1. global: a deterministic multi-start over the few parameters that shape the internal state: an
   unscrambled Sobol design over their box (the exponent n spaced geometrically), then Nelder-Mead
   from the best distinct design points; for each candidate the torque coefficients come from one
   linear least-squares solve of the torque balance on smoothed derivatives (variable projection,
   equation error) - milliseconds per candidate. Nothing in it is random, so the answer depends on
   the data only (the seed's genetic algorithm, differential evolution, remains for ``two_stage``);
2. local: trust-region least squares (scipy ``least_squares``) on the output error over all free
   parameters, from the best few global candidates screened by their output error; the best
   refinement wins, and whether the others reached the same cost is reported (convergence).
Initial angles (``initial_angle_tolerance_rad`` > 0): an encoder gives each run's release angle only
to within its count cell (and its noise), and a run simulated from the wrong start carries that
offset through every sample; the fit would bend the damper's parameters to absorb it (the yield
torque most, by several per cent on a damper whose yield spans few counts). So each record's
initial angle is a nuisance parameter of the local stage, searched within +- the tolerance of its
first sample (the classic output-error treatment of an unknown initial state), with its Jacobian
column from a simulation of that record alone.
``two_stage=True`` is the seed 000 procedure instead: the linear part (k, c1, c2) with Coulomb
friction first (output error), then the hysteresis parameters by differential evolution on the
output error with the linear part fixed, then the same local refinement of everything.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution, least_squares, lsq_linear

from sashil.identify.data import Record, angle_quantum
from sashil.identify.progress import Progress
from sashil.identify.rig_models import MODELS, RigModel
from sashil.stats import nrmse

#: parameters a linear solve keeps >= 0 (physical torques and damping); Bingham's offset f0 is free
FREE_SIGN = {"f0"}
#: each record's initial angle is searched within this many encoder counts of its first sample: the
#: count cell (half a count each way) and the angle noise of two encoders (a few tenths of a count)
INITIAL_ANGLE_COUNTS = 2.0
#: relative forward-difference step of the Jacobian (scipy's 2-point: the square root of the float epsilon)
FD_STEP = float(np.finfo(float).eps) ** 0.5


@dataclass
class FitOptions:
    passive: bool = False  # fix the current-dependent terms at 0 (runs at one current)
    two_stage: bool = False
    J: float = 1.0
    popsize: int = 12  # two-stage DE only
    maxiter: int = 30  # two-stage DE only
    design: int = 256  # Sobol design points of the global stage (rounded to a power of two)
    starts: int = 8  # distinct global candidates screened by their output error
    refine: int = 2  # local refinements from the best screened candidates
    probe_nfev: int = 25  # evaluations of each refinement before the best one is carried on
    max_nfev: int = 100  # evaluations of the carried-on refinement
    seed: int = 0  # two-stage DE only; the default search is deterministic
    max_step: float = 1e-3
    progress: bool = False
    local: bool = True
    # each record's initial angle searched within +- this of its first sample [rad]; 0: taken as exact
    initial_angle_tolerance_rad: float = 0.0


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
    convergence: dict = field(default_factory=dict)
    # the optimum in search coordinates (``free``), the output-error residuals there (all records,
    # concatenated) and their Jacobian: what :mod:`sashil.identify.intervals` leaves out block by block
    free: tuple[str, ...] = ()
    x: np.ndarray | None = None
    residuals: np.ndarray | None = None
    jacobian: np.ndarray | None = None
    # the search vector's bounds, and each record's fitted initial-angle offset [rad] (fit order)
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    initial_offsets_rad: list[float] = field(default_factory=list)

    @property
    def rms_total(self) -> float:
        return float(math.sqrt(np.mean(np.square(self.rms_rad))))

    @property
    def nrmse_mean(self) -> float:
        return float(np.mean(self.nrmse))

    @property
    def model_free(self) -> int:
        """How many of the free parameters are the model's (the initial-angle offsets left out)."""
        return len(self.free) - len(self.initial_offsets_rad) if self.free else 0


#: rows of the equation-error (variable projection) stage, about: longer records are sampled sparser
VP_ROWS = 12_000


def _every(record: Record, stride: int) -> Record:
    """The record at every ``stride``-th sample (the same record when stride is 1)."""
    if stride == 1:
        return record
    arrays = {
        name: getattr(record, name)[::stride]
        for name in ("time_s", "theta", "current", "acc_road", "torque_in", "theta_dot", "theta_ddot", "theta_smooth")
    }
    return dataclasses.replace(record, **arrays)


class Problem:
    """A model, its free parameters and the records: the maps between search vectors and params."""

    def __init__(self, model: RigModel, records: Sequence[Record], options: FitOptions):
        self.model = model
        self.records = list(records)
        self.options = options
        self.linear = tuple(s for s in model.linear if not (options.passive and s in model.current_terms))
        self.fixed_linear = {s: 0.0 for s in model.linear if s not in self.linear}
        self.evaluations = 0
        # the equation-error stage sees every stride-th sample (about VP_ROWS rows in all): the state
        # path over the coarser angle increments is the same rate-independent law, only sampled less
        total = sum(r.theta.size for r in self.records)
        self.stride = max(1, round(total / VP_ROWS))
        self._vp_records = [_every(r, self.stride) for r in self.records]
        edge = math.ceil(15 / self.stride)  # the smoothed derivatives' edges (15 ms) are left out
        trim = [slice(edge, r.theta.size - edge) for r in self._vp_records]
        tolerance = float(options.initial_angle_tolerance_rad)
        self.tolerance = tolerance if tolerance > 0.0 else 0.0
        self.offsets = tuple(f"initial_angle_{k}" for k in range(len(self.records))) if self.tolerance else ()
        self._last: tuple[bytes, np.ndarray] | None = None
        self._target = np.concatenate(
            [
                (r.torque_in - options.J * (r.theta_ddot + r.acc_road))[s]
                for r, s in zip(self._vp_records, trim, strict=True)
            ]
        )
        self._trim = trim

    # --- variable projection (equation error) ----------------------------------------------------
    def linear_solve(self, nl: dict[str, float]) -> tuple[dict[str, float], float]:
        """Torque coefficients for an internal-state shape, and the RMS torque residual."""
        model = self.model
        probe = model.full_params(nl, {s: 1.0 for s in model.linear}, self.options.J)
        blocks = []
        for record, s in zip(self._vp_records, self._trim, strict=True):
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
        """The search vector: torque coefficients, state shape, then each record's initial-angle offset."""
        return self.linear + self.model.nonlinear + self.offsets

    @property
    def model_size(self) -> int:
        """Entries of the search vector that are the model's (the initial-angle offsets follow)."""
        return len(self.linear) + len(self.model.nonlinear)

    def params_of(self, x: np.ndarray) -> dict[str, float]:
        nl_names = self.model.nonlinear
        lin = dict(zip(self.linear, x[: len(self.linear)], strict=True))
        nl = dict(zip(nl_names, x[len(self.linear) : self.model_size], strict=True))
        return self.model.full_params(nl, {**lin, **self.fixed_linear}, self.options.J)

    def offsets_of(self, x: np.ndarray) -> list[float]:
        """Each record's initial-angle offset [rad] (0 where the search vector has none)."""
        tail = x[self.model_size :]
        return [float(v) for v in tail] if tail.size == len(self.records) else [0.0] * len(self.records)

    def padded(self, x: np.ndarray) -> np.ndarray:
        """A model-only search vector (a global stage's candidate) with zero initial-angle offsets."""
        return np.concatenate([x, np.zeros(len(self.offsets))]) if x.size == self.model_size else x

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-np.inf if n in FREE_SIGN else 0.0 for n in self.linear] + [b[0] for b in self.model.nl_bounds]
        hi = [np.inf for _ in self.linear] + [b[1] for b in self.model.nl_bounds]
        lo += [-self.tolerance] * len(self.offsets)
        hi += [self.tolerance] * len(self.offsets)
        return np.array(lo, float), np.array(hi, float)

    def simulate(self, params: dict[str, float], offsets: Sequence[float] | None = None) -> list[np.ndarray]:
        self.evaluations += 1
        shifts = offsets if offsets is not None else [0.0] * len(self.records)
        return [
            self.model.simulate(params, r, self.options.max_step, d) for r, d in zip(self.records, shifts, strict=True)
        ]

    def _record_residual(self, k: int, params: dict[str, float] | None, offset: float) -> np.ndarray:
        """theta_sim - theta_rec of record k (1.0 where the simulation failed or is not finite)."""
        record = self.records[k]
        if params is None:
            return np.full(record.theta.size, 1.0)
        try:
            e = self.model.simulate(params, record, self.options.max_step, offset) - record.theta
        except (ValueError, ZeroDivisionError, FloatingPointError):
            return np.full(record.theta.size, 1.0)
        return np.where(np.isfinite(e), e, 1.0)

    def _params_or_none(self, x: np.ndarray) -> dict[str, float] | None:
        try:
            return self.params_of(x)
        except (ValueError, ZeroDivisionError, FloatingPointError):
            return None

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Output error of every record, concatenated in fit order."""
        self.evaluations += 1
        params = self._params_or_none(x)
        offsets = self.offsets_of(x)
        out = np.concatenate([self._record_residual(k, params, offsets[k]) for k in range(len(self.records))])
        self._last = (x.tobytes(), out)  # least_squares asks for the Jacobian where it last evaluated
        return out

    @property
    def jac_option(self) -> Callable[[np.ndarray], np.ndarray] | str:
        """What ``least_squares`` differentiates with: :meth:`jacobian` with initial-angle offsets, else
        its own 2-point differences (the same step)."""
        return self.jacobian if self.offsets else "2-point"

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Forward-difference Jacobian of :meth:`residuals` (scipy's 2-point step, turned inwards at a
        bound); an initial-angle offset moves only its own record, which alone is re-simulated."""
        lo, hi = self.bounds()
        last = self._last
        base = last[1] if last is not None and last[0] == x.tobytes() else self.residuals(x)
        ends = np.cumsum([0] + [r.theta.size for r in self.records])
        params = self._params_or_none(x)
        offsets = self.offsets_of(x)
        out = np.zeros((base.size, x.size))
        for j in range(x.size):
            h = FD_STEP * (1.0 if x[j] >= 0.0 else -1.0) * max(1.0, abs(float(x[j])))
            if not lo[j] <= x[j] + h <= hi[j]:
                h = -h
            if j < self.model_size:
                moved = x.copy()
                moved[j] += h
                out[:, j] = (self.residuals(moved) - base) / h
            else:
                k = j - self.model_size
                rows = slice(int(ends[k]), int(ends[k + 1]))
                out[rows, j] = (self._record_residual(k, params, offsets[k] + h) - base[rows]) / h
        return out


def _inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """x moved strictly inside finite bounds (least_squares needs an interior start)."""
    with np.errstate(invalid="ignore"):
        lo_m = np.where(np.isfinite(lo), lo + 1e-7 * (1 + np.abs(lo)), lo)
        hi_m = np.where(np.isfinite(hi), hi - 1e-7 * (1 + np.abs(hi)), hi)
    return np.clip(x, lo_m, hi_m)


def _design(model: RigModel, count: int) -> np.ndarray:
    """Deterministic space-filling points of the model's nonlinear box (unscrambled Sobol)."""
    from scipy.stats import qmc

    dims = len(model.nonlinear)
    m = max(1, math.ceil(math.log2(max(count, 2))))
    unit = qmc.Sobol(dims, scramble=False).random_base2(m)
    unit = (unit + 0.5 / unit.shape[0]) % 1.0  # off the box corners (the first Sobol point is 0)
    logs = model.nl_log or (False,) * dims
    out = np.empty_like(unit)
    for j, ((lo, hi), log) in enumerate(zip(model.nl_bounds, logs, strict=True)):
        if log:
            out[:, j] = np.exp(np.log(lo) + unit[:, j] * (np.log(hi) - np.log(lo)))
        else:
            out[:, j] = lo + unit[:, j] * (hi - lo)
    return out


def _global_vp(problem: Problem, options: FitOptions, bar: Progress, starts: int = 1) -> list[np.ndarray]:
    """Best (and up to ``starts`` distinct good) candidates of the variable-projection search.

    Deterministic: the Sobol design's VP costs, then Nelder-Mead from the best distinct points
    (distinct: more than a tenth of the box apart in some coordinate)."""
    from scipy.optimize import minimize

    model = problem.model
    if not model.nonlinear:
        lin, _ = problem.linear_solve({})
        return [np.array([lin[s] for s in problem.linear])]
    lo = np.array([b[0] for b in model.nl_bounds])
    hi = np.array([b[1] for b in model.nl_bounds])
    span = hi - lo

    def cost(v: np.ndarray) -> float:
        v = np.clip(v, lo, hi)
        try:
            value = problem.linear_solve(dict(zip(model.nonlinear, v, strict=True)))[1]
        except (ValueError, ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError):
            return math.inf
        return value if math.isfinite(value) else math.inf

    design = _design(model, options.design)
    scores = np.array([cost(v) for v in design])
    bar.advance(1)
    seeds: list[np.ndarray] = []
    for index in np.argsort(scores, kind="stable"):
        v = design[index]
        if all(np.max(np.abs(v - c) / span) > 0.1 for c in seeds):
            seeds.append(v)
        if len(seeds) >= max(starts, 1):
            break
    polished = []
    for v in seeds:
        result = minimize(
            cost,
            v,
            method="Nelder-Mead",
            options={"maxfev": 40 * len(v), "xatol": 1e-4, "fatol": 1e-10, "initial_simplex": _simplex(v, lo, hi)},
        )
        polished.append((float(result.fun), np.clip(result.x, lo, hi)))
        bar.advance(1)
    candidates: list[np.ndarray] = []
    for _, v in sorted(polished, key=lambda item: item[0]):
        if all(np.max(np.abs(v - c) / span) > 0.02 for c in candidates):
            candidates.append(v)
    out = []
    for v in candidates[: max(starts, 1)]:
        lin, _ = problem.linear_solve(dict(zip(model.nonlinear, v, strict=True)))
        out.append(np.array([lin[s] for s in problem.linear] + list(v)))
    return out


def _simplex(v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Nelder-Mead's first simplex: v and one step of a twentieth of the box along each axis (inwards)."""
    points = [v.copy()]
    for j in range(v.size):
        step = 0.05 * (hi[j] - lo[j])
        p = v.copy()
        p[j] = v[j] + step if v[j] + step <= hi[j] else v[j] - step
        points.append(p)
    return np.array(points)


def _two_stage(problem: Problem, records: Sequence[Record], options: FitOptions, bar: Progress) -> np.ndarray:
    """Seed 000 section 4.2: linear part with Coulomb friction first, then the hysteresis."""
    coulomb = Problem(MODELS["bingham"], records, FitOptions(**{**options.__dict__, "passive": options.passive}))
    x0 = coulomb.padded(_global_vp(coulomb, options, bar)[0])
    lo, hi = coulomb.bounds()
    fit1 = least_squares(
        coulomb.residuals, _inside(x0, lo, hi), bounds=(lo, hi), x_scale="jac", max_nfev=60, jac=coulomb.jac_option
    )
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
        return float(np.sqrt(np.mean(problem.residuals(problem.padded(compose(v))) ** 2)))

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


def one_blas_thread() -> contextlib.AbstractContextManager:
    """BLAS on one thread within the block: the fit's matrices are tall and thin (tens of thousands
    of samples by a dozen parameters), where BLAS's worker threads only contend for the cores."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def fit_model(name: str, records: Sequence[Record], options: FitOptions | None = None) -> FitResult:
    """Identify model ``name`` jointly on ``records`` (see the module docstring), BLAS on one thread."""
    with one_blas_thread():
        return _fit_model(name, records, options or FitOptions())


def _fit_model(name: str, records: Sequence[Record], options: FitOptions) -> FitResult:
    started = time.perf_counter()
    model = MODELS[name]
    problem = Problem(model, records, options)
    total = options.maxiter * 2 + 1 if options.two_stage else options.starts + options.refine + 1
    bar = Progress(total, f"identify {name}", enabled=options.progress)
    stages = []
    if options.two_stage and name == "bouc-wen":
        starts = [_two_stage(problem, records, options, bar)]
        stages.append("two-stage: Coulomb linear part (output error), then hysteresis by DE (output error)")
    else:
        starts = _global_vp(problem, options, bar, options.starts)
        stages.append(
            f"global: deterministic multi-start (Sobol design of {_design(model, options.design).shape[0]} points, "
            f"Nelder-Mead from {len(starts)} distinct), variable projection on the torque balance"
        )
    starts = [problem.padded(x) for x in starts]
    lo, hi = problem.bounds()
    screened = len(starts)
    global_s = time.perf_counter() - started
    if len(starts) > options.refine:
        # screen the global candidates by their output error, refine the best few
        scores = [float(np.sum(problem.residuals(_inside(x, lo, hi)) ** 2)) for x in starts]
        starts = [starts[j] for j in np.argsort(scores, kind="stable")[: options.refine]]
    trials = []
    # a short refinement of each start, then the best one carried on to convergence
    budget = options.probe_nfev if len(starts) > 1 else options.max_nfev
    for x0 in starts:
        trial = least_squares(
            problem.residuals,
            _inside(x0, lo, hi),
            bounds=(lo, hi),
            x_scale="jac",
            max_nfev=budget if options.local else 1,
            jac=problem.jac_option,
        )
        trials.append(trial)
        bar.advance(1)
    best = min(range(len(trials)), key=lambda j: trials[j].cost)
    fit = trials[best]
    if options.local and len(starts) > 1 and fit.status == 0:
        more = least_squares(
            problem.residuals,
            _inside(fit.x, lo, hi),
            bounds=(lo, hi),
            x_scale="jac",
            max_nfev=options.max_nfev,
            jac=problem.jac_option,
        )
        more.nfev += fit.nfev
        trials[best] = fit = more
    convergence = _convergence(problem, fit, trials)
    convergence["global_s"] = round(global_s, 3)
    convergence["local_s"] = round(time.perf_counter() - started - global_s, 3)
    stages.append(
        f"local: least_squares on the output error from the best {len(trials)} of {screened} screened start(s) "
        f"(best: {fit.nfev} evaluations, status {fit.status}: {convergence['message']})"
    )
    bar.close()
    params = problem.params_of(fit.x)
    stderr, corr, flagged = _uncertainty(problem, fit)
    offsets = problem.offsets_of(fit.x)
    sims = problem.simulate(params, offsets)
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
        convergence=convergence,
        free=problem.free,
        x=np.array(fit.x, dtype=float),
        residuals=np.array(fit.fun, dtype=float),
        jacobian=np.array(fit.jac, dtype=float),
        lower=lo,
        upper=hi,
        initial_offsets_rad=offsets,
    )


def initial_angle_tolerance(records: Sequence[Record]) -> float:
    """How far from its first sample each record's initial angle is searched [rad]:
    INITIAL_ANGLE_COUNTS encoder counts of the records (0 for angles that are not counts)."""
    return INITIAL_ANGLE_COUNTS * angle_quantum(records)


def simulate_fitted(result: FitResult, records: Sequence[Record]) -> list[np.ndarray]:
    """theta_sim [rad] of each record under the fitted model, from the initial angle the fit
    estimated for it (its first sample, for a record the fit did not see)."""
    model = MODELS[result.model]
    offsets = dict(zip(result.record_names, result.initial_offsets_rad, strict=False))
    return [model.simulate(result.params, r, initial_offset_rad=offsets.get(r.name, 0.0)) for r in records]


def _convergence(problem: Problem, fit, trials: Sequence) -> dict:
    """How the local stage ended: status, evaluations, gradient, and the spread of the refinements."""
    best = float(fit.cost)
    agree = [t for t in trials if t.cost <= best * 1.005 + 1e-300]
    converged = fit.status > 0  # 0: evaluation budget used up
    return {
        "converged": bool(converged),
        "status": int(fit.status),
        "message": str(fit.message),
        "evaluations": int(fit.nfev),
        "optimality": float(fit.optimality),
        "refinements": len(trials),
        "refinements_within_0_5pct": len(agree),
        "costs": [float(2.0 * t.cost) for t in trials],
    }

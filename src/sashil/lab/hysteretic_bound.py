"""The optimal bound on the rig's own model: the best comfort a damper could reach knowing the road
in advance, with its Bouc-Wen state and the coil's lag, rather than the viscous envelope of
:mod:`sashil.lab.optimal_bound`.

The envelope leaves out the hysteretic torque α(i)·z: where z sits at its bound z_u it is a friction
of α1·z_u at 0 A and (α1 + α2·i_max)·z_u at i_max, so the rig's hard end is harder than the
envelope's and a law on the rig can beat the envelope's bound; at small travel it is a spring of
stiffness α(i)·δ, which a friction leaves out too, and there the envelope's bound lies far below
anything the rig can do (a damper whose z never leaves that spring locks the arm to the road at any
current). This bound solves the same problem (direct transcription: the command of every cycle free
in [0, i_max], the exact discrete adjoint of :mod:`sashil.control.plan_boucwen`, L-BFGS-B) on the
rig's model, the whole road as one block.

Its cost is the metric's own: θ̈2 low-passed at ``bandwidth_hz`` as compare's metric is (a
friction's switching adds θ̈2 above the metric's band, which the metric never sees), its mean
square over the cycles :func:`sashil.lab.compare_metrics.metric_window` keeps (those after
``compare.settle_s``): the settling window is in neither. With the filter F applied forward and
back from rest (Fᵀ = F, :func:`sashil.control.preview_plan.lowpass`) and the window a mask M of m
cycles, the direct term of the gradient is 2·F(M·F a)/m.

The problem is not convex: each start ends in a local optimum of its own, and the bound is the best
of them. The starts owe nothing to any law (:data:`STARTS`): the constant mid current, the model's
best constant current (a bounded scalar search on the same cost), a sign rule computed here along
that constant's trajectory (i_max where the arm's rate θ̇2 and the damper's rate θ̇ share a sign,
the skyhook condition of Karnopp, Crosby & Harwood 1974, else 0), and a seeded random smooth
sequence. The spread of their optima is reported (:attr:`HystereticBound.spread`): how far the
answer depends on where the search starts. Like the envelope's, the bound is the best found, not a
certificate.

The bound is the model's own θ̈2, with no measurement in it; a run over a link is measured by its
encoders (:func:`sashil.lab.compare_metrics.arm_acceleration`). Through the samples' counts alone
their quantisation adds a floor of noise independent of the arm's motion, in quadrature (for a
4096-count encoder about 1 rad/s² RMS at 20 Hz, the same for every law). Through the arm encoder's
edges, as compare reads a stream that has them, that floor is gone, and the chain reads 0.1–2 % low
instead (the band's content where the edges lie further apart than its period, most at 1 A, where
the arm moves least). Both ends of a share's scale and the law must be on one chain:
:func:`bound_on_chain` puts the bound on the chain that measured the runs, with the floor measured as
the passive run's excess over the model's own passive run at the same current (:func:`model_passive`),
sqrt(b² + p_chain² − p_model²). On the edges' chain that excess is small and of either sign (the
chain's loss, and the road the link realised, ±1 %), and still wanted: a passive run read low
narrows the share's gap p − b, and the bound read alike keeps it (over serial, 30 s runs: shares
within a median 5 points of the simulated rig's with it, 8 without). On the simulated rig's own θ̈2
the floor is the model's discretisation alone (near 0).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview import commanded_road
from sashil.control.preview_plan import comfort_filter, lowpass, simulate_plan
from sashil.lab.compare_metrics import cycle_times, metric_window
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RoadProfile

__all__ = ["STARTS", "HystereticBound", "bound_on_chain", "find_bound", "hysteretic_bound", "model_passive"]

#: the starts of the bound's search, none of them a law's plan (module docstring)
STARTS = ("mid current", "best constant", "sign rule", "random smooth")
#: the seed of the random smooth start, and its bandwidth [Hz] (a few changes a second, as the road's
#: dominant motion below the arm's resonance)
RANDOM_SEED = 0
RANDOM_BANDWIDTH_HZ = 2.0
#: the tolerance of the scalar search for the model's best constant current, as a share of i_max
CONSTANT_XATOL = 1e-3


@dataclass(frozen=True)
class HystereticBound:
    """The bound's RMS θ̈2 [rad/s²] (the best of the starts' optima), the model's best constant
    current [A] and its RMS θ̈2, and each start's optimum by name (:data:`STARTS`)."""

    rms_accel_bound: float
    passive_current_a: float
    rms_accel_passive: float
    starts: dict[str, float] = field(default_factory=dict)

    @property
    def spread(self) -> float:
        """How far apart the starts' optima lie [rad/s²]: the worst less the best (0 with one start)."""
        found = [v for v in self.starts.values() if math.isfinite(v)]
        return max(found) - min(found) if found else math.nan

    @property
    def spread_pct(self) -> float:
        """:attr:`spread` as a share of the gap from the model's best constant current to the bound [%]
        (NaN when the bound is not below it)."""
        gap = self.rms_accel_passive - self.rms_accel_bound
        return 100.0 * self.spread / gap if gap > 0.0 else math.nan


def _road_rates(road: RoadProfile, duration_s: float, h: float) -> np.ndarray:
    """The road speeds commanded at each cycle of ``h`` over ``duration_s``, as a run commands them."""
    n = int(round(duration_s / h))
    return commanded_road(lambda t: road(t)[1], h, duration_s, 0).rate_rad_s[:n]


def _window(n: int, settle_s: float, h: float) -> np.ndarray:
    """The cycles of ``n`` compare's metric keeps (after ``settle_s``), as a 0/1 mask; the last cycle
    kept where the run is no longer than the settling (a cost needs one cycle)."""
    mask = metric_window(cycle_times(n, h), settle_s).astype(float)
    if not mask.any():
        mask[-1] = 1.0
    return mask


def _rms_after(accel: np.ndarray, settle_s: float, h: float, bandwidth_hz: float | None) -> float:
    """RMS of ``accel`` low-passed at ``bandwidth_hz`` (None: unfiltered) over the metric's window."""
    mask = _window(accel.size, settle_s, h)
    a = lowpass(accel, comfort_filter(bandwidth_hz, h))
    return math.sqrt(float(np.sum(mask * a * a) / np.sum(mask)))


def model_passive(
    params: BoucWenParams,
    current_a: float,
    coil_tau_s: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    bandwidth_hz: float | None = None,
) -> float:
    """RMS θ̈2 [rad/s²] after ``settle_s`` of the bound's model at the constant current ``current_a``
    on ``road``: the passive run as the bound's model gives it, low-passed as compare's metric is."""
    rates = _road_rates(road, duration_s, h)
    plan = simulate_plan(BoucWenPlanModel.of(params, coil_tau_s, h), np.full(rates.size, float(current_a)), rates, h)
    return _rms_after(plan.accel_rad_s2, settle_s, h, bandwidth_hz)


def bound_on_chain(bound: float, passive_chain: float, passive_model: float) -> float:
    """The bound ``bound`` [rad/s²] as the chain that measured the passive run ``passive_chain`` would
    read it: sqrt(b² + f²), the chain's floor f² = ``passive_chain``² − ``passive_model``² (the model's
    passive run at the same current; module docstring). NaN where a value is missing or b² + f² ≤ 0."""
    floor2 = passive_chain * passive_chain - passive_model * passive_model
    total = bound * bound + floor2
    if not (math.isfinite(total) and total > 0.0):
        return math.nan
    return math.sqrt(total)


class _Cost:
    """The bound's cost of a command sequence on the model: the mean square of θ̈2 low-passed by
    ``sos`` over the metric's window (module docstring), and its exact gradient."""

    def __init__(self, model: BoucWenPlanModel, rates: np.ndarray, h: float, sos: np.ndarray | None, mask: np.ndarray):
        self.model, self.h, self.sos, self.mask = model, h, sos, mask
        self.w = np.ascontiguousarray(rates, dtype=float)
        self.m = model.vector()
        self.x0 = np.zeros(4)
        self.bufs = [np.empty(self.w.size) for _ in range(5)]
        self.grad = np.empty(self.w.size)
        self.kept = float(np.sum(mask))

    def _filtered(self, u: np.ndarray) -> np.ndarray:
        """θ̈2 under ``u``, low-passed (the trajectory left in the buffers for the adjoint)."""
        thetas, vs, zs, coil, accel = self.bufs
        self.model.forward(
            np.ascontiguousarray(u, dtype=float), self.w, self.m, self.h, self.x0, thetas, vs, zs, coil, accel
        )
        return lowpass(accel, self.sos)

    def value(self, u: np.ndarray) -> float:
        filtered = self._filtered(u)
        return float(np.sum(self.mask * filtered * filtered) / self.kept)

    def __call__(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        filtered = self._filtered(u)
        value = float(np.sum(self.mask * filtered * filtered) / self.kept)
        direct = (2.0 / self.kept) * lowpass(self.mask * filtered, self.sos)
        thetas, vs, zs, coil, _ = self.bufs
        self.model.adjoint(
            np.ascontiguousarray(u, dtype=float), self.w, self.m, self.h, thetas, vs, zs, coil, direct, self.grad
        )
        return value, self.grad.copy()

    def rates(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The arm's rate θ̇2 and the damper's rate θ̇ = θ̇2 − θ̇1 before each cycle under ``u``."""
        self.value(u)
        body = self.bufs[1].copy()
        return body, body - self.w


def _random_smooth(n: int, current_max_a: float, h: float) -> np.ndarray:
    """A seeded random command sequence: white noise low-passed at :data:`RANDOM_BANDWIDTH_HZ`,
    about the mid current with a quarter of i_max as its spread, clipped to [0, i_max]."""
    rng = np.random.default_rng(RANDOM_SEED)
    smooth = lowpass(rng.standard_normal(n), comfort_filter(RANDOM_BANDWIDTH_HZ, h))
    scale = float(np.std(smooth)) or 1.0
    return np.clip(current_max_a * (0.5 + 0.25 * smooth / scale), 0.0, current_max_a)


def _starts(cost: _Cost, current_max_a: float, h: float) -> tuple[dict[str, np.ndarray], float, float]:
    """The starts of :data:`STARTS` by name, the model's best constant current and its cost."""
    from scipy.optimize import minimize_scalar

    n = cost.w.size
    best = minimize_scalar(
        lambda i: cost.value(np.full(n, i)),
        bounds=(0.0, current_max_a),
        method="bounded",
        options={"xatol": CONSTANT_XATOL * current_max_a},
    )
    ends = [(cost.value(np.full(n, i)), i) for i in (0.0, current_max_a)]
    passive_cost, passive_a = min([(float(best.fun), float(best.x)), *ends])
    body, relative = cost.rates(np.full(n, passive_a))
    starts = {
        "mid current": np.full(n, 0.5 * current_max_a),
        "best constant": np.full(n, passive_a),
        "sign rule": np.where(body * relative > 0.0, current_max_a, 0.0),
        "random smooth": _random_smooth(n, current_max_a, h),
    }
    return starts, passive_a, passive_cost


def find_bound(
    params: BoucWenParams,
    current_max_a: float,
    coil_tau_s: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    max_iterations: int = 3000,
    bandwidth_hz: float | None = None,
    on_start: Callable[[str, float], None] | None = None,
) -> HystereticBound:
    """The bound of the module docstring on ``road`` over ``duration_s``, its cost over the metric's
    window (after ``settle_s``); ``bandwidth_hz``: θ̈2 low-passed there, in the cost and the result,
    as compare's metric is. ``on_start``: told each start's name and optimum [rad/s²] as it ends."""
    from scipy.optimize import minimize

    rates = _road_rates(road, duration_s, h)
    model = BoucWenPlanModel.of(params, coil_tau_s, h)
    cost = _Cost(model, rates, h, comfort_filter(bandwidth_hz, h), _window(rates.size, settle_s, h))
    if not (current_max_a > 0.0 and model.authority):  # no authority: the damper is passive
        rms = math.sqrt(cost.value(np.zeros(rates.size)))
        return HystereticBound(rms, 0.0, rms, {})
    starts, passive_a, passive_cost = _starts(cost, current_max_a, h)
    options = {"maxiter": max_iterations, "maxfun": 2 * max_iterations}
    bounds = [(0.0, current_max_a)] * rates.size
    found = {}
    for name, u0 in starts.items():
        res = minimize(cost, u0, jac=True, method="L-BFGS-B", bounds=bounds, options=options)
        u = np.clip(np.asarray(res.x, dtype=float), 0.0, current_max_a)
        found[name] = math.sqrt(cost.value(u))
        if on_start is not None:
            on_start(name, found[name])
    bound = min(min(found.values()), math.sqrt(passive_cost))  # a start never ends above where it began
    return HystereticBound(bound, passive_a, math.sqrt(passive_cost), found)


def hysteretic_bound(
    params: BoucWenParams,
    current_max_a: float,
    coil_tau_s: float,
    road: RoadProfile,
    duration_s: float,
    settle_s: float,
    h: float = 1e-3,
    max_iterations: int = 3000,
    bandwidth_hz: float | None = None,
) -> float:
    """RMS θ̈2 [rad/s²] over the metric's window of the best plan :func:`find_bound` finds on ``road``."""
    return find_bound(
        params, current_max_a, coil_tau_s, road, duration_s, settle_s, h, max_iterations, bandwidth_hz
    ).rms_accel_bound

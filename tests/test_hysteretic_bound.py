"""The optimal bound on the rig's own model: its cost over exactly the metric's window, its exact
gradient there, and its starts, none of them a law's plan, with their spread reported."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview_plan import comfort_filter
from sashil.engine.resolve import default_config
from sashil.lab.compare_metrics import cycle_times, metric_window
from sashil.lab.hysteretic_bound import STARTS, _Cost, _road_rates, _window, find_bound, model_passive
from sashil.models.hysteresis import BoucWenParams
from sashil.roads.option import RoadParts, parse_road

H = 1e-3


def _road():
    config = default_config()
    config["road"]["period_s"] = 10.0
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    return road, BoucWenParams.from_mapping(config["model"]["params"]), float(config["rig"]["coil_tau_s"])


def test_the_window_keeps_the_cycles_the_metric_keeps():
    # a run's time_s is its cycle's start in whole nanoseconds times 1e-9: cycle k at k·1 ms
    assert cycle_times(4, H).tolist() == [0.0, 0.001, 0.002, 0.003]
    # 3 s at 1 kHz with 2 s left out: cycles 2000..2999, as compare's metrics keep them
    assert int(_window(3000, 2.0, H).sum()) == 1000 and _window(3000, 2.0, H)[2000] == 1.0
    assert _window(3000, 2.0, H)[1999] == 0.0
    assert int(metric_window(cycle_times(3000, H), 0.3).sum()) == 2700
    assert int(_window(100, 5.0, H).sum()) == 1  # no longer than the settling: the last cycle alone


def test_the_cost_is_the_metrics_mean_square_after_the_settling_and_its_gradient_is_exact():
    road, params, tau = _road()
    rates = _road_rates(road, 1.5, H)
    model = BoucWenPlanModel.of(params, tau, H)
    cost = _Cost(model, rates, H, comfort_filter(20.0, H), _window(rates.size, 0.5, H))
    # at a constant current it is the model's passive run as the metric reads it
    assert math.sqrt(cost.value(np.full(rates.size, 0.6))) == pytest.approx(
        model_passive(params, 0.6, tau, road, 1.5, 0.5, bandwidth_hz=20.0), rel=1e-12
    )
    # the window's and the filter's part of the gradient, 2·F(M·F a)/m, checked where the adjoint is
    # otherwise exact: without the hysteresis (plan_boucwen's z derivatives are the exact flow's, a few
    # per cent off its Runge-Kutta steps where n is small)
    viscous = BoucWenPlanModel.of(replace(params, alpha1=0.0, alpha2=0.0), tau, H)
    cost = _Cost(viscous, rates, H, comfort_filter(20.0, H), _window(rates.size, 0.5, H))
    rng = np.random.default_rng(3)
    u = np.clip(0.5 + 0.2 * rng.standard_normal(rates.size), 0.0, 1.0)
    _, grad = cost(u)
    for k in (100, 400, 700, 1200):  # two in the settling window (only through the state they leave), two after
        step = np.zeros(rates.size)
        step[k] = 1e-5
        numeric = (cost.value(u + step) - cost.value(u - step)) / 2e-5
        assert grad[k] == pytest.approx(numeric, rel=1e-4)
    # θ̈2 inside the settling window costs nothing: the last command before it moves no kept cycle's
    # acceleration directly, only through the state it leaves
    cut = _Cost(model, rates, H, None, _window(rates.size, 0.5, H))
    whole = _Cost(model, rates, H, None, _window(rates.size, 0.0, H))
    assert cut.value(u) != whole.value(u)


def test_the_bound_comes_from_starts_no_law_made_and_reports_their_spread():
    road, params, tau = _road()
    seen = []
    bound = find_bound(params, 1.0, tau, road, 3.0, 1.0, bandwidth_hz=20.0, on_start=lambda n, v: seen.append(n))
    assert tuple(bound.starts) == STARTS == ("mid current", "best constant", "sign rule", "random smooth")
    assert seen == list(STARTS)
    # the bound is the best of them, never above the model's best constant current
    assert bound.rms_accel_bound == min(bound.starts.values())
    assert bound.rms_accel_bound < bound.rms_accel_passive
    assert bound.rms_accel_passive == pytest.approx(
        model_passive(params, bound.passive_current_a, tau, road, 3.0, 1.0, bandwidth_hz=20.0), rel=1e-12
    )
    for current in (0.0, 0.5, 1.0):  # the model's best constant current is no worse than these
        passive = model_passive(params, current, tau, road, 3.0, 1.0, bandwidth_hz=20.0)
        assert bound.rms_accel_passive <= passive * (1.0 + 1e-9)
    assert bound.spread == max(bound.starts.values()) - min(bound.starts.values())
    assert bound.spread_pct == pytest.approx(
        100.0 * bound.spread / (bound.rms_accel_passive - bound.rms_accel_bound), rel=1e-12
    )

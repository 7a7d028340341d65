"""The optimal semi-active bound: its adjoint gradient, no gain without authority, and no worse
than the best constant damping or a clairvoyant-free on-off law in the same model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.engine.resolve import default_config
from sashil.lab.optimal_bound import _forward, _gradient, envelope_cost, optimal_bound
from sashil.models.hysteresis import BoucWenParams
from sashil.roads.option import RoadParts, parse_road

H = 1e-3


def road_rate(seconds: float) -> tuple[object, np.ndarray]:
    config = default_config()
    config["road"]["period_s"] = 10.0
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    return road, np.array([road(i * H)[1] for i in range(int(seconds / H))])


def test_adjoint_gradient_matches_finite_differences():
    _, w = road_rate(2.0)
    c = np.random.default_rng(0).uniform(0.7, 2.2, w.size)
    accel, grad = np.empty(w.size), np.empty(w.size)
    f0 = _forward(c, w, 109.0, 1.0, H, 200, accel)
    _gradient(c, w, 109.0, 1.0, H, 200, accel, grad)
    for i in (150, 700, 1999):
        step = np.zeros(w.size)
        step[i] = 1e-6
        numeric = (_forward(c + step, w, 109.0, 1.0, H, 200, accel) - f0) / 1e-6
        assert grad[i] == pytest.approx(numeric, rel=1e-3, abs=1e-12)


def test_without_authority_the_bound_is_the_passive_damper():
    road, _ = road_rate(4.0)
    result = optimal_bound(BoucWenParams(c2=0.0), 1.0, road, 4.0, 1.0)
    assert result.gain_pct == pytest.approx(0.0, abs=1e-9)
    assert result.c_passive == pytest.approx(0.7)


def test_the_bound_beats_every_constant_and_an_on_off_skyhook_in_its_model():
    road, w = road_rate(6.0)
    p = BoucWenParams()
    result = optimal_bound(p, 1.0, road, 6.0, 1.0)
    first = 1000
    for c in np.linspace(0.7, 2.2, 7):
        assert result.rms_accel_bound <= math.sqrt(envelope_cost(np.full(w.size, c), w, p, H, first)) + 1e-12
    # on-off skyhook in the same envelope: c_hi when θ̇2·θ̇ > 0, c_lo otherwise
    theta = v = 0.0
    total = 0.0
    for i in range(w.size):
        c = 2.2 if v * (v - w[i]) > 0.0 else 0.7
        a = -p.k * theta - c * (v - w[i])
        total += a * a if i >= first else 0.0
        v += H * a
        theta += H * (v - w[i])
    assert result.rms_accel_bound < math.sqrt(total / (w.size - first))
    assert result.gain_pct > 5.0

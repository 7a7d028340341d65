"""The Bouc-Wen hysteretic benchmark oscillator: exact z update, interpolation, identification."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sashil.identify import boucwen_benchmark as B


@pytest.mark.parametrize("zh,dy", [(0.0, 1e-3), (-2e-4, 1e-3), (3e-4, -2e-3), (-1e-4, -5e-4)])
def test_exact_zhat_update_matches_integration(zh, dy):
    a, d = 800.0, -1100.0
    s = math.copysign(1.0, dy)
    sol = solve_ivp(
        lambda u, z: [s * (1.0 - a * s * z[0] - d * abs(z[0]))],
        (0, abs(dy)),
        [zh],
        rtol=1e-12,
        atol=1e-15,
        max_step=abs(dy) / 200,
    )
    assert B.zhat_advance(zh, dy, a, d) == pytest.approx(sol.y[0, -1], rel=1e-7, abs=1e-12)


def test_band_limited_upsample_is_exact_for_a_line():
    n = 64
    t = np.arange(n)
    x = np.sin(2 * np.pi * 5 * t / n + 0.3)
    fine = B.band_limited_upsample(x, 4)
    tf = np.arange(4 * n) / 4
    np.testing.assert_allclose(fine, np.sin(2 * np.pi * 5 * tf / n + 0.3), atol=1e-12)


def test_multisine_spec():
    u = B.multisine(1)
    spec = np.abs(np.fft.rfft(u))
    f = np.arange(spec.size) * B.FS / B.N_PERIOD
    assert np.sqrt(np.mean(u**2)) == pytest.approx(50.0)
    assert np.all(spec[(f < 5) | (f > 150)] < 1e-9 * spec.max())


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_identification_meets_benchmark_acceptance():
    u, y = B.generate(3, 3, B.NOISE_M)  # 3 periods (first discarded) keeps the test short
    fit = B.identify(u, y)
    rmse, _std = B.test_rmse(fit.params)
    assert rmse <= 2e-6
    assert fit.params["k"] == pytest.approx(5e4, rel=0.01)

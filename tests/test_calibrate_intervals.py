"""The block jackknife behind calibrate's 95 % intervals: blocks, scores, the quantities, coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.identify.data import Record
from sashil.identify.fit import FitResult
from sashil.identify.intervals import (
    block_count,
    block_labels,
    block_scores,
    bootstrap,
    covariance_intervals,
    jackknife,
    lab_quantities,
    yield_torque,
)

FREE = ("k", "c0", "fc", "f0", "c0_i", "fc_i")  # Bingham: every parameter linear, no internal state


def record(seconds: float, dt: float = 1e-3) -> Record:
    t = np.arange(0.0, seconds, dt)
    z = np.zeros_like(t)
    return Record("r", t, z, z, z, z, z, z, z)


def fake_fit(jacobian: np.ndarray, residuals: np.ndarray, x: np.ndarray) -> FitResult:
    params = {"J": 1.0, **dict(zip(FREE, map(float, x), strict=True))}
    return FitResult(
        "bingham", params, {}, {}, [], [0.0], [0.0], ["r"], 0.0, 0, {"J": 1.0}, "", [], {},
        FREE, x, residuals, jacobian,
    )  # fmt: skip


def test_blocks_cut_each_record_into_whole_blocks_and_join_a_short_tail():
    records = [record(3.0), record(0.4), record(2.6)]
    labels = block_labels(records, 1.0)
    assert labels.size == sum(r.time_s.size for r in records)
    assert block_count(records, 1.0) == 3 + 1 + 3  # 0.4 s: one block; 2.6 s: three of ~0.87 s
    assert np.all(np.diff(labels) >= 0) and np.all(np.diff(labels) <= 1)


def test_block_scores_sum_the_jacobian_times_residual_per_block():
    J = np.arange(12.0).reshape(6, 2)
    e = np.array([1.0, -1.0, 2.0, 0.5, 0.0, 1.0])
    scores = block_scores(J, e, np.array([0, 0, 1, 1, 1, 2]))
    assert scores == pytest.approx(np.array([J[0] - J[1], 2 * J[2] + 0.5 * J[3], J[5]]))


def test_lab_quantities_follow_the_seed_equations():
    p = {"J": 1.0, "k": 109.0, "c1": 0.7, "c2": 1.5, "alpha1": 1.0, "alpha2": 1.0}
    p |= {"beta": 873.0, "gamma": 1.0, "delta": 700.0, "n": 0.099}
    q = lab_quantities("bouc-wen", p, 2.0)
    zu = (700.0 / 874.0) ** (1 / 0.099)
    assert q["c_0a"] == 0.7 and q["c_max"] == pytest.approx(0.7 + 3.0)
    assert q["yield_0a"] == pytest.approx(zu) and q["yield_max"] == pytest.approx(3.0 * zu)
    assert yield_torque(p, 1.0) == pytest.approx(2.0 * zu)


def ar1_problem(rng: np.random.Generator, rows: int = 4000, phi: float = 0.98) -> tuple[np.ndarray, np.ndarray]:
    """A linear output-error problem with strongly correlated residuals (AR(1), phi 0.98)."""
    t = np.linspace(0.0, 1.0, rows)
    J = np.column_stack([np.sin(2 * np.pi * (j + 1) * t + j) + 0.2 * j for j in range(len(FREE))])
    noise = np.zeros(rows)
    shocks = rng.normal(0.0, 1e-3, rows)
    for k in range(1, rows):
        noise[k] = phi * noise[k - 1] + shocks[k]
    return J, noise


def test_jackknife_covers_with_correlated_residuals_where_the_white_covariance_does_not():
    """Linear least squares on AR(1) residuals: the estimate's error is (J^T J)^-1 J^T noise; the
    block jackknife's interval holds it about 95 % of the time, the white-residual one far less."""
    rng = np.random.default_rng(7)
    truth = np.array([100.0, 1.0, 0.5, 0.1, 2.0, 0.3])
    covered, covered_white, trials = 0, 0, 40
    records = [record(4.0)]  # 4000 samples; 0.25 s blocks: 16 blocks
    for _ in range(trials):
        J, noise = ar1_problem(rng)
        x = truth + np.linalg.lstsq(J, noise, rcond=None)[0]
        e = J @ (x - truth) - noise  # residuals at the optimum (simulated minus recorded)
        fit = fake_fit(J, e, x)
        s2 = float(e @ e) / (e.size - len(FREE))
        cov = s2 * np.linalg.inv(J.T @ J)
        fit.stderr = {n: float(math.sqrt(cov[j, j])) for j, n in enumerate(FREE)}
        fit.correlations = {a: {b: float(cov[i, j] / math.sqrt(cov[i, i] * cov[j, j])) for j, b in enumerate(FREE)}
                            for i, a in enumerate(FREE)}  # fmt: skip
        new = jackknife(fit, records, 1.0, block_s=0.25)
        old = covariance_intervals(fit, 1.0, 1.0)
        covered += new.covers("k", truth[0])
        covered_white += old.covers("k", truth[0])
    assert covered / trials >= 0.85
    assert covered_white / trials <= 0.5


def test_jackknife_is_the_delete_one_block_refit():
    """For a linear problem one Gauss-Newton step is the exact refit without the block."""
    rng = np.random.default_rng(3)
    J, noise = ar1_problem(rng, rows=2000)
    x = np.linalg.lstsq(J, noise, rcond=None)[0] + 1.0
    e = J @ (x - 1.0) - noise
    fit = fake_fit(J, e, x)
    iv = jackknife(fit, [record(2.0)], 1.0, block_s=0.5)
    assert iv.blocks == 4
    keep = np.arange(2000) >= 500  # block 0 left out: the least-squares fit to the other three
    refit = np.linalg.lstsq(J[keep], noise[keep], rcond=None)[0] + 1.0
    assert iv.samples["k"][0] == pytest.approx(refit[0], rel=1e-9)
    pseudo = iv.samples["k"]
    spread = math.sqrt(3 / 4 * np.sum((pseudo - pseudo.mean()) ** 2))
    bias = 3 * (pseudo.mean() - iv.value["k"])  # the jackknife's bias estimate (B - 1)(mean - value)
    # Student's t for B - 1 = 3 degrees of freedom: 3.182446 (tables), not the normal's 1.96
    assert iv.high["k"] - iv.value["k"] == pytest.approx(3.182446 * spread + abs(bias), rel=1e-6)
    assert iv.value["k"] - iv.low["k"] == pytest.approx(3.182446 * spread + abs(bias), rel=1e-6)


def test_bootstrap_is_deterministic_and_brackets_the_estimate():
    rng = np.random.default_rng(3)
    J, noise = ar1_problem(rng, rows=2000)
    x = np.array([100.0, 1.0, 0.5, 0.1, 2.0, 0.3])
    fit = fake_fit(J, -noise, x)
    a = bootstrap(fit, [record(2.0)], 1.0, replicates=300, block_s=0.1, seed=5)
    b = bootstrap(fit, [record(2.0)], 1.0, replicates=300, block_s=0.1, seed=5)
    assert a.low == b.low and a.high == b.high and a.blocks == 20
    assert all(a.low[n] <= a.value[n] <= a.high[n] for n in a.value)
    assert set(a.value) == {"k", *FREE}


def test_an_extra_step_never_widens_and_one_along_the_quantity_shrinks_it_most():
    from sashil.lab.calibration.extra import predicted_ratio

    rng = np.random.default_rng(11)
    J = rng.normal(size=(500, 3)) * np.array([1.0, 1.0, 0.01])  # the third direction barely pinned
    H = J.T @ J
    g = np.array([0.0, 0.0, 1.0])
    along = np.zeros((50, 3))
    along[:, 2] = 1.0
    across = np.zeros((50, 3))
    across[:, 0] = 1.0
    assert predicted_ratio(H, along, g) < 0.5 < predicted_ratio(H, across, g) <= 1.0
    assert predicted_ratio(H, np.zeros((10, 3)), g) == pytest.approx(1.0)


def test_interval_bounds_stay_physical():
    rng = np.random.default_rng(5)
    J, noise = ar1_problem(rng, rows=2000)
    x = np.array([100.0, 1e-4, 0.5, 0.1, 2.0, 1e-4])  # c0 and fc_i near their floor of 0
    iv = jackknife(fake_fit(J, 50 * noise, x), [record(2.0)], 1.0, block_s=0.25)
    assert iv.low["c0"] == 0.0 and iv.low["fc_i"] == 0.0
    assert iv.low["f0"] < 0.0  # Bingham's offset may be negative

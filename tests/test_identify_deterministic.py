"""The fit's answer depends on the data only; n above 1 is integrated safely; stale kernels are dropped."""

from __future__ import annotations

import pytest

from sashil.identify.data import record_from_columns
from sashil.identify.fit import FitOptions, fit_model
from sashil.identify.synthetic import drop_test_columns
from sashil.models._jit import refresh_stale_cache
from sashil.models.hysteresis import BoucWenParams, advance_z

SEED_DAMPER = BoucWenParams()  # seed 001: n = 0.099, the damper --model all once ranked below LuGre


@pytest.mark.parametrize("n", [1.0, 1.5, 2.0, 3.0])
def test_advance_z_with_n_above_one_from_a_tiny_z(n):
    # |z|^n underflows to 0 at |z| = 1e-200 for n > 1: the stiffness is 0 there, not a division by it
    beta, gamma, delta = 90.0, 10.0, 100.0
    z_u = (delta / (beta + gamma)) ** (1.0 / n)  # = 1
    z = advance_z(1e-200, 1e-3, beta, gamma, delta, n, z_u)
    # dz/dtheta = delta at z = 0, so one milliradian moves z by ~0.1 (slightly less: |z|^n grows)
    assert 0.09 < z <= 0.1 + 1e-12
    assert advance_z(-1e-300, -5.0, beta, gamma, delta, n, z_u) == pytest.approx(-1.0, abs=1e-6)


@pytest.fixture(scope="module")
def seed_drops():
    return [
        record_from_columns(f"{i:g} A", drop_test_columns(SEED_DAMPER, -5.0, i, duration_s=6.0)) for i in (0.0, 1.0)
    ]


@pytest.fixture(scope="module")
def seed_fit(seed_drops):
    return fit_model("bouc-wen", seed_drops, FitOptions(seed=0))


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_the_fit_does_not_depend_on_the_seed(seed_drops, seed_fit):
    again = fit_model("bouc-wen", seed_drops, FitOptions(seed=12345))
    assert again.params == seed_fit.params
    assert seed_fit.convergence["refinements"] == 2 and "converged" in seed_fit.convergence


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_bouc_wen_ranks_first_on_the_seed_damper(seed_drops, seed_fit):
    lugre = fit_model("lugre", seed_drops, FitOptions())
    assert seed_fit.rms_total < lugre.rms_total
    assert max(seed_fit.nrmse) < 0.03  # the 4096-count quantisation alone is ~1.5 %
    # the torques the drops pin down: c(i) and k
    assert seed_fit.params["k"] == pytest.approx(109.0, rel=0.01)
    for i in (0.0, 1.0):
        c = seed_fit.params["c1"] + seed_fit.params["c2"] * i
        assert c == pytest.approx(0.7 + 1.5 * i, rel=0.08)


def test_stale_numba_cache_is_dropped_when_a_kernel_source_changes(tmp_path):
    (tmp_path / "models" / "__pycache__").mkdir(parents=True)
    (tmp_path / "identify" / "__pycache__").mkdir(parents=True)
    source = tmp_path / "models" / "hysteresis.py"
    source.write_text("def advance_z(): return 1\n")
    (tmp_path / "identify" / "kernels.py").write_text("x = 1\n")
    assert refresh_stale_cache(tmp_path)  # no digest yet
    cached = [
        tmp_path / "models" / "__pycache__" / "plant.rig_substep-49.py311.1.nbc",
        tmp_path / "identify" / "__pycache__" / "kernels.simulate_rig-79.py311.nbi",
    ]
    for path in cached:
        path.write_bytes(b"compiled")
    assert not refresh_stale_cache(tmp_path)  # unchanged sources: the cache stays
    assert all(path.exists() for path in cached)
    source.write_text("def advance_z(): return 2\n")
    assert refresh_stale_cache(tmp_path)
    assert not any(path.exists() for path in cached)

"""Identification recovers known, non-seed rig parameters from simulated drop tests."""

from __future__ import annotations

import numpy as np
import pytest

from sashil.identify.data import record_from_columns
from sashil.identify.fit import FitOptions, fit_model
from sashil.identify.rig_models import MODELS, bouc_wen_rescale
from sashil.identify.synthetic import drop_test_columns
from sashil.models.hysteresis import BoucWenParams
from sashil.stats import nrmse

TRUTH = BoucWenParams(k=95.0, c1=0.5, c2=1.2, alpha1=1.3, alpha2=0.8, beta=600.0, gamma=50.0, delta=500.0, n=0.2)


@pytest.fixture(scope="module")
def drops():
    return [record_from_columns(f"{i:g} A", drop_test_columns(TRUTH, -5.0, i)) for i in (0.0, 1.0)]


@pytest.fixture(scope="module")
def bouc_wen_fit(drops):
    return fit_model("bouc-wen", drops, FitOptions())


def test_rescale_keeps_the_torque_path():
    p = TRUTH.as_dict()
    q = bouc_wen_rescale(p)
    theta = np.concatenate([np.linspace(0, -0.08, 200), np.linspace(-0.08, 0.05, 300)])
    rec = record_from_columns(
        "r", {"time_s": np.arange(theta.size) * 1e-3, "theta_rad": theta, "current_a": np.zeros(theta.size)}
    )
    zp = MODELS["bouc-wen"].state_path(p, rec)
    zq = MODELS["bouc-wen"].state_path(q, rec)
    assert q["delta"] == pytest.approx(q["beta"] + q["gamma"])  # unit bound
    np.testing.assert_allclose(p["alpha1"] * zp, q["alpha1"] * zq, rtol=1e-6, atol=1e-9)


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_recovery_of_non_seed_parameters(bouc_wen_fit):
    truth = bouc_wen_rescale(TRUTH.as_dict())
    got = bouc_wen_fit.params
    assert got["k"] == pytest.approx(truth["k"], rel=0.02)
    for i in (0.0, 1.0):
        assert got["c1"] + got["c2"] * i == pytest.approx(truth["c1"] + truth["c2"] * i, rel=0.10)
        assert got["alpha1"] + got["alpha2"] * i == pytest.approx(truth["alpha1"] + truth["alpha2"] * i, rel=0.10)
    assert got["delta"] == pytest.approx(got["beta"] + got["gamma"])  # the stated normalisation
    assert set(bouc_wen_fit.stderr) >= {"k", "c1", "c2", "alpha1", "alpha2", "beta", "gamma", "delta", "n"}


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_held_out_drop_test_prediction(bouc_wen_fit):
    cols = drop_test_columns(TRUTH, -4.0, 0.5)
    clean = drop_test_columns(TRUTH, -4.0, 0.5, counts_per_rev=0)["theta_rad"]
    sim = MODELS["bouc-wen"].simulate(bouc_wen_fit.params, record_from_columns("held", cols))
    assert nrmse(sim, clean) <= 0.02


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_bouc_wen_ranks_above_dahl_and_bingham(drops, bouc_wen_fit):
    for other in ("dahl", "bingham"):
        result = fit_model(other, drops, FitOptions())
        assert bouc_wen_fit.rms_total < result.rms_total, other


def test_passive_fit_fixes_current_terms():
    rec = [record_from_columns("0 A", drop_test_columns(TRUTH, -5.0, 0.0, duration_s=4.0))]
    result = fit_model("dahl", rec, FitOptions(passive=True))
    assert result.params["c2"] == 0.0 and result.params["kwb"] == 0.0
    assert result.fixed["c2"] == 0.0
    assert result.params["k"] == pytest.approx(95.0, rel=0.02)


@pytest.mark.e2e  # a whole simulate-and-fit identification (seconds)
def test_parameter_file_in_another_z_scale(bouc_wen_fit):
    from sashil.identify.report import param_document

    doc = param_document(bouc_wen_fit, delta=700.0)
    p = doc["params"]
    assert p["delta"] == pytest.approx(700.0)
    bound = (p["delta"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"])
    for key in ("alpha1", "alpha2"):  # the saturated hysteretic torque alpha*bound is unchanged
        assert p[key] * bound == pytest.approx(bouc_wen_fit.params[key], rel=1e-9)
    assert "delta = 700" in doc["normalisation"]

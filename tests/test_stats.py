"""The one NRMSE (sashil.stats)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.stats import nrmse


def test_nrmse_is_rms_error_over_the_spread_of_the_truth():
    truth = np.array([1.0, -1.0, 1.0, -1.0])  # std 1
    assert nrmse(truth + 0.5, truth) == pytest.approx(0.5)
    assert nrmse(truth, truth) == 0.0


def test_nrmse_does_not_shrink_with_an_offset_in_the_truth():
    truth = np.array([1.0, -1.0, 1.0, -1.0])
    assert nrmse(truth + 100.5, truth + 100.0) == pytest.approx(nrmse(truth + 0.5, truth))


def test_nrmse_leaves_out_non_finite_rows_and_is_nan_without_any():
    truth = np.array([1.0, -1.0, np.nan, 1.0, -1.0])
    estimate = np.array([1.5, -0.5, 0.0, np.inf, -0.5])
    assert nrmse(estimate, truth) == pytest.approx(0.5 / np.std([1.0, -1.0, -1.0]))
    assert math.isnan(nrmse(np.array([np.nan]), np.array([1.0])))
    assert math.isnan(nrmse(np.array([]), np.array([])))

"""Error measures shared by identification, the sweep, the reports and the tools."""

from __future__ import annotations

import math

import numpy as np


def nrmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Normalised RMS error: RMS(estimate - truth) / std(truth), over the rows where both are finite.

    Normalised by the spread of the truth (not its RMS), so an offset in the truth does not make the
    error look small. NaN when no row is finite.
    """
    e, t = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    ok = np.isfinite(e) & np.isfinite(t)
    if not ok.any():
        return math.nan
    e, t = e[ok], t[ok]
    return float(np.sqrt(np.mean((e - t) ** 2)) / max(float(np.std(t)), 1e-15))

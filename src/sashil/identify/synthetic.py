"""Drop tests from the simulated rig plant, for recovery tests and benchmarks.

The plant (:class:`sashil.models.plant.RigPlant`) is pressed to theta0 at a constant coil current,
released, and sampled every ``dt`` with the encoder's quantisation (``counts_per_rev``) and optional
seeded Gaussian angle noise: what a drop test on the simulated rig records.
"""

from __future__ import annotations

import math

import numpy as np

from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RigPlant


def drop_test_columns(
    params: BoucWenParams,
    theta0_deg: float,
    current_a: float,
    duration_s: float = 10.0,
    dt: float = 1e-3,
    counts_per_rev: int = 4096,
    noise_rad: float = 0.0,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """data.csv columns (time_s, theta_rad, current_a, current_cmd_a) of one simulated drop test."""
    plant = RigPlant(params, current_max_a=max(1.0, current_a))
    plant.state.current_a = current_a
    plant.hold(math.radians(theta0_deg))
    plant.release()
    count = int(round(duration_s / dt)) + 1
    theta = np.empty(count)
    current = np.empty(count)
    theta[0], current[0] = plant.state.theta_rad, plant.state.current_a
    for j in range(1, count):
        st = plant.step(dt, current_a)
        theta[j], current[j] = st.theta_rad, st.current_a
    if noise_rad > 0.0:
        theta = theta + np.random.default_rng(seed).normal(0.0, noise_rad, count)
    if counts_per_rev:
        q = 2.0 * math.pi / counts_per_rev
        theta = np.round(theta / q) * q
    return {
        "time_s": np.arange(count) * dt,
        "theta_rad": theta,
        "current_a": current,
        "current_cmd_a": np.full(count, float(current_a)),
    }

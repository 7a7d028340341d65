"""Simulating a parameter file's model on given inputs (the core of ``sashil simulate``)."""

from __future__ import annotations

import math

import numpy as np

from sashil.identify.data import record_from_columns
from sashil.identify.rig_models import MODELS


def drop_test_inputs(theta0_deg: float, current_a: float, duration_s: float, dt: float = 1e-3) -> dict[str, np.ndarray]:
    """Input columns of a drop test: held at theta0, released at t = 0, constant current."""
    count = int(round(duration_s / dt)) + 1
    t = np.arange(count) * dt
    theta = np.zeros(count)
    theta[0] = math.radians(theta0_deg)
    return {"time_s": t, "theta_rad": theta, "current_a": np.full(count, current_a)}


def simulate_columns(
    model: str, params: dict[str, float], inputs: dict[str, np.ndarray], start_at_rest: bool = True
) -> dict[str, np.ndarray]:
    """data.csv columns of the model driven by ``inputs`` (time_s, current_a, optional theta_road_rad,
    torque_in_nm; theta_rad's first sample is the initial angle)."""
    columns = dict(inputs)
    if "current_a" not in columns:
        columns["current_a"] = columns.get("current_cmd_a", np.zeros_like(columns["time_s"]))
    record = record_from_columns("input", columns, start_at_rest)
    theta = MODELS[model].simulate(params, record)
    out = {
        "time_s": record.time_s,
        "theta_rad": theta,
        "current_a": record.current,
        "current_cmd_a": np.asarray(columns.get("current_cmd_a", record.current), dtype=float),
    }
    for name in ("theta_road_rad", "torque_in_nm"):
        if name in inputs:
            out[name] = np.asarray(inputs[name], dtype=float)
    return out

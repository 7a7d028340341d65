"""The compiled simulator uses a record's input torque, road-side motion and moving start like the plant."""

from __future__ import annotations

import math

import numpy as np

from sashil.identify.data import record_from_columns
from sashil.identify.rig_models import MODELS
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RigPlant

TRUTH = BoucWenParams(k=95.0, c1=0.5, c2=1.2, alpha1=1.3, alpha2=0.8, beta=600.0, gamma=50.0, delta=500.0, n=0.2)


def _run(plant: RigPlant, seconds: float, current: float, road=None, torque=None):
    t, th, i, th1, tin = [], [], [], [], []
    for j in range(int(seconds * 1000) + 1):
        if j:
            plant.step(1e-3, current)
        st = plant.state
        t.append(st.time_s)
        th.append(st.theta_rad)
        i.append(st.current_a)
        th1.append(road(st.time_s)[0] if road else 0.0)
        tin.append(torque(st.time_s) if torque else 0.0)
    return {
        "time_s": np.array(t),
        "theta_rad": np.array(th),
        "current_a": np.array(i),
        "theta_road_rad": np.array(th1),
        "torque_in_nm": np.array(tin),
    }


def test_input_torque_column_drives_the_simulation():
    torque = lambda t: 3.0 * math.sin(2 * math.pi * 2.0 * t)  # noqa: E731
    plant = RigPlant(TRUTH, torque_in=torque)
    plant.state.current_a = 0.3
    cols = _run(plant, 3.0, 0.3, torque=torque)
    sim = MODELS["bouc-wen"].simulate(TRUTH.as_dict(), record_from_columns("tin", cols))
    assert np.sqrt(np.mean((sim - cols["theta_rad"]) ** 2)) < 0.01 * np.std(cols["theta_rad"])
    cols["torque_in_nm"][:] = 0.0  # without the torque the prediction is wrong: the column is used
    sim0 = MODELS["bouc-wen"].simulate(TRUTH.as_dict(), record_from_columns("none", cols))
    assert np.sqrt(np.mean((sim0 - cols["theta_rad"]) ** 2)) > 0.5 * np.std(cols["theta_rad"])


def test_road_angle_column_drives_the_simulation():
    w = 2 * math.pi * 1.5
    road = lambda t: (0.03 * math.sin(w * t), 0.03 * w * math.cos(w * t), -0.03 * w * w * math.sin(w * t))  # noqa: E731
    plant = RigPlant(TRUTH, road=road)
    cols = _run(plant, 3.0, 0.0, road=road)
    sim = MODELS["bouc-wen"].simulate(TRUTH.as_dict(), record_from_columns("road", cols))
    assert np.sqrt(np.mean((sim - cols["theta_rad"]) ** 2)) < 0.02 * np.std(cols["theta_rad"])


def test_moving_start_estimates_the_initial_velocity():
    plant = RigPlant(TRUTH)
    plant.state.theta_rad, plant.state.theta_dot_rad_s = 0.0, 0.4
    cols = _run(plant, 2.0, 0.0)
    record = record_from_columns("moving", cols, start_at_rest=False)
    assert abs(record.v0 - 0.4) < 0.02
    assert record.initial_state_sign() == 1.0
    assert record_from_columns("rest", cols).v0 == 0.0

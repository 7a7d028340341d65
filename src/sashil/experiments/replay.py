"""Replay: a recorded run's sensor stream through a controller, offline.

Each recorded row becomes the :class:`~sashil.drivers.interface.RigSample` the loop read (encoder
counts back from ``theta_rad``/``theta_road_rad``, the measured ``current_a``, ``seq``, the device
time and each encoder's last edge when the run recorded them), with the
period the loop measured (``time_s`` differences) and the road speed the run commanded on the row
before (the controller's road feed-forward). The controller's estimator, observer, law and inverse
run as in the loop, on these samples; what it would have commanded (T*, i*, T̂) goes beside what
was commanded.

It is open loop: the recorded plant responded to the recorded commands, not to the replayed ones.
Replaying the run's own law and config reproduces its commands; another law's commands say what
that law would have asked for in the states the run went through, never what would have happened.
The run's last row (the shutdown's 0 A, after the last cycle) and rows the safety supervisor
changed (``trip_code`` not 0) are marked, not replayed as the controller's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sashil.control.controller import Controller
from sashil.drivers.interface import NO_EDGE, RigSample
from sashil.errors import DataFileError

#: what a replay needs of a recorded data.csv
REQUIRED = ("time_s", "theta_rad", "current_a", "seq")
#: what it writes beside the recorded columns
REPLAY_COLUMNS = ("replay_torque_cmd_nm", "replay_current_cmd_a", "replay_torque_hat_nm", "replay_z_hat")
#: the sample's integer fields a run records beside the angles (absent in older runs: no edges)
EDGE_FIELDS = ("device_time_us", "arm_edge_us", "arm_edge_dir", "road_edge_us", "road_edge_dir")
_ABSENT = {"device_time_us": 0, "arm_edge_us": NO_EDGE, "arm_edge_dir": 0, "road_edge_us": NO_EDGE, "road_edge_dir": 0}
TWO_PI = 2.0 * math.pi


def check_columns(data: dict[str, np.ndarray], where: str) -> None:
    """DataFileError naming the columns a replay needs that ``data`` lacks."""
    missing = [name for name in REQUIRED if name not in data]
    if missing:
        raise DataFileError(
            f"{where}: no column {', '.join(missing)} (a replay needs {', '.join(REQUIRED)}; "
            "runs recorded by `sashil run` have them)"
        )


def replay(controller: Controller, data: dict[str, np.ndarray], counts_per_rev: int) -> dict[str, np.ndarray]:
    """The controller's outputs for every recorded row (NaN on the shutdown row); ``replayed``: 1
    for a row the controller stepped on, 0 for the shutdown row."""
    time_s = data["time_s"]
    n = time_s.size
    theta = data["theta_rad"]
    road = data.get("theta_road_rad", np.zeros(n))
    current = data["current_a"]
    seq = data["seq"]
    road_cmd = data.get("road_speed_cmd_rad_s")
    fields = {
        name: np.asarray(data[name], dtype=np.int64) if name in data else np.full(n, _ABSENT[name], dtype=np.int64)
        for name in EDGE_FIELDS
    }
    device_us, arm_edge, arm_dir = fields["device_time_us"], fields["arm_edge_us"], fields["arm_edge_dir"]
    road_edge, road_dir = fields["road_edge_us"], fields["road_edge_dir"]
    scale = counts_per_rev / TWO_PI
    out = {name: np.full(n, np.nan) for name in REPLAY_COLUMNS}
    replayed = np.zeros(n)
    # the stream ends on the shutdown's safe-state row: the last cycle's sample again, at 0 A
    last = n - 1 if n > 1 and seq[-1] == seq[-2] else n
    t_ns = np.rint(time_s * 1e9).astype(np.int64)
    prev_ns = 0
    for k in range(last):
        road_counts = int(round(road[k] * scale))
        sample = RigSample(
            seq=int(seq[k]),
            time_ns=int(t_ns[k]),
            device_time_us=int(device_us[k]),
            arm_counts=int(round(theta[k] * scale)) + road_counts,
            road_counts=road_counts,
            current_a=float(current[k]),
            flags=0,
            counts_per_rev=counts_per_rev,
            arm_edge_us=int(arm_edge[k]),
            arm_edge_dir=int(arm_dir[k]),
            road_edge_us=int(road_edge[k]),
            road_edge_dir=int(road_dir[k]),
        )
        if road_cmd is not None and k:
            speed = float(road_cmd[k - 1])
            controller.command.road_speed_rad_s = speed if math.isfinite(speed) else None
        controller.step(sample, int(t_ns[k]), int(t_ns[k] - prev_ns))
        prev_ns = int(t_ns[k])
        out["replay_torque_cmd_nm"][k] = controller.torque_cmd_nm
        out["replay_current_cmd_a"][k] = controller.current_cmd_a
        out["replay_torque_hat_nm"][k] = controller.torque_hat_nm
        out["replay_z_hat"][k] = controller.z_hat
        replayed[k] = 1.0
    out["replayed"] = replayed
    return out


def differences(data: dict[str, np.ndarray], out: dict[str, np.ndarray]) -> dict[str, Any]:
    """How the replayed commands differ from the recorded ones, over the replayed rows the safety
    supervisor did not change: RMS and largest difference of i* and T*, and the rows compared."""
    use = out["replayed"] > 0
    if "trip_code" in data:
        use &= data["trip_code"] == 0
    result: dict[str, Any] = {
        "rows_compared": int(use.sum()),
        "rows_supervised": int((out["replayed"] > 0).sum() - use.sum()),
    }
    for recorded, replayed, key in (
        ("current_cmd_a", "replay_current_cmd_a", "current_cmd_a"),
        ("torque_cmd_nm", "replay_torque_cmd_nm", "torque_cmd_nm"),
    ):
        if recorded not in data:
            continue
        diff = out[replayed][use] - data[recorded][use]
        diff = diff[np.isfinite(diff)]
        result[key] = (
            {"rms": float(np.sqrt(np.mean(diff**2))), "max_abs": float(np.max(np.abs(diff)))} if diff.size else None
        )
    return result


__all__ = ["REPLAY_COLUMNS", "REQUIRED", "check_columns", "differences", "replay"]

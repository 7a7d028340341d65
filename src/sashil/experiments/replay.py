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
The run's last row (the shutdown's 0 A, after the last cycle), the rows read at 0 A while the
coil settled after a stop (``phase`` -1) and rows the safety supervisor changed (``trip_code`` not
0) are marked, not replayed as the controller's. A run whose law was
tuned live (``events.csv``) is replayed with the same changes at the same cycles.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sashil.control.controller import Controller
from sashil.drivers.interface import NO_EDGE, RigSample
from sashil.errors import DataFileError
from sashil.runtime.loop import SETTLE_PHASE
from sashil.runtime.tuning import EVENT_COLUMNS, LiveTuning

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


def recorded_changes(path: Path) -> dict[int, tuple[dict[str, Any], float]]:
    """The live parameter changes of a run's ``events.csv`` (:mod:`sashil.runtime.tuning`) that a
    cycle applied: ``{cycle: ({param: value}, ramp_s)}``; {} when the run has none. Values are read
    as YAML, as the command line gave them. DataFileError naming the file for a malformed one."""
    if not path.is_file():
        return {}
    changes: dict[int, tuple[dict[str, Any], float]] = {}
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        missing = [name for name in EVENT_COLUMNS if name not in (reader.fieldnames or ())]
        if missing:
            raise DataFileError(f"{path}: no column {', '.join(missing)} (expected {', '.join(EVENT_COLUMNS)})")
        for line, row in enumerate(reader, start=2):
            if row["status"] != "applied":
                continue
            try:
                cycle, ramp_s, value = int(row["cycle"]), float(row["ramp_s"]), yaml.safe_load(row["new"])
            except (ValueError, yaml.YAMLError):
                raise DataFileError(f"{path}: line {line}: expected a cycle, a ramp in s and a value") from None
            values, ramp = changes.get(cycle, ({}, 0.0))
            values[row["key"]] = value
            changes[cycle] = (values, max(ramp, ramp_s))
    return changes


def replay(
    controller: Controller,
    data: dict[str, np.ndarray],
    counts_per_rev: int,
    changes: Mapping[int, tuple[dict[str, Any], float]] | None = None,
    rate_hz: float = 1000.0,
) -> dict[str, np.ndarray]:
    """The controller's outputs for every recorded row (NaN on the shutdown row); ``replayed``: 1
    for a row the controller stepped on, 0 for the shutdown row. ``changes``: live parameter
    changes to re-apply at their cycles (:func:`recorded_changes`), through the same hand-off as
    the live loop (ramps at ``rate_hz``, the run's loop rate)."""
    tuning = LiveTuning(controller.law, rate_hz) if changes else None
    time_s = data["time_s"]
    n = time_s.size
    seq = data["seq"]
    fields = {
        name: np.asarray(data[name], dtype=np.int64) if name in data else np.full(n, _ABSENT[name], dtype=np.int64)
        for name in EDGE_FIELDS
    }
    device_us, arm_edge, arm_dir, road_edge, road_dir = (fields[name].tolist() for name in EDGE_FIELDS)
    scale = counts_per_rev / TWO_PI
    # the encoder counts back from the recorded angles, whole columns at once (rint: the same
    # half-to-even rounding as the counts were divided from); Python lists index fastest per row
    road_counts = np.rint(data.get("theta_road_rad", np.zeros(n)) * scale).astype(np.int64)
    arm_counts = (np.rint(data["theta_rad"] * scale).astype(np.int64) + road_counts).tolist()
    road_list = road_counts.tolist()
    current = data["current_a"].astype(float).tolist()
    seq_list = seq.astype(np.int64).tolist()
    t_ns = np.rint(time_s * 1e9).astype(np.int64).tolist()
    time_list = time_s.tolist()
    road_cmd = data.get("road_speed_cmd_rad_s")
    speeds = None if road_cmd is None else [v if math.isfinite(v) else None for v in road_cmd.tolist()]
    # the stream ends on the shutdown's safe-state row (the last sample again, at 0 A), after a stop
    # on the rows read while the coil settled at 0 A: no law ran in either
    last = n - 1 if n > 1 and seq[-1] == seq[-2] else n
    if "phase" in data:
        settling = np.flatnonzero(np.asarray(data["phase"]) == SETTLE_PHASE)
        if settling.size:
            last = int(settling[0])
    torque_cmd, current_cmd, torque_hat, z_hat = [], [], [], []
    command = controller.command
    step = controller.step
    prev_ns = 0
    for k in range(last):
        now_ns = t_ns[k]
        sample = RigSample(
            seq_list[k], now_ns, device_us[k], arm_counts[k], road_list[k], current[k], 0, counts_per_rev,
            arm_edge[k], arm_dir[k], road_edge[k], road_dir[k],
        )  # fmt: skip
        if speeds is not None and k:
            command.road_speed_rad_s = speeds[k - 1]
        if tuning is not None:
            change = changes.get(k) if changes is not None else None
            if change is not None:
                tuning.post(*change)
            if tuning.busy:
                tuning.service(time_list[k], k)
        step(sample, now_ns, now_ns - prev_ns)
        prev_ns = now_ns
        torque_cmd.append(controller.torque_cmd_nm)
        current_cmd.append(controller.current_cmd_a)
        torque_hat.append(controller.torque_hat_nm)
        z_hat.append(controller.z_hat)
    out = {}
    for name, values in zip(REPLAY_COLUMNS, (torque_cmd, current_cmd, torque_hat, z_hat), strict=True):
        column = np.full(n, np.nan)
        column[:last] = values
        out[name] = column
    replayed = np.zeros(n)
    replayed[:last] = 1.0
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

"""Running one plan step on the rig: the one adapter between calibrate and the experiment code.

A step is a drop test (:func:`sashil.lab._drop_test.run_drop_test`: hold, release, record;
on the simulated rig the backend plays the operator, on the emulator ``--hold-deg`` does (with
``--prompts``, at the angle the host's prompt asks), on the bench a person) whose "controller"
(:class:`~sashil.plans.calibration_step.StepStage`, built again where the drop's loop runs)
commands the step's constant current and, from the release on, the road wheel's speed for a road
step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.drivers.interface import TWO_PI
from sashil.errors import SashilError
from sashil.identify.road import held_speed
from sashil.lab._drop_test import DropRecord, run_drop_test
from sashil.plans.calibration_step import Step, StepStage, StuckEncoderError
from sashil.plans.drop import CONTROLLER_COLUMNS

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

#: a record whose angle spans fewer encoder counts than this did not move
MIN_COUNTS_MOVED = 4


@dataclass
class StepResult:
    step: Step
    columns: dict[str, np.ndarray]
    hold_angle_deg: float
    release_estimated: bool
    error: SashilError | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def on_device_clock(record: DropRecord, road: bool) -> dict[str, np.ndarray]:
    """The record on the device's clock: each row's time is the device time of its sample (the
    instant the board sampled the encoders) minus the device time at the release, and its ``seq``
    is the sample's sequence number. Over a link the host's times carry the link's latency jitter
    (rows 0.03-11 ms apart at 1 kHz on a busy machine), which an output-error fit reads as
    dynamics; a repeated sample (a link gap) is dropped. A road step (``road``) adds the wheel
    speed commanded in each row's cycle (``road_speed_cmd_rad_s``) and the road encoder's last edge
    as each sample carried it, on the same clock (``road_edge_s``: NaN none; ``road_edge_dir``
    +1/-1, 0 none): where the board's wheel was, and when. All from the runner's stream."""
    columns = {k: v for k, v in record.data.items() if k not in CONTROLLER_COLUMNS}
    stream = record.stream
    if columns["time_s"].size == 0 or "device_time_us" not in stream or record.device_release_s is None:
        return columns
    t = stream["device_time_us"] * 1e-6 - record.device_release_s
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    out = {k: v[keep] for k, v in columns.items()}
    out["time_s"] = t[keep]
    if road:
        out["road_speed_cmd_rad_s"] = held_speed(stream["road_speed_cmd_rad_s"])[keep]
        if "road_edge_us" in stream:
            edge_us = np.asarray(stream["road_edge_us"], dtype=float)
            edge_s = np.where(edge_us >= 0.0, edge_us * 1e-6 - record.device_release_s, np.nan)
            out["road_edge_s"] = edge_s[keep]
            out["road_edge_dir"] = np.asarray(stream["road_edge_dir"])[keep].astype(np.int64)
    return out


def run_step(run: RunSpec, step: Step, data_path: str | Path | None = None) -> StepResult:
    """Run one step on the run's rig (``run``: the calibration's assembled run); errors that end it early are in ``result.error`` (the rig is
    already at 0 A), with the data up to them. A record that never moved is a StuckEncoderError.
    ``data_path``: where the runner streams the step's every cycle as it runs."""
    stage = StepStage(step)
    record = run_drop_test(run, step.theta0_deg, step.current_a, step.duration_s, controller=stage, data_path=data_path)
    columns = on_device_clock(record, step.road is not None)
    error = record.error
    counts = run.stage.counts_per_rev
    theta = columns.get("theta_rad", np.zeros(0))
    if error is None and (theta.size == 0 or np.ptp(theta) < MIN_COUNTS_MOVED * TWO_PI / counts):
        error = StuckEncoderError(
            f"{step.name}: the arm did not move after the release (the angle spans "
            f"{np.ptp(theta) * counts / TWO_PI if theta.size else 0:.0f} encoder counts): a stuck encoder or a blocked arm"
        )
    extra: dict[str, Any] = {}
    if record.metrics is not None:
        extra["metrics"] = record.metrics.as_dict()
    for key in ("link", "loop_process"):  # the link's statistics; the loop process that ran the step
        if key in record.extra:
            extra[key] = record.extra[key]
    if record.summary:
        extra["trips"] = record.summary["trips"]
    return StepResult(step, columns, math.degrees(record.hold_angle_rad), record.release_estimated, error, extra)

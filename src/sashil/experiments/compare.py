"""``sashil compare``: each law on the same road through the one runner, and its metrics.

A :class:`LawJob` is one law's run: its label, its checked config (``controller.law`` and its
parameters), the road spec, the duration and its run folder. :func:`run_job` builds the law's stage
(:func:`sashil.control.registry.make_stage`: the controller, or a constant-current stage for a law
that reads no state, such as ``passive``), wraps it in the road
(:class:`~sashil.experiments.road_option.RoadStage`: the road motor's speed each cycle), runs it with
:func:`sashil.runtime.runner.run_plan`, streaming every cycle into the folder's ``data.csv`` (and
its loop timing into ``timing.npz``), and derives the metrics from the stream. A job is picklable,
so on the simulated rig jobs may run in parallel processes; the caller writes each folder's
``config.yaml`` before and its ``summary.json`` after (:attr:`LawResult.summary`).

Metrics, after ``compare.settle_s``:

* comfort: RMS of the arm's angular acceleration θ̈2 low-passed at ``compare.accel_bandwidth_hz``
  (4th-order Butterworth, forward and back). On a simulated rig θ̈2 is the plant's own,
  (−k·θ − T)/J of its true state (seed 001 eq. 13), recorded every cycle as
  ``arm_accel_true_rad_s2``; on any other rig it is the arm angle θ2 = θ + θ1 of the encoders,
  differentiated twice after the low-pass, on a uniform grid of the samples' own device time (a
  link loses samples and repeats one when a cycle reads nothing new; a grid of the rows would read
  those as jumps) (a 4096-count encoder adds a floor of about 0.9 rad/s² RMS in quadrature at
  20 Hz, the same for every law);
* travel: RMS of the relative angle θ;
* peak measured current, and the energy to the coil R·∫i² dt (R = ``compare.coil_resistance_ohm``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil import engine
from sashil.config.parts import StageParts
from sashil.control.registry import make_stage
from sashil.drivers import open_rig
from sashil.drivers.interface import capabilities_of
from sashil.engine import assemble
from sashil.experiments.road_option import RoadParts, RoadStage, parse_road
from sashil.recording.run_folder import RunFolder
from sashil.runtime.loop import stage_signals

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["LawJob", "LawResult", "MeasuredStage", "metrics_of", "run_job"]

#: seconds of arm acceleration kept for the time-trace plot, and its decimation
TRACE_S = 5.0
TRACE_DECIMATE = 5


@dataclass
class LawJob:
    """One law's run (picklable: a process runs it on the simulated rig)."""

    label: str
    config: RunConfig
    road: str
    duration_s: float
    #: the law's run folder (created, its config.yaml written): data.csv and timing.npz go there
    folder: str | None = None


@dataclass
class LawResult:
    """A law's metrics (NaN when it did not finish), its status and what the plots show."""

    label: str
    status: str = "ok"
    metrics: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    psd_f: list[float] = field(default_factory=list)
    psd: list[float] = field(default_factory=list)
    trace_t: list[float] = field(default_factory=list)
    trace: list[float] = field(default_factory=list)
    #: where θ̈2 came from: "plant" (a simulated rig's true state) or "encoders"
    accel_source: str = ""
    #: the runner's common summary keys of the law's run (timing, trips, controller_stats, ...)
    summary: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


METRICS = (
    "rms_accel_rad_s2",
    "rms_theta_deg",
    "peak_current_a",
    "coil_energy_j",
)


class MeasuredStage:
    """A loop stage that runs ``stage`` and records the true arm acceleration θ̈2 = (−k·θ − T)/J
    (seed 001 eq. 13) of a rig that reports it (its capability ``true_torque``: a simulated plant) as
    ``arm_accel_true_rad_s2`` (NaN on any other rig)."""

    def __init__(self, stage: Any, rig: Any):

        self.stage = stage
        self._truth = rig if rig is not None and capabilities_of(rig).true_torque else None
        self.signal_names = (*stage_signals(stage), "arm_accel_true_rad_s2")
        self.arm_accel_true_rad_s2 = math.nan

    def __getattr__(self, name: str) -> Any:  # the inner stage's signals
        if name == "stage":
            raise AttributeError(name)
        return getattr(self.stage, name)

    def step(self, sample: Any, t_ns: int, dt_ns: int) -> Any:
        if self._truth is not None:
            self.arm_accel_true_rad_s2 = self._truth.plant_truth().arm_accel_rad_s2
        return self.stage.step(sample, t_ns, dt_ns)


def arm_acceleration(stream: dict[str, Any], rate_hz: float, bandwidth_hz: float) -> tuple[np.ndarray, str]:
    """θ̈2 [rad/s²] low-passed at ``bandwidth_hz``: the plant's own when the stream has it, else from
    the encoders (θ2 = θ + θ1, low-passed, differentiated twice); and which it is."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, min(bandwidth_hz, 0.45 * rate_hz), fs=rate_hz, output="sos")

    def smooth(x: np.ndarray) -> np.ndarray:
        return np.asarray(sosfiltfilt(sos, x)) if x.size > 30 else x

    true = np.asarray(stream.get("arm_accel_true_rad_s2", ()), dtype=float)
    if true.size and np.all(np.isfinite(true)):
        return smooth(true), "plant"
    theta2 = np.asarray(stream["theta_rad"], dtype=float) + np.asarray(stream["theta_road_rad"], dtype=float)
    dt = 1.0 / rate_hz
    sampled = sample_times(stream)
    if sampled is None:
        return np.asarray(np.gradient(np.gradient(smooth(theta2), dt), dt)), "encoders"
    # a link's samples are taken on the device's clock, with gaps where samples were lost and a
    # cycle that read no new sample repeating the last: differentiate on a uniform grid of the
    # device's time, then read the result back at every row
    from scipy.interpolate import CubicSpline

    times, first = sampled
    grid = np.arange(times[0], times[-1] + 0.5 * dt, dt)
    grid = grid[grid <= times[-1]]
    on_grid = CubicSpline(times, theta2[first])(grid)  # a lost sample's gap bridged smoothly
    accel = np.gradient(np.gradient(smooth(on_grid), dt), dt)
    row_times = np.interp(np.arange(theta2.size), first, times)
    return np.asarray(np.interp(row_times, grid, accel)), "encoders"


def sample_times(stream: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """Each distinct sample's device time [s] (rising) and the row that first carried it, from the
    stream's ``seq`` and ``device_time_us``; None when the stream has no device clock (a simulated
    rig's rows are its samples, evenly spaced)."""
    device = np.asarray(stream.get("device_time_us", ()), dtype=float)
    seq = np.asarray(stream.get("seq", ()), dtype=float)
    if device.size < 3 or seq.size != device.size or not np.all(np.isfinite(device)) or not np.any(device):
        return None
    first = np.flatnonzero(np.r_[True, np.diff(seq) != 0])
    times = device[first] * 1e-6
    keep = np.r_[True, np.diff(times) > 0]  # a clock that did not advance adds nothing
    first, times = first[keep], times[keep]
    if times.size < 3:
        return None
    return times, first


def metrics_of(stream: dict[str, Any], config: RunConfig) -> tuple[dict[str, float], np.ndarray, np.ndarray, str]:
    """The metrics of a law's stream (module docstring), its time and θ̈2 after the settling, and
    where θ̈2 came from."""
    rate = float(config["loop"]["rate_hz"])
    section = config["compare"]
    time_s = np.asarray(stream["time_s"], dtype=float)[:-1]  # the last row is the shutdown's safe state
    accel, source = arm_acceleration(
        {k: np.asarray(v)[:-1] for k, v in stream.items()}, rate, float(section["accel_bandwidth_hz"])
    )
    keep = time_s >= float(section["settle_s"])
    if not np.any(keep):
        raise ValueError("nothing recorded after compare.settle_s")
    theta = np.asarray(stream["theta_rad"], dtype=float)[:-1][keep]
    current = np.asarray(stream["current_a"], dtype=float)[:-1][keep]
    current = np.where(np.isfinite(current), current, 0.0)
    a = accel[keep]
    rms_a = float(np.sqrt(np.mean(a * a)))
    metrics = {
        "rms_accel_rad_s2": rms_a,
        "rms_theta_deg": math.degrees(float(np.sqrt(np.mean(theta * theta)))),
        "peak_current_a": float(np.max(current)),
        "coil_energy_j": float(section["coil_resistance_ohm"]) * float(np.sum(current * current)) / rate,
    }
    return metrics, time_s[keep], a, source


def _stage(config: RunConfig) -> Any:
    return make_stage(StageParts.read(config))[1]


def run_job(job: LawJob) -> LawResult:
    """Run one law on the road (on the clock the config's backend runs on) and measure it; a law
    that fails, trips or stops gets a result saying why instead of metrics."""
    from scipy.signal import welch

    config = job.config
    result = LawResult(job.label, metrics=dict.fromkeys(METRICS, math.nan))
    folder = RunFolder(Path(job.folder), "compare") if job.folder is not None else None
    start = time.perf_counter()
    try:
        road, _ = parse_road(job.road, RoadParts.read(config))
        stage = _stage(config)
        if road is not None:
            stage = RoadStage(stage, road, job.duration_s)
        spec = assemble(config)
        rig = open_rig(spec.rig)
        outcome = engine.run(
            spec,
            MeasuredStage(stage, rig),
            job.duration_s,
            rig=lambda: rig,
            data_path=folder.file("data.csv") if folder is not None else None,
            realtime=False,
            say=lambda _: None,
        )
    except Exception as err:  # a law that cannot even start: its row says why
        result.status = f"failed: {type(err).__name__}: {(str(err).splitlines() or [''])[0]}"
        result.wall_s = time.perf_counter() - start
        return result
    result.wall_s = time.perf_counter() - start
    result.summary = dict(outcome.summary)
    if folder is not None:
        folder.write_timing(outcome.timing)
    if outcome.error is not None or outcome.exit_status != "ok":
        trips = "; ".join(str(trip.get("reason", trip)) for trip in outcome.trips)
        why = trips or outcome.summary["error"] or outcome.stop_reason or outcome.exit_status
        result.status = f"{outcome.exit_status}: {why}"
        return result
    try:
        metrics, t, accel, result.accel_source = metrics_of(outcome.stream, config)
    except (KeyError, ValueError) as err:
        result.status = f"no metrics: {err}"
        return result
    result.metrics = metrics
    rate = float(config["loop"]["rate_hz"])
    f, pxx = welch(accel, fs=rate, nperseg=min(accel.size, int(8 * rate)))
    band = f <= 4.0 * float(config["compare"]["accel_bandwidth_hz"])
    result.psd_f, result.psd = f[band].tolist(), pxx[band].tolist()
    window = t <= t[0] + TRACE_S
    result.trace_t = t[window][::TRACE_DECIMATE].tolist()
    result.trace = accel[window][::TRACE_DECIMATE].tolist()
    return result

"""Road-side excitation sweeps: a linear chirp and a stepped sine with its transmissibility table.

The road/wheel-side angle follows theta1(t) = A(t)*sin(phi(t)) (like the seed's wheel speed-up
through the ~1.6 Hz resonance), A(t) rising over ``ramp_s`` with a raised cosine:

* chirp: phi(t) = 2*pi*(f0*t + (f1 - f0)*t^2/(2*T)), instantaneous frequency f0 -> f1 over T;
* stepped sine: phi(t) = 2*pi*f*t per frequency, ``settle_s`` to reach the steady state, then
  ``measure_s`` (rounded up to whole periods) over which the body (arm) angle theta2 = theta +
  theta1 and the road angle are measured; transmissibility = RMS(theta2) / RMS(theta1) (RMS about
  the mean). Then the amplitude ramps back to 0 over ``ramp_s``, so that a rig that stays up
  between frequencies starts the next one at rest.

Every cycle's command carries ``road_speed_rad_s = theta1_dot(t)``, which every backend's road
motor obeys (a real rig's, the emulator's and the simulated rig's road wheel). The simulated rig runs on the virtual clock unless the config asks
for the real one; a link (serial, CAN: the emulator or the bench) runs on the real clock with the
loop's real-time set-up, as a drop test does. Each row records the sample's sequence number
(``seq``, as on the wire), so a link run joins with the emulator's ``--truth`` file.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sashil.drivers.interface import TWO_PI, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.models.plant import RoadProfile
from sashil.runtime.clock import Clock
from sashil.runtime.runner import run_plan
from sashil.stats import nrmse

#: data.csv columns of a sweep (docs/architecture.md names; torque_true_nm only on the simulated rig), then ``seq``
SWEEP_COLUMNS = (
    "time_s",
    "theta_rad",
    "theta_road_rad",
    "current_a",
    "current_cmd_a",
    "theta_dot_rad_s",
    "z_hat",
    "torque_hat_nm",
    "torque_cmd_nm",
    "torque_true_nm",
)


def _envelope(t: float, ramp_s: float) -> tuple[float, float, float]:
    """Raised-cosine ramp e(t) from 0 to 1 over ramp_s, with e' and e''."""
    if ramp_s <= 0.0 or t >= ramp_s:
        return 1.0, 0.0, 0.0
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    w = math.pi / ramp_s
    return 0.5 - 0.5 * math.cos(w * t), 0.5 * w * math.sin(w * t), 0.5 * w * w * math.cos(w * t)


def _profile(
    amplitude_rad: float,
    ramp_s: float,
    phase: Callable[[float], tuple[float, float, float]],
    stop_s: float | None = None,
) -> RoadProfile:
    """A(t)*sin(phi(t)) with A(t) = A*e(t): e ramps up over ``ramp_s`` and, from ``stop_s`` on,
    back down over ``ramp_s`` (the product rule gives the rate and acceleration)."""

    def road(t: float) -> tuple[float, float, float]:
        e, de, dde = _envelope(t, ramp_s)
        if stop_s is not None and t > stop_s:
            r, dr, ddr = _envelope(t - stop_s, ramp_s)
            e, de, dde = e * (1.0 - r), de * (1.0 - r) - e * dr, dde * (1.0 - r) - 2.0 * de * dr - e * ddr
        p, dp, ddp = phase(t)
        s, c = math.sin(p), math.cos(p)
        a = amplitude_rad
        return (a * e * s, a * (de * s + e * c * dp), a * (dde * s + 2.0 * de * c * dp + e * (c * ddp - s * dp * dp)))

    return road


def chirp_profile(
    amplitude_rad: float, f_start_hz: float, f_stop_hz: float, duration_s: float, ramp_s: float = 1.0
) -> RoadProfile:
    """theta1(t) = A*sin(2*pi*(f0*t + (f1 - f0)*t^2/(2*T))), frequency held at f1 after T."""
    rate = (f_stop_hz - f_start_hz) / duration_s

    def phase(t: float) -> tuple[float, float, float]:
        if t <= duration_s:
            return TWO_PI * (f_start_hz * t + 0.5 * rate * t * t), TWO_PI * (f_start_hz + rate * t), TWO_PI * rate
        end = TWO_PI * (f_start_hz * duration_s + 0.5 * rate * duration_s**2)
        return end + TWO_PI * f_stop_hz * (t - duration_s), TWO_PI * f_stop_hz, 0.0

    return _profile(amplitude_rad, ramp_s, phase)


def sine_profile(amplitude_rad: float, f_hz: float, ramp_s: float = 1.0, stop_s: float | None = None) -> RoadProfile:
    """theta1(t) = A(t)*sin(2*pi*f*t); from ``stop_s`` on the amplitude ramps back to 0."""
    w = TWO_PI * f_hz
    return _profile(amplitude_rad, ramp_s, lambda t: (w * t, w, 0.0), stop_s)


def frequencies(f_start_hz: float, f_stop_hz: float, steps: int, spacing: str = "linear") -> list[float]:
    if spacing == "log":
        return [float(f) for f in np.geomspace(f_start_hz, f_stop_hz, steps)]
    return [float(f) for f in np.linspace(f_start_hz, f_stop_hz, steps)]


#: the controller's per-cycle values a sweep records (the controller's attributes, docs/architecture.md names)
CONTROLLER_SIGNALS = ("theta_dot_rad_s", "z_hat", "torque_hat_nm", "torque_cmd_nm")


class SweepStage:
    """Loop stage: run ``controller`` (any stage with the controller's attributes) and command the
    road speed. It keeps no data: the runner's stream records every cycle, with the controller's
    signals and the true damper torque of a rig that reports it (``torque_true_nm``: a simulated
    plant's, its capability ``true_torque``; NaN elsewhere)."""

    def __init__(self, controller: Any, road: RoadProfile, rig: RigInterface | None = None):
        self.controller = controller
        #: the controller's signals (a current law's own output, current_law_a, too) and the true torque
        self.signal_names = (*getattr(controller, "signal_names", CONTROLLER_SIGNALS), "torque_true_nm")
        self.road = road
        self._truth = rig if rig is not None and capabilities_of(rig).true_torque else None
        self.torque_true_nm = math.nan
        self._t0: int | None = None

    def __getattr__(self, name: str) -> Any:  # the controller's signals (NaN for a stage without them)
        if name in CONTROLLER_SIGNALS or name == "current_law_a":
            return getattr(self.__dict__["controller"], name, math.nan)
        raise AttributeError(name)

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        if self._t0 is None:
            self._t0 = t_ns
        t = (t_ns - self._t0) * 1e-9
        if self._truth is not None:
            self.torque_true_nm = self._truth.plant_truth().damper_torque_nm
        cmd = self.controller.step(sample, t_ns, dt_ns)
        cmd.road_speed_rad_s = self.road(t)[1]
        return cmd


def sweep_columns(stream: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """:data:`SWEEP_COLUMNS`, a current law's own output (``current_law_a``) when the stream has it,
    and ``seq`` (int64) of a sweep's stream."""
    if not stream:
        return {name: np.zeros(0) for name in SWEEP_COLUMNS} | {"seq": np.zeros(0, dtype=np.int64)}
    names = (*SWEEP_COLUMNS, "current_law_a") if "current_law_a" in stream else SWEEP_COLUMNS
    return {name: stream[name] for name in names} | {"seq": stream["seq"].astype(np.int64)}


RigFactory = Callable[[dict, RoadProfile], RigInterface]


def default_rig(config: dict[str, Any], road: RoadProfile) -> RigInterface:
    """The rig a sweep runs on: the config's backend, whose road motor gets the profile's speed
    from the sweep's commands (the simulated rig's road wheel as a board's)."""
    from sashil.drivers import open_rig

    return open_rig(config)


def run_profile(
    config: dict[str, Any],
    controller: Any,
    road: RoadProfile,
    duration_s: float,
    rig_factory: RigFactory | None = None,
    clock: Clock | None = None,
    keep: Callable[[dict[str, np.ndarray]], object] | None = None,
    data_path: str | Path | None = None,
) -> dict[str, np.ndarray]:
    """One run of ``controller`` under the road profile through the one runner
    (:func:`~sashil.runtime.runner.run_plan`: safety, signals, real-time set-up on the real clock,
    the road at rest and 0 A at the end); returns the recorded columns.

    Clock: ``clock``, else the config's (:func:`~sashil.experiments.drop_test.default_clock`: the
    virtual one for the simulated rig, the real one for a link). ``keep`` gets the columns recorded
    so far however the run ends (a link fault, a safety trip, a stop), before the error
    propagates. ``data_path``: the runner streams every cycle there as it runs. A signal ends the
    run cleanly and raises :class:`~sashil.errors.Stopped` (exit 130) after ``keep``.
    """
    from sashil.experiments.drop_test import default_clock

    rig = (rig_factory or default_rig)(config, road)
    stage = SweepStage(controller, road, rig)
    clock = clock if clock is not None else default_clock(config)
    log = logging.getLogger("sashil")
    outcome = run_plan(
        config,
        rig,
        stage,
        clock,
        duration_s,
        data_path=data_path,
        say=log.warning,
        note=log.debug,
        read_stream=True,
    )
    columns = sweep_columns(outcome.stream)
    if keep is not None:
        keep(columns)
    if outcome.error is not None:
        raise outcome.error
    outcome.raise_stop()
    return columns


def ac_rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean((x - x.mean()) ** 2))) if x.size else math.nan


@dataclass
class SteppedPoint:
    frequency_hz: float
    body_rms_rad: float
    road_rms_rad: float
    transmissibility: float
    observer_nrmse: float  # T-hat against the true plant torque (sim only, else NaN)
    clipped_cycles: int


def stepped_sine(
    config: dict[str, Any],
    make_controller: Callable[[], Any],
    freqs: list[float],
    rig_factory: RigFactory | None = None,
    keep: Callable[[float, dict[str, np.ndarray]], None] | None = None,
    stream_to: Callable[[float], Path] | None = None,
) -> list[SteppedPoint]:
    """Transmissibility per frequency: a fresh controller and rig per frequency (``sweep`` section).
    ``keep(frequency_hz, columns)`` gets each frequency's time series once it has run;
    ``stream_to(frequency_hz)``: the file the runner streams that frequency's cycles to."""
    sweep = config["sweep"]
    amplitude = math.radians(sweep["amplitude_deg"])
    points = []
    for f in freqs:
        measure = math.ceil(sweep["measure_s"] * f) / f
        start = sweep["ramp_s"] + sweep["settle_s"]
        controller = make_controller()
        # the road ramps down after the measurement: a rig that stays up between frequencies (a link)
        # starts the next one at rest instead of with a step of the road speed
        stop = start + measure
        cols = run_profile(
            config,
            controller,
            sine_profile(amplitude, f, sweep["ramp_s"], stop),
            stop + sweep["ramp_s"],
            rig_factory,
            data_path=stream_to(f) if stream_to is not None else None,
        )
        if keep is not None:
            keep(f, cols)
        window = (cols["time_s"] >= start - 1e-9) & (cols["time_s"] < stop - 1e-9)
        body = cols["theta_rad"][window] + cols["theta_road_rad"][window]
        road = cols["theta_road_rad"][window]
        body_rms, road_rms = ac_rms(body), ac_rms(road)
        points.append(
            SteppedPoint(
                f,
                body_rms,
                road_rms,
                body_rms / road_rms if road_rms > 0 else math.nan,
                nrmse(cols["torque_hat_nm"][window], cols["torque_true_nm"][window]),
                int(getattr(controller, "clip_count", 0)),
            )
        )
    return points

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

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil import engine
from sashil.control.registry import make_controller
from sashil.drivers import open_rig, rig_parts
from sashil.drivers.interface import TWO_PI, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.engine import assemble
from sashil.models.plant import RoadProfile
from sashil.runtime.clock import Clock
from sashil.stats import nrmse

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.config.typed import RunConfig

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


@dataclass(frozen=True)
class SweepRoad:
    """A sweep's road profile and what it was made from (:func:`road_of` makes it again: a loop
    process builds the same road from the spec)."""

    spec: dict[str, Any]
    profile: RoadProfile

    def __call__(self, t: float) -> tuple[float, float, float]:
        return self.profile(t)


def road_of(spec: dict[str, Any]) -> SweepRoad:
    """The road of a :class:`SweepRoad`'s ``spec`` (``shape`` chirp or sine and its arguments)."""
    shapes: dict[str, Callable[..., SweepRoad]] = {"chirp": chirp_profile, "sine": sine_profile}
    arguments = {key: value for key, value in spec.items() if key != "shape"}
    return shapes[spec["shape"]](**arguments)


def chirp_profile(
    amplitude_rad: float, f_start_hz: float, f_stop_hz: float, duration_s: float, ramp_s: float = 1.0
) -> SweepRoad:
    """theta1(t) = A*sin(2*pi*(f0*t + (f1 - f0)*t^2/(2*T))), frequency held at f1 after T."""
    rate = (f_stop_hz - f_start_hz) / duration_s

    def phase(t: float) -> tuple[float, float, float]:
        if t <= duration_s:
            return TWO_PI * (f_start_hz * t + 0.5 * rate * t * t), TWO_PI * (f_start_hz + rate * t), TWO_PI * rate
        end = TWO_PI * (f_start_hz * duration_s + 0.5 * rate * duration_s**2)
        return end + TWO_PI * f_stop_hz * (t - duration_s), TWO_PI * f_stop_hz, 0.0

    spec = {"shape": "chirp", "amplitude_rad": amplitude_rad, "f_start_hz": f_start_hz, "f_stop_hz": f_stop_hz}
    return SweepRoad({**spec, "duration_s": duration_s, "ramp_s": ramp_s}, _profile(amplitude_rad, ramp_s, phase))


def sine_profile(amplitude_rad: float, f_hz: float, ramp_s: float = 1.0, stop_s: float | None = None) -> SweepRoad:
    """theta1(t) = A(t)*sin(2*pi*f*t); from ``stop_s`` on the amplitude ramps back to 0."""
    w = TWO_PI * f_hz
    spec = {"shape": "sine", "amplitude_rad": amplitude_rad, "f_hz": f_hz, "ramp_s": ramp_s, "stop_s": stop_s}
    return SweepRoad(spec, _profile(amplitude_rad, ramp_s, lambda t: (w * t, w, 0.0), stop_s))


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
    plant's, its capability ``true_torque``; NaN elsewhere). The stage that runs, given its rig
    (:meth:`attach_rig`), hands the road to come to the controller, for a law that reads the road ahead
    (``duration_s``: how long it will be commanded, None: until stopped)."""

    def __init__(self, controller: Any, road: RoadProfile, duration_s: float | None = None):
        self.controller = controller
        self.duration_s = duration_s
        #: the controller is the config's law: a loop process can make its own (:meth:`spec`)
        self.from_config = False
        #: the controller's signals (a current law's own output, current_law_a, too) and the true torque
        self.signal_names = (*getattr(controller, "signal_names", CONTROLLER_SIGNALS), "torque_true_nm")
        self.road = road
        self._truth: RigInterface | None = None
        self.torque_true_nm = math.nan
        self._t0: int | None = None
        #: what the loop process's twin of this stage counted (:meth:`absorb`), None: it ran here
        self.seen: dict[str, Any] | None = None

    def __getattr__(self, name: str) -> Any:  # the controller's signals (NaN for a stage without them)
        if name in CONTROLLER_SIGNALS or name == "current_law_a":
            return getattr(self.__dict__["controller"], name, math.nan)
        raise AttributeError(name)

    def attach_rig(self, rig: RigInterface) -> None:
        """Meet the rig this stage runs on, before its loop starts: its true damper torque recorded
        when it reports one, and the road to come handed to the controller."""
        self._truth = rig if capabilities_of(rig).true_torque else None
        attach = getattr(self.controller, "attach_road", None)
        if attach is not None:
            road = self.road
            attach(lambda t: road(t)[1], self.duration_s)

    def spec(self) -> dict[str, Any] | None:
        """What a loop process builds this run from (the config's law on the same road:
        :func:`sweep_stage`), or None when it cannot (a controller not the config's law, a road
        without a spec)."""
        if not self.from_config or not isinstance(self.road, SweepRoad):
            return None
        return {"kind": "sweep", "road": self.road.spec, "duration_s": self.duration_s}

    def facts(self) -> dict[str, Any]:
        """The controller's counts after the run (its clipped cycles, its summary statistics)."""
        stats = getattr(self.controller, "stats", None)
        return {"clip_count": int(getattr(self.controller, "clip_count", 0)), "stats": stats() if stats else None}

    def absorb(self, facts: dict[str, Any]) -> None:
        """Take the :meth:`facts` of the same run in the loop process (:attr:`clip_count`, :meth:`stats`)."""
        self.seen = facts

    @property
    def clip_count(self) -> int:
        """The controller's clipped cycles (as the loop process's controller counted them, when it ran there)."""
        seen = self.__dict__.get("seen")
        return int(seen["clip_count"]) if seen is not None else int(getattr(self.controller, "clip_count", 0))

    def stats(self) -> dict[str, Any] | None:
        """The controller's summary statistics (the loop process's controller's, when it ran there)."""
        seen = self.__dict__.get("seen")
        if seen is not None:
            return seen["stats"]
        stats = getattr(self.controller, "stats", None)
        return stats() if stats is not None else None

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


RigFactory = Callable[["RunConfig", RoadProfile], RigInterface]


def sweep_stage(run: RunSpec, rig: RigInterface) -> SweepStage:
    """A sweep run's stage built in a loop process: the run's law on the road of its plan, for
    ``duration_s`` of it."""
    stage = SweepStage(make_controller(None, run.stage), road_of(run.plan["road"]), run.plan.get("duration_s"))
    stage.attach_rig(rig)
    return stage


def sweep_in_loop(run: RunSpec, rig: RigInterface, prompt: Callable[[str], None]) -> tuple[SweepStage, str, str]:
    """One run of a sweep built in a loop process (the ``sweep`` plan of ``sashil.plans``: a chirp,
    or one frequency of a stepped sine): the run's law on the road of its plan (``run.plan``)."""
    return sweep_stage(run, rig), run.stage.law, str(run.plan["road"].get("shape"))


def default_rig(config: RunConfig, road: RoadProfile) -> RigInterface:
    """The rig a sweep runs on: the config's backend, whose road motor gets the profile's speed
    from the sweep's commands (the simulated rig's road wheel as a board's)."""
    return open_rig(rig_parts(config))


def run_profile(
    config: RunConfig,
    controller: Any,
    road: RoadProfile,
    duration_s: float,
    rig_factory: RigFactory | None = None,
    clock: Clock | None = None,
    keep: Callable[[dict[str, np.ndarray]], object] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
) -> dict[str, np.ndarray]:
    """One run of ``controller`` under the road profile (:func:`run_sweep`); the recorded columns."""
    columns, _ = run_sweep(
        config, controller, road, duration_s, rig_factory, clock, keep, data_path, live=live, stop=stop
    )
    return columns


def run_sweep(
    config: RunConfig,
    controller: Any,
    road: RoadProfile,
    duration_s: float,
    rig_factory: RigFactory | None = None,
    clock: Clock | None = None,
    keep: Callable[[dict[str, np.ndarray]], object] | None = None,
    data_path: str | Path | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    law_of_config: bool = False,
) -> tuple[dict[str, np.ndarray], SweepStage]:
    """One run of ``controller`` under the road profile through the one runner
    (:func:`~sashil.runtime.runner.run_plan`: safety, signals, real-time set-up on the real clock,
    the road at rest and 0 A at the end); returns the recorded columns and the run's stage (its
    :attr:`~SweepStage.clip_count` and :meth:`~SweepStage.stats`).

    ``law_of_config``: ``controller`` is the config's law, so on the real clock with
    ``loop.process`` a loop process can run the same stage of its own (:func:`sweep_stage`; the
    road a :class:`SweepRoad`); ``rig_factory`` then goes unused. Clock: ``clock``, else the
    config's (:func:`~sashil.runtime.clock.default_clock`: the virtual one for the simulated
    rig, the real one for a link). ``keep`` gets the columns recorded so far however the run ends
    (a link fault, a safety trip, a stop), before the error propagates. ``data_path``: the runner
    streams every cycle there as it runs. ``live``: views of the stream (``start(stream, timing)``,
    ``close(trips, notes)``); ``stop``: a :class:`~sashil.runtime.signals.StopFlag` another thread
    may set. A signal or a stop ends the run cleanly and raises :class:`~sashil.errors.Stopped`
    (exit 130) after ``keep``; the error that ended a run carries its ``safe_state`` (how the coil
    settled at 0 A after a stop).
    """
    run = assemble(config)
    stage = SweepStage(controller, road, duration_s)
    stage.from_config = law_of_config
    outcome = engine.run(
        run,
        stage,
        duration_s,
        clock=clock,
        rig=lambda: (rig_factory or default_rig)(config, road),
        data_path=data_path,
        live=live,
        stop=stop,
    )
    if live is not None:
        live.close(outcome.trips, ())
    columns = sweep_columns(outcome.stream)
    if keep is not None:
        keep(columns)
    ended = outcome.error if outcome.error is not None else outcome.stop_error()
    if ended is not None:
        ended.safe_state = outcome.safe_state  # type: ignore[attr-defined]  # the run's summary row shows it
        raise ended
    return columns, stage


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
    config: RunConfig,
    make_controller: Callable[[], Any],
    freqs: list[float],
    rig_factory: RigFactory | None = None,
    keep: Callable[[float, dict[str, np.ndarray]], None] | None = None,
    stream_to: Callable[[float], Path] | None = None,
    *,
    live: Any = None,
    stop: Any = None,
    law_of_config: bool = False,
) -> list[SteppedPoint]:
    """Transmissibility per frequency: a fresh controller and rig per frequency (``sweep`` section).
    ``keep(frequency_hz, columns)`` gets each frequency's time series once it has run;
    ``stream_to(frequency_hz)``: the file the runner streams that frequency's cycles to; ``live``
    and ``stop``: each frequency's run's views and stop flag; ``law_of_config``: ``make_controller``
    makes the config's law (:func:`run_sweep`)."""
    sweep = config["sweep"]
    amplitude = math.radians(sweep["amplitude_deg"])
    points = []
    for f in freqs:
        measure = math.ceil(sweep["measure_s"] * f) / f
        start = sweep["ramp_s"] + sweep["settle_s"]
        controller = make_controller()
        # the road ramps down after the measurement: a rig that stays up between frequencies (a link)
        # starts the next one at rest instead of with a step of the road speed
        stop_s = start + measure
        cols, stage = run_sweep(
            config,
            controller,
            sine_profile(amplitude, f, sweep["ramp_s"], stop_s),
            stop_s + sweep["ramp_s"],
            rig_factory,
            data_path=stream_to(f) if stream_to is not None else None,
            live=live,
            stop=stop,
            law_of_config=law_of_config,
        )
        if keep is not None:
            keep(f, cols)
        window = (cols["time_s"] >= start - 1e-9) & (cols["time_s"] < stop_s - 1e-9)
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
                stage.clip_count,
            )
        )
    return points

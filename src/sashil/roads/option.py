"""``sashil run --road``: road-side excitation θ1(t) of a closed-loop run.

``--road sine:F_HZ[:AMP_DEG]`` (a sine, raised-cosine ramp of ``sweep.ramp_s``),
``--road chirp:F0_HZ:F1_HZ:SECONDS[:AMP_DEG]`` (a linear chirp, then F1 held), ``--road FILE.csv``
(a recorded or designed profile: columns ``time_s`` and ``theta_road_rad``, linearly interpolated,
held at its last angle after its end; e.g. another run's ``data.csv``),
``--road iso8608:CLASS[:SPEED_M_S]`` (an ISO 8608 road of class A-H at ``road.speed_m_s``, through
the rig's geometry ``road.lever_m``, seeded by ``road.seed``: :mod:`sashil.roads.iso8608`),
``--road bump:HEIGHT_DEG`` (a raised-cosine bump of ``road.bump_width_s`` at ``road.bump_start_s``)
or ``--road none``; the amplitude defaults to ``sweep.amplitude_deg``. On the simulated rig with no ``--road`` the run
gets :data:`DEFAULT_SIM_ROAD`, so a first run shows the arm moving instead of a flat line.

On the simulated rig the profile drives the plant's road angle directly; over a link
(:class:`RoadStage`) every cycle's command carries the profile's road speed θ̇1 for the rig's road
motor, as ``sashil sweep`` does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from sashil.config.parts import read_keys
from sashil.drivers.interface import RigCommand, RigSample
from sashil.errors import ConfigError, DataFileError
from sashil.models.plant import RoadProfile
from sashil.recording.data_file import read_data_csv
from sashil.roads.iso8608 import CLASSES, bump_profile, iso8608_height, periodic_profile
from sashil.roads.profiles import chirp_profile, sine_profile
from sashil.roads.syntax import DEFAULT_SIM_ROAD, SYNTAX

__all__ = ["DEFAULT_SIM_ROAD", "SYNTAX", "RoadParts", "RoadStage", "parse_road"]


@dataclass(frozen=True)
class RoadParts:
    """What a ``--road`` value is made into a profile with: the loop's rate, the ``sweep`` section's
    ramp and amplitude, and the ``road`` section's geometry and generator."""

    rate_hz: float
    ramp_s: float
    amplitude_deg: float
    lever_m: float
    speed_m_s: float
    seed: int
    period_s: float
    bump_width_s: float
    bump_start_s: float

    #: the config keys a road is made with (``{field: dotted key}``), as a backend declares its own
    READS: ClassVar[Mapping[str, str]] = {
        "rate_hz": "loop.rate_hz",
        "ramp_s": "sweep.ramp_s",
        "amplitude_deg": "sweep.amplitude_deg",
        "lever_m": "road.lever_m",
        "speed_m_s": "road.speed_m_s",
        "seed": "road.seed",
        "period_s": "road.period_s",
        "bump_width_s": "road.bump_width_s",
        "bump_start_s": "road.bump_start_s",
    }

    @classmethod
    def of(cls, values: Mapping[str, Any]) -> RoadParts:
        """The parts among ``values`` (a run's ``options`` that include :attr:`READS`): the seed a
        whole number, the rest numbers."""
        numbers = {name: float(values[name]) for name in cls.READS if name != "seed"}
        return cls(seed=int(values["seed"]), **numbers)

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> RoadParts:
        """The parts of a resolved config, by :attr:`READS`."""
        return cls.of(read_keys(config, cls.READS, "road parts"))


def parse_road(text: str | None, parts: RoadParts) -> tuple[RoadProfile | None, str]:
    """``(profile, description)`` of a ``--road`` value (``(None, "none")`` for ``none``)."""
    if text is None or text.strip() == "none":
        return None, "none"
    if text.strip().endswith(".csv"):
        return file_profile(text.strip())
    kind, _, rest = text.strip().partition(":")
    if kind == "iso8608":
        return iso8608_road(text, rest, parts)
    try:
        values = [float(part) for part in rest.split(":")] if rest else []
    except ValueError:
        raise ConfigError(f"--road {text}: expected {SYNTAX}") from None
    if not all(math.isfinite(v) for v in values):
        raise ConfigError(f"--road {text}: expected finite numbers ({SYNTAX})")
    nyquist = parts.rate_hz / 10
    ramp = parts.ramp_s
    if kind == "sine" and len(values) in (1, 2):
        f_hz, amp_deg = values[0], values[1] if len(values) == 2 else parts.amplitude_deg
        _check(text, f_hz, amp_deg, nyquist)
        return sine_profile(math.radians(amp_deg), f_hz, ramp), f"sine {f_hz:g} Hz, {amp_deg:g} deg"
    if kind == "chirp" and len(values) in (3, 4):
        f0, f1, seconds = values[:3]
        amp_deg = values[3] if len(values) == 4 else parts.amplitude_deg
        _check(text, f0, amp_deg, nyquist)
        _check(text, f1, amp_deg, nyquist)
        if not seconds > 0:
            raise ConfigError(f"--road {text}: expected a chirp length in seconds > 0, got {seconds:g}")
        return (
            chirp_profile(math.radians(amp_deg), f0, f1, seconds, ramp),
            f"chirp {f0:g}-{f1:g} Hz over {seconds:g} s, {amp_deg:g} deg",
        )
    if kind == "bump" and len(values) == 1:
        height = values[0]
        if not 0.0 < abs(height) <= 20.0:
            raise ConfigError(f"--road {text}: expected a bump height in [-20, 20] deg, not 0, got {height:g}")
        width, start = parts.bump_width_s, parts.bump_start_s
        return bump_profile(math.radians(height), width, start), f"bump {height:g} deg over {width:g} s at {start:g} s"
    raise ConfigError(f"--road {text}: expected {SYNTAX}")


def iso8608_road(text: str, rest: str, parts: RoadParts) -> tuple[RoadProfile, str]:
    """``iso8608:CLASS[:SPEED_M_S]``: the class's road at the speed (default ``road.speed_m_s``)
    through ``road.lever_m``, one period of ``road.period_s`` at the loop's rate, faded in over
    ``sweep.ramp_s``."""
    road_class, _, speed_text = rest.partition(":")
    road_class = road_class.strip().upper()
    if road_class not in CLASSES:
        raise ConfigError(f"--road {text}: expected an ISO 8608 road class A-H, got {road_class or 'none'!r}")
    speed = parts.speed_m_s
    if speed_text:
        try:
            speed = float(speed_text)
        except ValueError:
            raise ConfigError(f"--road {text}: expected a speed in m/s after the class, got {speed_text!r}") from None
    if not (math.isfinite(speed) and 0.0 < speed <= 100.0):
        raise ConfigError(f"--road {text}: expected a speed in (0, 100] m/s, got {speed:g}")
    height = iso8608_height(road_class, speed, parts.period_s, parts.rate_hz, parts.seed)
    lever = parts.lever_m
    profile = periodic_profile(height / lever, parts.rate_hz, parts.ramp_s)
    return profile, f"ISO 8608 class {road_class} at {speed:g} m/s (lever {lever:g} m, seed {parts.seed})"


def file_profile(path: str) -> tuple[RoadProfile, str]:
    """The road profile of a CSV file (``time_s``, ``theta_road_rad``), from its first sample on."""
    try:
        cols = read_data_csv(path, required=("time_s", "theta_road_rad"), min_rows=2)
    except DataFileError as err:
        raise ConfigError(f"--road {err}") from None
    t = cols["time_s"] - cols["time_s"][0]
    theta = cols["theta_road_rad"]
    if not np.all(np.isfinite(theta)) or np.max(np.abs(theta)) > math.radians(20.0):
        raise ConfigError(f"--road {path}: theta_road_rad: expected finite angles within ±20 deg")
    rate = np.gradient(theta, t)
    accel = np.gradient(rate, t)
    end = float(t[-1])

    def road(time_s: float) -> tuple[float, float, float]:
        if time_s >= end:
            return float(theta[-1]), 0.0, 0.0
        return (
            float(np.interp(time_s, t, theta)),
            float(np.interp(time_s, t, rate)),
            float(np.interp(time_s, t, accel)),
        )

    return road, f"profile {path} ({end:g} s)"


def _check(text: str, f_hz: float, amp_deg: float, nyquist: float) -> None:
    if not 0.0 < f_hz <= nyquist:
        raise ConfigError(f"--road {text}: expected a frequency in (0, {nyquist:g}] Hz, got {f_hz:g}")
    if not 0.0 < amp_deg <= 20.0:
        raise ConfigError(f"--road {text}: expected an amplitude in (0, 20] deg, got {amp_deg:g}")


class RoadStage:
    """A loop stage that runs ``stage`` and adds the road speed θ̇1(t) to each of its commands
    (for a rig whose road motor takes speed commands). Its recorded signals are ``stage``'s.

    The road to come is known here, so a stage that takes it (a controller:
    ``attach_road(speed, duration_s)``) is given it before the run, for a law that reads the road
    ahead; ``duration_s``: how long the run will command it (None: until stopped)."""

    def __init__(self, stage: Any, road: RoadProfile, duration_s: float | None = None):
        self.stage = stage
        self.road = road
        self._t0: int | None = None
        attach = getattr(stage, "attach_road", None)
        if attach is not None:
            attach(lambda t: road(t)[1], duration_s)

    def __getattr__(self, name: str) -> Any:  # the inner stage's signals (theta_dot_rad_s, z_hat, ...)
        if name == "stage":
            raise AttributeError(name)
        return getattr(self.stage, name)

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        if self._t0 is None:
            self._t0 = t_ns
        cmd = self.stage.step(sample, t_ns, dt_ns)
        if cmd is not None:
            cmd.road_speed_rad_s = self.road((t_ns - self._t0) * 1e-9)[1]
        return cmd

"""What the rtdac backend writes to the coil's power stage and the road motor: pure math, no I/O.

sashil commands a coil current; the RT-DAC gives a PWM duty or a D/A voltage. :class:`CoilDrive`
turns the current into that output through the power stage's calibration map (piecewise linear),
and, where an A/D senses the coil current, corrects it with an integral loop on the sensed current.
:class:`RoadDrive` closes the road motor's loop on the road encoder, as sashil's own board does on
its side: the commanded road speed integrates into a reference angle, and the output is the speed's
feed-forward (led by the motor's lag: a first-order motor's inverse) plus a gain on the angle's
error; it keeps the tracking error's statistics and says when its output sits at a bound.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def interp(x: float, xs: Sequence[float], ys: Sequence[float]) -> float:
    """Piecewise-linear ``ys`` at ``x`` over rising ``xs``, held at the ends."""
    if x <= xs[0]:
        return ys[0]
    for i in range(1, len(xs)):
        if x <= xs[i]:
            span = xs[i] - xs[i - 1]
            return ys[i] if span <= 0.0 else ys[i - 1] + (ys[i] - ys[i - 1]) * (x - xs[i - 1]) / span
    return ys[-1]


class CoilDrive:
    """The coil current's output (module docstring); ``ki_per_s`` 0 or no sense: the map alone.

    The loop compares the sensed current with the current the command gives through the coil's
    first-order lag (``tau_s``, seed 001's coil model), not with the command itself, so a command's
    step does not wind it up: what it integrates is the power stage's static mismatch with the map.
    Its authority is bounded: its correction is at most ``authority`` times the commanded current, and
    the output stays within ``rest + (1 ± authority)·(map - rest)`` of the map's output for the
    command, so a sense that reads nothing (or too much) moves the coil at most that far from the
    map; :attr:`at_authority` says the correction asked for passed that bound this cycle (a power
    stage further off its map than the authority, or a sense that disagrees with the coil).
    """

    def __init__(
        self,
        map_current_a: Sequence[float],
        map_output: Sequence[float],
        ki_per_s: float,
        authority: float = 0.25,
        tau_s: float = 0.0,
    ):
        self.map_current_a = tuple(map_current_a)
        self.map_output = tuple(map_output)
        self.ki_per_s = ki_per_s
        self.authority = authority
        self.rest = self.map_output[0]
        self.tau_s = tau_s
        self.at_authority = False
        self._integral_a = 0.0
        self._expected_a = 0.0

    def reset(self) -> None:
        self._integral_a = 0.0
        self._expected_a = 0.0
        self.at_authority = False

    def output(self, current_a: float, sensed_a: float | None, dt_s: float) -> float:
        """The output for ``current_a`` (0, below or NaN: rest); the loop integrates the error of the
        sensed current (None or NaN: not sensed) against the lagged command over ``dt_s``, within the
        authority bound (class docstring)."""
        self.at_authority = False
        if not current_a > 0.0:  # 0 A, below it, or NaN: rest, the loop's correction forgotten
            self._integral_a = 0.0
            self._lag(0.0, dt_s)
            return self.rest
        expected = self._lag(current_a, dt_s)
        planned = interp(current_a, self.map_current_a, self.map_output)
        if sensed_a is None or sensed_a != sensed_a:
            return planned
        step = self.ki_per_s * (expected - sensed_a) * min(dt_s, 0.01)
        limit = self.authority * current_a  # the loop's authority, as a current
        wanted = self._integral_a + step
        self._integral_a = min(max(wanted, -limit), limit)  # held at the bound: no wind-up past it
        self.at_authority = self._integral_a != wanted  # the correction asked for passes the authority
        out = interp(current_a + self._integral_a, self.map_current_a, self.map_output)
        span = self.authority * (planned - self.rest)  # the output's bound too, whatever the map's shape
        return min(max(out, planned - span), planned + span)

    def _lag(self, current_a: float, dt_s: float) -> float:
        """The current ``current_a`` gives through the coil's first-order lag, advanced by ``dt_s``."""
        if self.tau_s > 0.0:
            self._expected_a += (1.0 - math.exp(-dt_s / self.tau_s)) * (current_a - self._expected_a)
        else:
            self._expected_a = current_a  # no lag: the command itself
        return self._expected_a


class RoadDrive:
    """The road motor's loop on its encoder (module docstring).

    ``limit`` bounds the output's magnitude; ``reverses`` False (a one-direction PWM output) bounds it
    below by 0, so a negative output (a brake the wiring cannot give) is rest, never forward drive.
    Each cycle leaves :attr:`error_rad` (the angle error, NaN with no road commanded) and
    :attr:`at_limit` (the output held at a bound) for the safety supervisor.
    """

    def __init__(
        self,
        output_per_rad_s: float,
        kp_per_rad: float,
        limit: float,
        rest: float = 0.0,
        lag_s: float = 0.0,
        reverses: bool = True,
    ):
        self.output_per_rad_s = output_per_rad_s
        self.kp_per_rad = kp_per_rad
        #: the motor's time constant: its speed lags its output as a first-order system would, so the
        #: feed-forward leads it by lag_s times the commanded speed's rate of change
        self.lag_s = lag_s
        self._last_speed: float | None = None
        self.limit = limit
        self.reverses = reverses
        self.rest = rest
        self.speed_rad_s: float | None = None
        self.reference_rad: float | None = None
        self.error_rad = math.nan
        self.at_limit = False
        self.error_count = 0
        self.error_sq_sum = 0.0
        self.error_max_rad = 0.0
        self.limit_cycles = 0

    def command(self, speed_rad_s: float | None) -> None:
        """The road speed from now on (None or NaN: unchanged)."""
        if speed_rad_s is not None and speed_rad_s == speed_rad_s:
            self.speed_rad_s = speed_rad_s

    def stop(self) -> None:
        """No road command: the motor's output at rest, the reference forgotten."""
        self.speed_rad_s = None
        self.reference_rad = None
        self._last_speed = None
        self.error_rad = math.nan
        self.at_limit = False

    def output(self, road_angle_rad: float, dt_s: float) -> float:
        """The motor's output (volts or a signed duty) at the measured road angle; rest when no road
        speed was ever commanded."""
        speed = self.speed_rad_s
        if speed is None:
            self.at_limit = False
            return self.rest
        accel = 0.0
        if self.reference_rad is None:
            self.reference_rad = road_angle_rad
        else:
            self.reference_rad += speed * dt_s
            if self._last_speed is not None and dt_s > 0.0:
                accel = (speed - self._last_speed) / dt_s
        self._last_speed = speed
        error = self.reference_rad - road_angle_rad
        self.error_rad = error
        self.error_count += 1
        self.error_sq_sum += error * error
        self.error_max_rad = max(self.error_max_rad, abs(error))
        out = (speed + self.lag_s * accel) * self.output_per_rad_s + self.kp_per_rad * error
        low = -self.limit if self.reverses else 0.0
        held = min(max(out, low), self.limit)
        self.at_limit = held != out
        if self.at_limit:
            self.limit_cycles += 1
        return held

    def tracking(self) -> dict[str, float | int]:
        """How well the road followed its reference: RMS and largest angle error [rad], cycles, and
        the cycles its output was held at a limit."""
        n = self.error_count
        return {
            "road_cycles": n,
            "road_error_rms_rad": round(math.sqrt(self.error_sq_sum / n), 6) if n else 0.0,
            "road_error_max_rad": round(self.error_max_rad, 6),
            "road_limit_cycles": self.limit_cycles,
        }

"""What the rtdac backend writes to the coil's power stage and the road motor: pure math, no I/O.

sashil commands a coil current; the RT-DAC gives a PWM duty or a D/A voltage. :class:`CoilDrive`
turns the current into that output through the power stage's calibration map (piecewise linear),
and, where an A/D senses the coil current, corrects it with an integral loop on the sensed current.
:class:`RoadDrive` closes the road motor's loop on the road encoder, as sashil's own board does on
its side: the commanded road speed integrates into a reference angle, and the output is the speed's
feed-forward (led by the motor's lag: a first-order motor's inverse) plus a gain on the angle's
error; it keeps the tracking error's statistics.
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
    """The coil current's output (module docstring); ``ki_per_s`` 0 or no sense: the map alone."""

    def __init__(
        self, map_current_a: Sequence[float], map_output: Sequence[float], ki_per_s: float, current_max_a: float
    ):
        self.map_current_a = tuple(map_current_a)
        self.map_output = tuple(map_output)
        self.ki_per_s = ki_per_s
        self.current_max_a = current_max_a
        self.rest = self.map_output[0]
        self._integral_a = 0.0

    def reset(self) -> None:
        self._integral_a = 0.0

    def output(self, current_a: float, sensed_a: float | None, dt_s: float) -> float:
        """The output for ``current_a``; the loop integrates the error of the sensed current
        (None: not sensed) over ``dt_s``, its correction held within ±``current_max_a``."""
        if current_a <= 0.0 or current_a != current_a:
            self._integral_a = 0.0
            return self.rest
        if sensed_a is not None and self.ki_per_s > 0.0 and dt_s > 0.0:
            step = self.ki_per_s * (current_a - sensed_a) * min(dt_s, 0.01)
            self._integral_a = min(max(self._integral_a + step, -self.current_max_a), self.current_max_a)
        return interp(current_a + self._integral_a, self.map_current_a, self.map_output)


class RoadDrive:
    """The road motor's loop on its encoder (module docstring)."""

    def __init__(self, output_per_rad_s: float, kp_per_rad: float, limit: float, rest: float = 0.0, lag_s: float = 0.0):
        self.output_per_rad_s = output_per_rad_s
        self.kp_per_rad = kp_per_rad
        #: the motor's time constant: its speed lags its output as a first-order system would, so the
        #: feed-forward leads it by lag_s times the commanded speed's rate of change
        self.lag_s = lag_s
        self._last_speed: float | None = None
        self.limit = limit
        self.rest = rest
        self.speed_rad_s: float | None = None
        self.reference_rad: float | None = None
        self.error_count = 0
        self.error_sq_sum = 0.0
        self.error_max_rad = 0.0

    def command(self, speed_rad_s: float | None) -> None:
        """The road speed from now on (None or NaN: unchanged)."""
        if speed_rad_s is not None and speed_rad_s == speed_rad_s:
            self.speed_rad_s = speed_rad_s

    def stop(self) -> None:
        """No road command: the motor's output at rest, the reference forgotten."""
        self.speed_rad_s = None
        self.reference_rad = None
        self._last_speed = None

    def output(self, road_angle_rad: float, dt_s: float) -> float:
        """The motor's output (volts or a signed duty) at the measured road angle; rest when no road
        speed was ever commanded."""
        speed = self.speed_rad_s
        if speed is None:
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
        self.error_count += 1
        self.error_sq_sum += error * error
        self.error_max_rad = max(self.error_max_rad, abs(error))
        out = (speed + self.lag_s * accel) * self.output_per_rad_s + self.kp_per_rad * error
        return min(max(out, -self.limit), self.limit)

    def tracking(self) -> dict[str, float | int]:
        """How well the road followed its reference: RMS and largest angle error [rad], cycles."""
        n = self.error_count
        return {
            "road_cycles": n,
            "road_error_rms_rad": round(math.sqrt(self.error_sq_sum / n), 6) if n else 0.0,
            "road_error_max_rad": round(self.error_max_rad, 6),
        }

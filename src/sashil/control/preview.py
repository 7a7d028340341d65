"""The road ahead of a law that reads it: the commanded road sampled before the run, and the
window of the next N cycles filled each cycle.

A plan that commands the road (a run on a road profile, ``compare``, a sweep) knows every speed it
will command. :func:`commanded_road` samples them once, before the run, at the loop's period:
``w[k] = road(k·dt)`` θ̇1, held over cycle k (the road motor's speed loop holds the command until the
next), and the angles they give from 0, ``C[k] = dt·Σ_{j<k} w[j]``. Each cycle
:class:`RoadWindow` gives the law the next N speeds ``w[k .. k+N−1]`` exactly, and the angles at
the next N samples as the *measured* road angle θ1 now plus the commanded motion from now on,
``θ1 + C[k+1 .. k+N] − C[k]``: the motor's tracking error so far is read from the road encoder,
the motion to come from the command. Past the sampled road the window holds the road at rest.
Each fill is two slices and one subtraction into a buffer kept from cycle to cycle (no allocation).

A run counts its cycles, and over a link a late host's cycle reads the newest sample, skipping the
ones before it: the run then lasts longer on the wall clock than its duration (4-6 % measured over
serial against the emulated board with the machine's load at 3.5), while the road is commanded by
the wall clock. The road is sampled :data:`OVERRUN_FRACTION` beyond the run's duration, so that a
plan made on it still covers the road such a run commands at its end.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sashil.control.law_api import CommandedRoad, LawState

__all__ = ["OVERRUN_FRACTION", "UNBOUNDED_RUN_S", "RoadWindow", "commanded_road", "run_road"]

#: how much road is sampled for a run of no set duration [s] (beyond it the window holds the road at rest)
UNBOUNDED_RUN_S = 600.0
#: how far beyond a run's duration its road is sampled, as a fraction of it (module docstring)
OVERRUN_FRACTION = 0.1


def commanded_road(
    speed: Callable[[float], float], dt_s: float, duration_s: float | None, preview_cycles: int
) -> CommandedRoad:
    """The road speed ``speed(t)`` [rad/s] commanded at each cycle of a run of ``duration_s`` (None:
    :data:`UNBOUNDED_RUN_S`), plus ``preview_cycles`` beyond its end, and the angles it gives."""
    span = UNBOUNDED_RUN_S if duration_s is None else float(duration_s)
    n = int(round(span / dt_s)) + int(preview_cycles) + 1
    rate = np.fromiter((speed(k * dt_s) for k in range(n)), dtype=float, count=n)
    theta = np.empty(n + 1)
    theta[0] = 0.0
    np.cumsum(rate * dt_s, out=theta[1:])
    return CommandedRoad(dt_s, rate, theta[:n])


def run_road(
    speed: Callable[[float], float], dt_s: float, duration_s: float | None, preview_cycles: int
) -> CommandedRoad:
    """The road a run of ``duration_s`` (None: no set duration) may command: :func:`commanded_road`
    over the duration and :data:`OVERRUN_FRACTION` of it beyond (module docstring)."""
    span = None if duration_s is None else float(duration_s) * (1.0 + OVERRUN_FRACTION)
    return commanded_road(speed, dt_s, span, preview_cycles)


class RoadWindow:
    """Fills a :class:`LawState`'s road-ahead window of ``cycles`` cycles from ``road`` each cycle."""

    def __init__(self, road: CommandedRoad, cycles: int):
        self.cycles = int(cycles)
        n = road.rate_rad_s.size
        pad = self.cycles + 1
        # the road at rest after the sampled road: speeds 0, the angle held
        self._rate = np.concatenate([road.rate_rad_s, np.zeros(pad)])
        last = road.theta_rad[-1] + road.dt_s * road.rate_rad_s[-1]
        self._theta = np.concatenate([road.theta_rad, np.full(pad, last)])
        self._n = n
        self._angles = np.zeros(self.cycles)
        self._rates = np.zeros(self.cycles)

    def fill(self, state: LawState, cycle: int, road_rad: float) -> None:
        """The window of ``cycle`` (0: the run's first), the angles corrected by the measured ``road_rad``."""
        k = min(max(cycle, 0), self._n)
        n = self.cycles
        np.copyto(self._rates, self._rate[k : k + n])
        np.subtract(self._theta[k + 1 : k + n + 1], self._theta[k] - road_rad, out=self._angles)
        state.road_ahead_dot_rad_s = self._rates
        state.road_ahead_rad = self._angles

"""What the RT-DAC walk's readings say about the rig's wiring: pure math on recorded counts and volts.

:mod:`sashil.diagnostics.rtdac_walk` drives the board and asks the operator; this module turns what
it recorded into wiring: which counter is the arm's (an angle the operator set), what each output's
pulse moved (an A/D: the coil and its sense; a counter, steadily: the road motor and its encoder),
the road wheel's counts per revolution, the coil's calibration map from current steps, and the road
motor's step response. Each function either returns its finding or raises :class:`NotFound` with a
sentence the walk shows the operator.
"""

from __future__ import annotations

import itertools
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from sashil.drivers.rtdac_outputs import interp
from sashil.drivers.rtdac_wiring import Wiring

#: an A/D that rises by less than this [V] (or than NOISE_SPREADS of its spread at rest) did not move
AD_RISE_V = 0.05
NOISE_SPREADS = 6.0
#: a counter that moves by fewer counts than this in a pulse did not move
MIN_COUNTS = 8
#: the arm's step needs at least this many counts of travel
ARM_MIN_COUNTS = 4
#: a coil map's current must rise by at least this much [A] from one point to the next to be a point
MAP_MIN_RISE_A = 0.005


class NotFound(Exception):
    """A step's readings name no wiring (the message says why, for the operator)."""


# the arm ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ArmFinding:
    """The arm's counter, its counts per revolution and sign, from two held positions."""

    encoder: int
    counts_per_rev: int
    reversed: bool
    counts: int  # counts from the marker to the rest
    travel_deg: float


def find_arm(marker: Sequence[float], rest: Sequence[float], marker_deg: float) -> ArmFinding:
    """The counter that moved as the arm went from ``marker_deg`` to its rest at 0 deg: the counts
    per degree over that travel give the counts per revolution, their sign the counter's sense."""
    moved = [round(b - a) for a, b in zip(marker, rest, strict=True)]
    encoder = max(range(len(moved)), key=lambda i: abs(moved[i]))
    counts = moved[encoder]
    if abs(counts) < ARM_MIN_COUNTS:
        raise NotFound(f"no counter moved by {ARM_MIN_COUNTS} counts between the marker and the rest")
    others = [i for i in range(len(moved)) if i != encoder and abs(moved[i]) * 4 > abs(counts)]
    if others:
        listed = ", ".join(f"counter {i} {moved[i]:+d}" for i in [encoder, *others])
        raise NotFound(f"more than one counter moved ({listed}): only the arm should move in this step")
    travel = -marker_deg
    per_degree = counts / travel
    return ArmFinding(encoder, round(abs(per_degree) * 360.0), per_degree < 0, counts, travel)


# the pulses ------------------------------------------------------------------------------------
@dataclass
class PulseTrace:
    """What the board read before and during one output's pulse."""

    kind: str  # "pwm" or "da"
    channel: int
    level: float  # duty, or volts
    rest_ads: list[list[float]]  # A/D volts at rest just before the pulse, sample by sample
    start_counts: list[int]
    times: list[float]  # [s] from the pulse's start
    counts: list[list[int]]
    ads: list[list[float]]
    stopped: str = ""  # why a guard ended the pulse early ("": it ran its length)


@dataclass(frozen=True)
class PulseEffect:
    """What one pulse moved: the A/D that rose most (None: none rose) and the counter that moved
    steadily the most (None: none), leaving the arm's out."""

    kind: str
    channel: int
    level: float
    ad: int | None
    ad_rise_v: float
    counter: int | None
    counts: int
    stopped: str

    @property
    def name(self) -> str:
        return output_name(self.kind, self.channel)


def output_name(kind: str, channel: int) -> str:
    return f"{'PWM' if kind == 'pwm' else 'D/A'} {channel}"


def _steady(series: Sequence[int], moved: int) -> bool:
    """The counter's second half moves one way (the sign of ``moved``), never back by a count."""
    half = series[len(series) // 2 :]
    sign = 1 if moved > 0 else -1
    return all(sign * (b - a) >= 0 for a, b in itertools.pairwise(half))


def pulse_effect(trace: PulseTrace, arm_encoder: int | None) -> PulseEffect:
    """The A/D whose mean over the pulse's last third rose most above its mean at rest, if it rose
    by :data:`AD_RISE_V` and :data:`NOISE_SPREADS` spreads at rest; and the counter (not the arm's)
    that moved most, if by :data:`MIN_COUNTS` and steadily."""
    ad, rise = None, 0.0
    if trace.ads:
        tail = trace.ads[len(trace.ads) - max(1, len(trace.ads) // 3) :]
        for i in range(len(trace.ads[0])):
            rest = [row[i] for row in trace.rest_ads]
            base = statistics.fmean(rest)
            spread = statistics.pstdev(rest) if len(rest) > 1 else 0.0
            up = statistics.fmean(row[i] for row in tail) - base
            if up >= max(AD_RISE_V, NOISE_SPREADS * spread) and up > rise:
                ad, rise = i, up
    counter, counts = None, 0
    if trace.counts:
        end = trace.counts[-1]
        for i, (a, b) in enumerate(zip(trace.start_counts, end, strict=True)):
            moved = b - a
            if i == arm_encoder or abs(moved) < MIN_COUNTS or abs(moved) <= abs(counts):
                continue
            if _steady([row[i] for row in trace.counts], moved):
                counter, counts = i, moved
    return PulseEffect(trace.kind, trace.channel, trace.level, ad, round(rise, 4), counter, counts, trace.stopped)


@dataclass(frozen=True)
class CoilFinding:
    kind: str
    channel: int
    sense_ad: int


@dataclass(frozen=True)
class RoadFinding:
    kind: str
    channel: int
    encoder: int
    reversed: bool
    counts: int  # the pulse's counts (signed)


def find_coil(effects: Sequence[PulseEffect]) -> CoilFinding:
    """The one output whose pulse raised an A/D and turned no counter: the coil, and that A/D its sense."""
    found = [e for e in effects if e.ad is not None and e.counter is None]
    if not found:
        raise NotFound("no output raised an A/D without turning a counter: no coil with a current sense found")
    if len(found) > 1:
        listed = ", ".join(f"{e.name} (A/D {e.ad} +{e.ad_rise_v:.3f} V)" for e in found)
        raise NotFound(f"more than one output raised an A/D: {listed}; the coil is one of them")
    e = found[0]
    assert e.ad is not None
    return CoilFinding(e.kind, e.channel, e.ad)


def find_road(effects: Sequence[PulseEffect], arm_known: bool) -> RoadFinding:
    """The one output whose pulse turned a counter steadily: the road motor, that counter its
    encoder; the counter's sense under a positive output is theta1's (the motor defines it, as the
    host's road loop needs)."""
    found = [e for e in effects if e.counter is not None]
    if not found:
        raise NotFound("no output turned a counter: no road motor found (rtdac.road_output: none, if the rig has none)")
    if len(found) > 1:
        listed = ", ".join(f"{e.name} (counter {e.counter} {e.counts:+d})" for e in found)
        raise NotFound(f"more than one output turned a counter: {listed}")
    e = found[0]
    assert e.counter is not None
    if not arm_known:
        raise NotFound(
            f"{e.name} turned counter {e.counter}, but the arm step was skipped: the arm's counter, which "
            "follows the road, cannot be told from the road's"
        )
    return RoadFinding(e.kind, e.channel, e.counter, e.counts < 0, e.counts)


# the road wheel's revolution -------------------------------------------------------------------
def find_revolution(start: Sequence[int], end: Sequence[int], road_encoder: int | None, arm_encoder: int | None) -> int:
    """The road wheel's counts per revolution: the counts its encoder moved in one revolution."""
    moved = [b - a for a, b in zip(start, end, strict=True)]
    others = [i for i in range(len(moved)) if i != arm_encoder]
    top = max(others, key=lambda i: abs(moved[i]))
    if road_encoder is not None and top != road_encoder and abs(moved[top]) > abs(moved[road_encoder]):
        raise NotFound(
            f"counter {top} moved most ({moved[top]:+d}), not the road's counter {road_encoder} "
            f"({moved[road_encoder]:+d})"
        )
    counter = road_encoder if road_encoder is not None else top
    counts = abs(moved[counter])
    if counts < 16:
        raise NotFound(f"the road's counter {counter} moved {moved[counter]:+d} counts: not a revolution")
    return counts


def road_step(times: Sequence[float], angles: Sequence[float], level: float) -> tuple[float, float] | None:
    """The road motor's step response: its steady speed per unit of output and its time constant.

    A first-order motor stepped at time 0 runs, once steady, along ``angle = speed * (t - lag)``; the
    least-squares line through the trace's last 40 % gives the speed (its slope) and the lag (where
    it meets the time axis), the encoder's counts averaged out. ``angles`` [rad] from the step."""
    if len(times) < 10 or level == 0.0:
        return None
    tail = int(0.6 * len(times))
    ts, ys = times[tail:], angles[tail:]
    mean_t, mean_y = statistics.fmean(ts), statistics.fmean(ys)
    spread = sum((t - mean_t) ** 2 for t in ts)
    if spread <= 0.0:
        return None
    speed = sum((t - mean_t) * (y - mean_y) for t, y in zip(ts, ys, strict=True)) / spread
    if abs(speed) < 1e-6:
        return None
    lag = mean_t - mean_y / speed
    return abs(speed / level), max(lag, 0.0)


# the coil's map --------------------------------------------------------------------------------
@dataclass(frozen=True)
class CoilMap:
    currents_a: tuple[float, ...]
    outputs: tuple[float, ...]
    offset_v: float
    a_per_v: float
    dropped: tuple[float, ...]  # step outputs left out: their current did not rise


def coil_map(levels: Sequence[float], volts: Sequence[float], a_per_v: float) -> CoilMap:
    """The coil's calibration map from the sense's volts at each output (``levels[0]`` the rest):
    the current is ``(volts - volts at rest) * a_per_v``; the map starts at (0 A, rest output) and
    keeps each step whose current rises by :data:`MAP_MIN_RISE_A` over the last kept point (the
    section's check: currents rising from 0 A, outputs not falling)."""
    offset = volts[0]
    currents, outputs, dropped = [0.0], [levels[0]], []
    for level, v in zip(levels[1:], volts[1:], strict=True):
        current = (v - offset) * a_per_v
        if current >= currents[-1] + MAP_MIN_RISE_A and level >= outputs[-1]:
            currents.append(round(current, 4))
            outputs.append(round(level, 4))
        else:
            dropped.append(level)
    if len(currents) < 2:
        raise NotFound(
            f"the sensed current did not rise with the output (A/D volts {', '.join(f'{v:.3f}' for v in volts)}): "
            "no map (a sense that falls as the current rises has a negative scale, which the section cannot hold)"
        )
    return CoilMap(tuple(currents), tuple(outputs), round(offset, 4), a_per_v, tuple(dropped))


def meter_scale(meter_a: float, volts: float, offset_v: float) -> float:
    """The sense's scale [A/V] from one current a meter read at the sense's ``volts``."""
    if abs(volts - offset_v) < AD_RISE_V:
        raise NotFound(f"the sense moved {volts - offset_v:+.3f} V from rest: too little for a scale")
    scale = meter_a / (volts - offset_v)
    if not (math.isfinite(scale) and scale > 0.0):
        raise NotFound(f"{meter_a:g} A at {volts - offset_v:+.3f} V from rest: not a positive scale")
    return scale


# the bring-up caps -----------------------------------------------------------------------------
def output_caps(wiring: Wiring) -> dict[str, float]:
    """The largest output of each kind the config's bring-up caps allow while nothing is confirmed:
    the coil's (its map's output at ``bringup_current_max_a``) for the coil's kind, the road's
    (``bringup_road_output`` of ``road_output_limit``) for the road's; a kind neither names: full."""
    w = wiring
    caps = {"pwm": 1.0, "da": 10.0}
    coil = interp(w.bringup_current_max_a, w.coil_map_current_a, w.coil_map_output)
    caps[w.coil_output] = min(caps[w.coil_output], abs(coil))
    if w.road_output in caps:
        caps[w.road_output] = min(caps[w.road_output], w.bringup_road_output * w.road_output_limit)
    return caps

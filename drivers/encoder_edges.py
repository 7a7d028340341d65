"""True encoder edge times from a simulated trajectory: when did a count last change, and which way.

An encoder of ``q`` radians per count reports ``round(angle / q)``: its count changes when the angle
crosses a boundary ``(n + 1/2) q``. Between two plant sub-steps the trajectory is taken as the cubic
Hermite curve through both ends' angle and rate (the plant's trapezoidal step is exact for it up to
its own second order; seed 001 eqs. 13-17 give the ends), plus the road's own profile theta1(t).

:func:`last_crossing` finds, over one sub-step, the last instant a count changed and its direction:
a quick test first (the ends' counts equal and the curve provably inside their cell: no edge, the
common case at 1 kHz), else the curve's counts at a few points locate the last change and a
bracketed root finder (Illinois regula falsi) puts it on the boundary to well under a nanosecond.
Pure functions of floats; the simulated rig (:mod:`sashil.drivers.sim`) calls them per sub-step, the
quick test (:func:`quick_test`) compiled with numba, as its every cycle runs it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from sashil.models._jit import jit, loop_kernel

#: root-finder stop: the bracket's width as a fraction of the sub-step (1e-7 of 1 ms: 0.1 ns)
TOLERANCE = 1e-7
#: points per sub-step that locate the last change, at least (more when many counts pass)
MIN_POINTS = 4
MAX_POINTS = 64


def hermite(y0: float, m0: float, y1: float, m1: float, s: float) -> float:
    """The cubic Hermite curve at ``s`` in [0, 1] through (0, y0) and (1, y1) with slopes ``m0``, ``m1``
    per unit of ``s`` (the rate times the sub-step)."""
    s2 = s * s
    s3 = s2 * s
    return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * m1


@loop_kernel(lambda: (0.0, 1e-4, 2e-4, 1e-4))
@jit
def hermite_bulge(y0: float, m0: float, y1: float, m1: float) -> float:
    """A bound on how far the Hermite curve strays from its chord over [0, 1].

    H(s) - chord(s) = s (1 - s) [(m0 - d)(1 - s) - (m1 - d) s] with d = y1 - y0, and s (1 - s) <= 1/4.
    """
    d = y1 - y0
    return 0.25 * max(abs(m0 - d), abs(m1 - d))


@loop_kernel(lambda: (0.0, 1e-4, 1e-6, 1.5e-3))
@jit
def stays_in_cell(y0: float, y1: float, bulge: float, q: float) -> bool:
    """Whether a curve from ``y0`` to ``y1`` that strays at most ``bulge`` from its chord provably keeps
    one count (no edge): both ends' counts equal and the curve inside that count's cell."""
    c1 = round(y1 / q)
    if round(y0 / q) != c1:
        return False
    if y0 < y1:
        lo, hi = y0 - bulge, y1 + bulge
    else:
        lo, hi = y1 - bulge, y0 + bulge
    return (c1 - 0.5) * q < lo and hi < (c1 + 0.5) * q


@loop_kernel(lambda: (0.0, 1e-4, 2e-4, 1e-4, 0.0, 0.0, 0.0, 1.5e-3))
@jit
def quick_test(y0: float, m0: float, y1: float, m1: float, r0: float, r1: float, road_bulge: float, q: float) -> float:
    """One sub-step's quick test of both encoders: -1 when neither count can change (the common case at
    1 kHz), else the bound on how far the arm's curve strays from its chord (>= 0), for the search.

    The arm's curve is the relative angle's Hermite curve (ends ``y0``, ``y1``, slopes ``m0``, ``m1``)
    plus the road's, which strays at most ``road_bulge`` from its chord (ends ``r0``, ``r1``).
    """
    arm_bulge = hermite_bulge(y0, m0, y1, m1) + road_bulge
    if stays_in_cell(y0 + r0, y1 + r1, arm_bulge, q) and stays_in_cell(r0, r1, road_bulge, q):
        return -1.0
    return arm_bulge


def last_crossing(
    angle: Callable[[float], float], y0: float, y1: float, bulge: float, q: float
) -> tuple[float, int] | None:
    """The last count change of ``angle(s)``, s in [0, 1], as (s, direction +1/-1), or None.

    ``y0``/``y1``: the angle at the ends; ``bulge``: a bound on how far it strays from the chord
    between them (0 for a straight line); ``q``: radians per count.
    """
    if stays_in_cell(y0, y1, bulge, q):
        return None
    c0, c1 = round(y0 / q), round(y1 / q)
    points = min(MAX_POINTS, MIN_POINTS + 2 * abs(c1 - c0))
    prev_s, prev_c = 1.0, c1
    for k in range(points - 1, -1, -1):
        s = k / points
        c = c0 if k == 0 else round(angle(s) / q)
        if c != prev_c:
            direction = 1 if prev_c > c else -1
            boundary = (prev_c - 0.5 * direction) * q
            return _root(angle, boundary, s, prev_s), direction
        prev_s, prev_c = s, c
    return None


def _root(angle: Callable[[float], float], target: float, a: float, b: float) -> float:
    """The crossing of ``angle(s) = target`` in [a, b] (the ends on either side; Illinois regula falsi),
    the bracket's end on the far side of the boundary: at or just after the crossing."""
    fa, fb = angle(a) - target, angle(b) - target
    side = 0
    for _ in range(100):
        if b - a <= TOLERANCE:
            break
        s = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not a < s < b:
            s = 0.5 * (a + b)
        fs = angle(s) - target
        if fs == 0.0:
            return s
        if math.copysign(1.0, fs) == math.copysign(1.0, fb):
            b, fb = s, fs
            if side == 1:
                fa *= 0.5
            side = 1
        else:
            a, fa = s, fs
            if side == -1:
                fb *= 0.5
            side = -1
    return b

"""True encoder edge times from a simulated trajectory: when did a count last change, and which way.

An encoder of ``q`` radians per count reports ``round(angle / q)``: its count changes when the angle
crosses a boundary ``(n + 1/2) q``. Between two plant sub-steps the trajectory is taken as the cubic
Hermite curve through both ends' angle and rate (the plant's trapezoidal step is exact for it up to
its own second order; seed 001 eqs. 13-17 give the ends), plus the road's own profile theta1(t).

This module holds the quick test that rules an edge out (:func:`quick_test`: the ends' counts equal
and the curve provably inside their cell, the common case at 1 kHz) and the search's constants. The
search itself, where the quick test lets a sub-step through, is compiled with the plant's sub-steps
in :mod:`sashil.drivers.sim_advance`: the curve's counts at a few points locate the last change, and
a bracketed root finder (Illinois regula falsi) puts it on the boundary to well under a nanosecond.
"""

from __future__ import annotations

from sashil.models._jit import jit, loop_kernel

#: root-finder stop: the bracket's width as a fraction of the sub-step (1e-7 of 1 ms: 0.1 ns)
TOLERANCE = 1e-7
#: points per sub-step that locate the last change, at least (more when many counts pass)
MIN_POINTS = 4
MAX_POINTS = 64


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

"""The simulated rig's motion over one read, as one compiled call: the plant's sub-steps and the
encoders' last count changes on the way (:mod:`sashil.drivers.sim`).

The same arithmetic as :meth:`sashil.models.plant.RigPlant.step` (the released arm's
:func:`~sashil.models.plant.rig_substep`, the held arm's coil alone), then the encoders' edge search
(:mod:`sashil.drivers.encoder_edges`' quick test, then here the last crossing on the sub-step's Hermite
curve, a bracketed root on the boundary), for the road the simulated rig drives: its wheel, whose angle
is ``road0 + speed * (t - road_t0)`` (no road force, no input torque). One call instead of a
few per sub-step: each compiled call from Python costs about as much as the sub-step itself.
"""

from __future__ import annotations

import math

import numpy as np

from sashil.drivers.encoder_edges import MAX_POINTS, MIN_POINTS, TOLERANCE, quick_test, stays_in_cell
from sashil.models._jit import jit, loop_kernel
from sashil.models.plant import rig_substep


@jit
def _angle(arm: bool, s: float, curve: tuple[float, float, float, float, float], road: tuple[float, ...]) -> float:
    """At ``s`` of the sub-step: the arm's angle (the relative angle's Hermite curve plus the road)
    or the road's. ``curve``: (y0, m0, y1, m1, t0); ``road``: (h, road0, speed, road_t0)."""
    y0, m0, y1, m1, t0 = curve
    h, road0, speed, road_t0 = road
    road_angle = road0 + speed * ((t0 + s * h) - road_t0)
    if not arm:
        return road_angle
    s2 = s * s
    s3 = s2 * s
    return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * m1 + road_angle


@jit
def _root(
    arm: bool,
    target: float,
    a: float,
    b: float,
    curve: tuple[float, float, float, float, float],
    road: tuple[float, ...],
) -> float:
    """The crossing of ``_angle(arm, s) = target`` in [a, b] (the ends on either side; Illinois regula
    falsi, to :data:`~sashil.drivers.encoder_edges.TOLERANCE` of the sub-step), the bracket's end on the
    far side of the boundary: at or just after the crossing."""
    fa = _angle(arm, a, curve, road) - target
    fb = _angle(arm, b, curve, road) - target
    side = 0
    for _ in range(100):
        if b - a <= TOLERANCE:
            break
        s = b - fb * (b - a) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not a < s < b:
            s = 0.5 * (a + b)
        fs = _angle(arm, s, curve, road) - target
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


@jit
def _last_crossing(
    arm: bool,
    y0: float,
    y1: float,
    bulge: float,
    q: float,
    curve: tuple[float, float, float, float, float],
    road: tuple[float, ...],
) -> tuple[float, int]:
    """The last count change of the arm's (``arm``) or the road's :func:`_angle` over the sub-step, as
    (s in [0, 1], direction +1/-1), or (0, 0) for none. ``y0``/``y1``: that angle at the ends;
    ``bulge``: a bound on how far it strays from the chord between them (0 for a straight line);
    ``q``: radians per count. Where the quick cell test cannot rule a change out, the counts at a few
    points (more when many counts pass) locate the last change and :func:`_root` puts it on its
    boundary."""
    if stays_in_cell(y0, y1, bulge, q):
        return 0.0, 0
    c0, c1 = round(y0 / q), round(y1 / q)
    points = min(MAX_POINTS, MIN_POINTS + 2 * abs(c1 - c0))
    prev_s, prev_c = 1.0, c1
    for k in range(points - 1, -1, -1):
        s = k / points
        c = c0 if k == 0 else round(_angle(arm, s, curve, road) / q)
        if c != prev_c:
            direction = 1 if prev_c > c else -1
            boundary = (prev_c - 0.5 * direction) * q
            return _root(arm, boundary, s, prev_s, curve, road), direction
        prev_s, prev_c = s, c
    return 0.0, 0


@loop_kernel(
    lambda: (
        *(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        *(0.0, 0.0, 0.0),
        *(1, 1e-3, 0.0, 0.9),
        False,
        np.array([1.5e-3, 1.0, 109.0, 0.7, 1.5, 1.0, 1.0, 873.0, 1.0, 700.0, 0.099, 0.9]),
    )
)
@jit
def advance(
    t: float,
    theta: float,
    v: float,
    z: float,
    i: float,
    r: float,
    rv: float,
    road0: float,
    speed: float,
    road_t0: float,
    count: int,
    h: float,
    cmd: float,
    decay: float,
    held: bool,
    constants: np.ndarray,
) -> tuple[float, float, float, float, float, float, int, float, int, int, float, int]:
    """``count`` sub-steps of ``h`` s towards the coil current ``cmd``, timing the encoders' last count
    changes. The state now: time ``t``, relative angle ``theta``, its rate ``v``, the damper's ``z``,
    the coil current ``i``, the road's angle ``r`` and rate ``rv``; the wheel's angle is ``road0 +
    speed * (t - road_t0)``; ``decay``: exp(-h/tau) of the coil; ``held``: the operator holds the
    relative angle (the coil alone moves, and the road); ``constants``: what stays for a run, one
    array (one argument to pass from Python, not twelve): ``q``, one count [rad], then the plant's
    coefficients J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n, z_u.

    Returns (t, theta, theta_dot, z, i, road angle, then for the arm and the road encoder the
    sub-step of its last count change (-1: none), the fraction of that sub-step and the direction).
    """
    q, J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n, z_u = (
        constants[0],
        constants[1],
        constants[2],
        constants[3],
        constants[4],
        constants[5],
        constants[6],
        constants[7],
        constants[8],
        constants[9],
        constants[10],
        constants[11],
    )
    road = (h, road0, speed, road_t0)
    arm_j, arm_s, arm_dir = -1, 0.0, 0
    road_j, road_s, road_dir = -1, 0.0, 0
    for j in range(count):
        t0, y0, v0, r0, rv0 = t, theta, v, r, rv
        if held:
            i = cmd + (i - cmd) * decay
        else:
            theta, v, z, i = rig_substep(
                theta, v, z, i, h, cmd, decay, J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n, z_u, 0.0
            )
        t += h
        r, rv = road0 + speed * (t - road_t0), speed
        m0, m1 = h * v0, h * v
        road_bulge = 0.125 * h * abs(rv - rv0)
        arm_bulge = quick_test(y0, m0, theta, m1, r0, r, road_bulge, q)
        if arm_bulge < 0.0:
            continue  # no count changed (the common case at 1 kHz)
        curve = (y0, m0, theta, m1, t0)
        s, direction = _last_crossing(True, y0 + r0, theta + r, arm_bulge, q, curve, road)
        if direction != 0:
            arm_j, arm_s, arm_dir = j, s, direction
        s, direction = _last_crossing(False, r0, r, road_bulge, q, curve, road)
        if direction != 0:
            road_j, road_s, road_dir = j, s, direction
    return t, theta, v, z, i, r, arm_j, arm_s, arm_dir, road_j, road_s, road_dir

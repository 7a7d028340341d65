"""The road wheel's angle as the board applied it, read from the road encoder's edge times.

The fit's road forcing is ``-J * theta1_ddot`` (seed 001 eq. 13 with the road side driven). The
speeds a host commands reach a board over a link late by a varying amount, so the road they
describe is shifted in time against the recorded arm: by the delay times the speed, a count or so
at the calibration chirp's top speed. The road encoder's edges say where the road was and when, on
the device's clock: a count ``n`` reached going up crossed the boundary ``(n - 1/2) q``, going down
``(n + 1/2) q``, at the instant the board stamped (``drivers/protocol.md``, "Encoder edges"). Those
points carry no quantisation.

Between edges (4-100 ms apart on a 1 deg chirp) the commanded speeds give the road's shape: the
road angle is their integral on the device's clock plus a correction the edges measure (the
accumulated delay of the commands so far), linear between edges. On a rig that applies each
command at once the correction is a constant. Without commanded speeds a cubic spline through the
edges is the road angle (its error over the longest gap, at a reversal of a 1 deg, 3 Hz chirp:
5/384 h^4 max|theta1 4th derivative|, about 2e-5 rad, 1 % of a count).

The boundary each edge crossed is chained from edge to edge (consecutive edges of directions
``d0, d1`` are ``(d0 + d1) / 2`` counts apart when none was missed between them) and anchored on
each edge's own count (the median count of the samples that carried it) through a running median
over ANCHOR_EDGES edges: counts that angle noise flipped (most often right after an edge, where
the angle is near the boundary) do not move an edge, and an edge the samples missed (lost
samples, or two changes in one sample period) is a step of the offset that the median keeps. The
chain also starts again where samples were lost.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import median_filter

#: the column of the road angle the board applied at each sample [rad]
APPLIED_ROAD = "theta_road_applied_rad"
#: edges whose anchors a running median takes (odd): a missed edge is a step of the chain's
#: offset, which the median keeps where it is; a count flipped by noise is an outlier it drops
ANCHOR_EDGES = 7
#: fewest edges the spline needs (a cubic with not-a-knot ends)
MIN_EDGES = 4


def edge_boundaries(
    edge_s: np.ndarray, edge_dir: np.ndarray, counts: np.ndarray, time_s: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """An encoder's distinct edges (the road's here, the arm's in compare's θ̈2): their times [s] and
    the boundaries they crossed [counts, half-integers], from each sample's last edge (``edge_s``: NaN
    none; ``edge_dir`` +1/-1, 0 none) and its count. Edges out of time order are left out. The chain
    of boundaries starts again where samples were lost (``time_s``: a step of more than 1.5 median
    periods), where an edge may have been missed. None: fewer than MIN_EDGES edges."""
    edge_s = np.asarray(edge_s, dtype=float)
    edge_dir = np.asarray(edge_dir, dtype=float)
    counts = np.asarray(counts, dtype=float)
    missed = np.zeros(counts.size, dtype=bool)
    if time_s is not None and counts.size > 2:
        step = np.diff(np.asarray(time_s, dtype=float))
        missed[1:] = step > 1.5 * float(np.median(step))
    run = np.cumsum(missed)  # the chain each sample belongs to
    rows = np.flatnonzero(np.isfinite(edge_s) & (edge_dir != 0.0))
    if rows.size == 0:
        return None
    t = edge_s[rows]
    later = np.ones(t.size, dtype=bool)  # each edge once (the first sample that carried it), in time order
    later[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    first, t = rows[later], t[later]
    if t.size < MIN_EDGES:
        return None
    d = np.sign(edge_dir[first])
    # every sample that carried an edge, and which one: its count is that edge's count after it
    carried = np.searchsorted(t, edge_s[rows])
    same = (carried < t.size) & (t[np.minimum(carried, t.size - 1)] == edge_s[rows])
    rows, carried = rows[same], carried[same]
    # each edge's own anchor: the median count of the samples that carried it, less the chain
    residual = counts[rows] - 0.5 * d[carried]
    split = np.flatnonzero(np.diff(carried)) + 1
    own = np.full(t.size, np.nan)
    own[carried[np.r_[0, split]]] = [float(np.median(part)) for part in np.split(residual, split)]
    boundary = np.empty(t.size)
    for chain in np.unique(run[first]):
        k = np.flatnonzero(run[first] == chain)
        chained = np.concatenate(([0.0], np.cumsum(0.5 * (d[k][:-1] + d[k][1:]))))
        offset = median_filter(own[k] - chained, size=min(ANCHOR_EDGES, k.size | 1), mode="mirror")
        boundary[k] = chained + np.floor(offset) + 0.5  # a boundary lies half-way between counts
    return t, boundary


def applied_road_angle(
    time_s: np.ndarray,
    edge_s: np.ndarray,
    edge_dir: np.ndarray,
    counts: np.ndarray,
    quantum_rad: float,
    speed_cmd_rad_s: np.ndarray | None = None,
) -> np.ndarray | None:
    """The road angle [rad] at each sample time ``time_s`` (the device's clock, as ``edge_s``) through
    the edges' boundaries (:func:`edge_boundaries`; ``counts``: the road encoder's count of each
    sample, ``quantum_rad`` its size). With the commanded speeds (``speed_cmd_rad_s``, each held from
    its row's sample on) the angle is their integral plus the correction the edges measure, linear
    between edges and held beyond the first and the last one: the link's delay of each command
    shows up as that correction. Without them, a cubic spline through the edges, held beyond its
    ends. None when the encoder reported fewer than MIN_EDGES edges."""
    time_s = np.asarray(time_s, dtype=float)
    edges = edge_boundaries(edge_s, edge_dir, counts, time_s)
    if edges is None:
        return None
    t_edge, boundary = edges
    angle = boundary * quantum_rad
    if speed_cmd_rad_s is None:
        inside = np.clip(time_s, t_edge[0], t_edge[-1])
        return np.asarray(CubicSpline(t_edge, angle)(inside))
    travelled = np.zeros(time_s.size)
    if time_s.size > 1:
        travelled[1:] = np.cumsum(np.asarray(speed_cmd_rad_s, dtype=float)[:-1] * np.diff(time_s))
    correction = angle - np.interp(t_edge, time_s, travelled)
    return travelled + np.interp(time_s, t_edge, correction)


def held_speed(commanded: np.ndarray) -> np.ndarray:
    """The road wheel's speed in each row: the last speed commanded (NaN: the cycle changed
    nothing), 0 before the first command (the wheel starts at rest)."""
    index = np.where(np.isfinite(commanded), np.arange(commanded.size), -1)
    index = np.maximum.accumulate(index) if index.size else index
    return np.where(index >= 0, commanded[np.maximum(index, 0)], 0.0)


def count_quantum(angle_rad: np.ndarray) -> float:
    """The encoder count [rad] of a recorded angle: its smallest step between samples when every
    step is a whole number of it; 0 when the angle never moved or is not a count."""
    steps = np.abs(np.diff(angle_rad))
    moved = steps[steps > 0.0]
    if moved.size == 0:
        return 0.0
    quantum = float(moved.min())
    ratio = moved / quantum
    return quantum if bool(np.all(np.abs(ratio - np.round(ratio)) <= 1e-6 * np.maximum(ratio, 1.0))) else 0.0


def road_of_columns(columns: dict[str, np.ndarray], quantum_rad: float | None = None) -> np.ndarray | None:
    """The applied road angle of a record's columns (:func:`applied_road_angle`): ``road_edge_s``
    (the road encoder's last edge of each sample, on ``time_s``'s clock), ``road_edge_dir``,
    ``theta_road_rad`` (its count) and, when present, ``road_speed_cmd_rad_s``. ``quantum_rad``:
    the encoder's count (None: read from ``theta_road_rad``'s steps). None without the edges."""
    if APPLIED_ROAD in columns:
        return np.asarray(columns[APPLIED_ROAD], dtype=float)
    if not {"road_edge_s", "road_edge_dir", "theta_road_rad"} <= columns.keys():
        return None
    road = np.asarray(columns["theta_road_rad"], dtype=float)
    q = quantum_rad or count_quantum(road)
    if q <= 0.0:
        return None
    speed = columns.get("road_speed_cmd_rad_s")
    return applied_road_angle(
        columns["time_s"],
        columns["road_edge_s"],
        columns["road_edge_dir"],
        np.rint(road / q),
        q,
        None if speed is None else held_speed(np.asarray(speed, dtype=float)),
    )


def speed_steps_acceleration(time_s: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The road acceleration at each sample that steps the wheel's speed by ``steps[j]`` at sample j,
    as the fit's simulation reads it (:func:`sashil.identify.kernels.simulate_rig` interpolates the
    acceleration linearly between samples): a triangle on sample j, zero on its neighbours, whose
    area is the step, ``2 steps[j] / (dt before + dt after)``. Half of it acts before the sample and
    half after, so its centre stays on the sample, and the speed is right after every step however
    unevenly the samples are spaced (a link loses some). Divided by the interval after the sample
    alone, a step next to a lost sample would change the speed by (dt before + dt after) / (2 dt
    after) times itself: a road speed off for the rest of the record."""
    time_s = np.asarray(time_s, dtype=float)
    if time_s.size < 2:
        return np.zeros_like(np.asarray(steps, dtype=float))
    dt = np.diff(time_s)
    before = np.concatenate((dt[:1], dt))  # the first sample's triangle as wide as its interval after
    after = np.concatenate((dt, dt[-1:]))
    return np.asarray(steps, dtype=float) * 2.0 / np.maximum(before + after, 2e-6)


def angle_acceleration(time_s: np.ndarray, theta_road_rad: np.ndarray) -> np.ndarray:
    """The road acceleration of a road angle known at each sample: the speed over each interval is
    the angle's chord, and it steps from one interval's to the next at the sample between them."""
    speed = np.diff(theta_road_rad) / np.maximum(np.diff(time_s), 1e-9)
    steps = np.zeros(time_s.size)
    steps[1:-1] = np.diff(speed)
    return speed_steps_acceleration(time_s, steps)

"""compare's θ̈2 from the encoders: the arm encoder's edges read as exact angles at their own times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.lab.compare_metrics import arm_acceleration

COUNTS = 4096
Q = 2 * math.pi / COUNTS
#: an edge older than this is reported as none (``drivers/protocol.md``, "Encoder edges")
MAX_AGE_US = 65535


def quantised_sine(amplitude_counts: float, f_hz: float, duration_s: float = 4.0) -> dict[str, np.ndarray]:
    """The stream of an arm swinging θ2 = A·sin(ωt) (the road still), sampled each 1 ms of device time:
    each sample's count round(θ2 / q), and its last edge, the last crossing of a boundary (n + ½)·q
    before it (sin(ωt) = b / A, the time to the microsecond) and its direction, none when older than
    the wire's age reaches."""
    w, a = 2 * math.pi * f_hz, amplitude_counts * Q
    device_us = np.arange(int(duration_s * 1000)) * 1000
    t = device_us * 1e-6
    crossings = []
    for n in range(-math.ceil(amplitude_counts) - 1, math.ceil(amplitude_counts) + 1):
        b = (n + 0.5) * Q
        if abs(b) < a:
            s = math.asin(b / a)
            crossings += [
                (phase + 2 * math.pi * k) / w for k in range(int(duration_s * f_hz) + 2) for phase in (s, math.pi - s)
            ]
    edges = np.sort([c for c in crossings if c <= duration_s])
    last = np.searchsorted(edges, t, side="right") - 1
    edge_us = np.round(edges[np.maximum(last, 0)] * 1e6)
    direction = np.sign(np.cos(w * edges[np.maximum(last, 0)]))
    none = (last < 0) | (device_us - edge_us >= MAX_AGE_US)
    return {
        "theta_rad": np.rint(a * np.sin(w * t) / Q) * Q,
        "theta_road_rad": np.zeros(t.size),
        "device_time_us": device_us.astype(float),
        "seq": np.arange(t.size, dtype=float),
        "arm_edge_us": np.where(none, -1.0, edge_us),
        "arm_edge_dir": np.where(none, 0.0, direction),
    }


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x[1000:-500] ** 2)))  # whole periods, away from the start


def test_the_arm_encoders_edges_take_the_quantisation_out_of_its_acceleration():
    """A 5-count, 2 Hz swing: RMS θ̈2 = A·ω²/√2 (0.856 rad/s²; the 20 Hz low-pass passes 2 Hz whole).
    Through the edges compare reads it within 1 %; through the counts alone (the same stream without
    its edges) their quantisation reads a third too high."""
    stream = quantised_sine(5, 2.0)
    expected = 5 * Q * (2 * math.pi * 2.0) ** 2 / math.sqrt(2)
    accel, source = arm_acceleration(stream, 1000.0, 20.0)
    assert source == "encoders"
    assert rms(accel) == pytest.approx(expected, rel=0.01)
    counts_only = {k: v for k, v in stream.items() if not k.startswith("arm_edge")}
    by_counts, _ = arm_acceleration(counts_only, 1000.0, 20.0)
    assert rms(by_counts) > 1.2 * expected


def test_the_edges_acceleration_has_no_transient_at_the_records_end():
    """The record stops mid-swing (θ̈2 near its peak): the low-pass extends an acceleration past
    the end, not an angle whose curvature its reflection would flip, so the last 100 ms read the
    swing's own θ̈2."""
    stream = {k: v[:2630] for k, v in quantised_sine(20, 2.0).items()}
    accel, _ = arm_acceleration(stream, 1000.0, 20.0)
    t = stream["device_time_us"] * 1e-6
    expected = -20 * Q * (2 * math.pi * 2.0) ** 2 * np.sin(2 * math.pi * 2.0 * t)
    tail = slice(-100, None)
    assert np.max(np.abs(accel[tail] - expected[tail])) < 0.05 * np.max(np.abs(expected))

"""A drop's metrics on the clock that sampled the arm (sashil.lab._drop_test.sampled_angle)."""

from __future__ import annotations

import math

import numpy as np

from sashil.lab._drop_test import DropRecord, sampled_angle
from sashil.lab.metrics import drop_metrics

PERIOD_S = 0.6
ZETA = 0.05


def _oscillation(t_s: np.ndarray) -> np.ndarray:
    """A damped free oscillation from −5° at t = 0: θ = θ0·e^(−ζωt)·cos(ω_d t)."""
    omega_d = 2 * math.pi / PERIOD_S
    omega = omega_d / math.sqrt(1 - ZETA**2)
    return math.radians(-5.0) * np.exp(-ZETA * omega * t_s) * np.cos(omega_d * t_s)


def _record(device_us: np.ndarray, loop_s: np.ndarray, seq: np.ndarray) -> DropRecord:
    theta = _oscillation(device_us * 1e-6)  # each row carries the angle of the sample it read
    record = DropRecord(
        data={"time_s": loop_s, "theta_rad": theta},
        release_time_ns=0,
        release_estimated=False,
        hold_angle_rad=math.radians(-5.0),
    )
    record.stream = {"time_s": loop_s, "theta_rad": theta, "seq": seq, "device_time_us": device_us.astype(float)}
    record.device_release_s = 0.0
    return record


def test_a_busy_hosts_late_reads_leave_the_period_on_the_devices_clock():
    device_us = np.arange(3000) * 1000  # a sample every ms on the board's clock
    # the host reads each sample a round trip later; around the third peak (1.5 s) it falls 12 ms
    # behind, as a busy core's host does, and catches up
    late_s = 0.0003 + np.where(np.abs(device_us * 1e-6 - 1.5) < 0.1, 0.012, 0.0)
    loop_s = np.maximum.accumulate(device_us * 1e-6 + late_s)
    record = _record(device_us, loop_s, np.arange(3000))
    time_s, theta = sampled_angle(record)
    assert np.array_equal(time_s, device_us * 1e-6)
    on_device = drop_metrics(time_s, theta).period_s
    on_host = drop_metrics(loop_s, record.data["theta_rad"]).period_s
    assert on_device is not None and abs(on_device - PERIOD_S) < 0.0006  # the 1 ms grid's resolution
    assert on_host is not None and on_host - PERIOD_S > 0.002  # the host's clock: a quarter of the 12 ms


def test_a_sample_read_twice_counts_once_at_its_own_time():
    device_us = np.repeat(np.arange(1500) * 2000, 2)  # each sample read by two cycles
    loop_s = np.arange(3000) * 1e-3 + 0.0004
    time_s, theta = sampled_angle(_record(device_us, loop_s, np.repeat(np.arange(1500), 2)))
    assert np.allclose(time_s, np.arange(1500) * 2e-3, rtol=0, atol=1e-12) and theta.size == 1500


def test_a_device_clock_that_restates_the_loops_gives_way_to_the_loops():
    loop_s = np.arange(3000) * 1e-3 + 3.7e-7  # a simulated rig: its device time is the loop's in whole µs
    device_us = np.floor(loop_s * 1e6)
    record = _record(device_us, loop_s, np.arange(3000))
    time_s, theta = sampled_angle(record)
    assert time_s is record.data["time_s"] and theta is record.data["theta_rad"]


def test_a_rig_without_a_device_clock_keeps_the_loops():
    loop_s = np.arange(100) * 1e-3
    record = _record(np.zeros(100), loop_s, np.arange(100))
    assert sampled_angle(record)[0] is record.data["time_s"]

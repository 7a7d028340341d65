"""The Kalman estimator with encoder edge events: below one count, old events, still encoders, bad events.

The samples are built by hand from a motion whose edges are analytic: the road turns at a constant
speed w (theta1 = w t), the arm follows it (theta = 0, so theta2 = theta1). With q radians per count
the count n is reached at t_n = (n - 1/2) q / w; a sample at t carries round(w t / q) and its last
edge, floored to the microsecond as a board stamps it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.config.parts import StageParts
from sashil.control.edge_kalman import _scalar_update
from sashil.control.kalman import EDGE_BAD_MIN_EVENTS, KalmanRigEstimator
from sashil.control.registry import make_controller
from sashil.drivers import rig_parts
from sashil.drivers.interface import NO_EDGE, TWO_PI, RigSample
from sashil.engine.resolve import default_config
from sashil.errors import SafetyTrip

COUNTS = 4096
Q = TWO_PI / COUNTS
DT = 1e-3


def moving_sample(k: int, speed: float, seq_offset: int = 0) -> RigSample:
    """Sample k (at k ms) of the constant-speed motion, with both encoders' last edges."""
    t_us = k * 1000
    n = round(speed * t_us * 1e-6 / Q)
    if n == 0:
        edge_us, direction = NO_EDGE, 0
    else:
        direction = 1 if speed > 0 else -1
        edge_us = math.floor((n - 0.5 * direction) * Q / speed * 1e6)
    return RigSample(k + seq_offset, t_us * 1000, t_us, n, n, 0.0, 0, COUNTS, edge_us, direction, edge_us, direction)


def estimator(edge_timing: bool) -> KalmanRigEstimator:
    est = KalmanRigEstimator(DT, edge_timing=edge_timing)
    est.prepare(COUNTS)
    return est


def road_errors(edge_timing: bool, speed: float, cycles: int = 600, every: int = 1) -> list[float]:
    """The road-angle estimate's error [counts] over the last half of the run (samples every ``every`` ms)."""
    est = estimator(edge_timing)
    errors = []
    for k in range(0, cycles, every):
        est.update(moving_sample(k, speed), every * DT)
        if k >= cycles // 2:
            errors.append((est.theta_road_rad - speed * k * DT) / Q)
    return errors


@pytest.mark.parametrize("speed", [0.37, -0.11])
def test_edge_events_place_a_moving_encoder_well_below_one_count(speed):
    with_edges = road_errors(True, speed)
    counts_alone = road_errors(False, speed)
    rms = math.sqrt(sum(e * e for e in with_edges) / len(with_edges))
    rms_counts = math.sqrt(sum(e * e for e in counts_alone) / len(counts_alone))
    assert rms < 0.02  # a fiftieth of a count
    assert rms_counts > 5 * rms  # the count alone: its quantisation, q / sqrt(12) = 0.29 count at best


def test_events_older_than_the_previous_sample_are_still_used():
    # every 5th sample only (as after skipped samples): each edge is up to 5 ms old when it arrives
    errors = road_errors(True, 0.37, every=5)
    assert max(abs(e) for e in errors) < 0.05


def test_a_still_encoder_is_its_count_and_the_relative_angle_follows_the_other():
    # the road does not move (no edge ever); the arm turns at w: theta = theta2 - theta1 = w t
    est = estimator(True)
    speed = 0.37
    for k in range(600):
        moving = moving_sample(k, speed)
        still = RigSample(
            k, k * 10**6, k * 1000, moving.arm_counts + 5, 5, 0.0, 0, COUNTS, moving.arm_edge_us, 0, -1, 0
        )
        if moving.arm_edge_dir:  # the arm's edges, shifted by the 5 counts of the still road
            still.arm_edge_dir = moving.arm_edge_dir
        est.update(still, DT)
    assert est.theta_road_rad == pytest.approx(5 * Q, abs=0.01 * Q)
    assert est.theta_rad == pytest.approx(speed * 599 * DT, abs=0.05 * Q)
    assert est.edge_events > 0 and est.edge_rejects == 0


def test_an_event_from_the_future_or_older_than_the_last_is_counted_and_left_out():
    est = estimator(True)
    speed = 0.37
    for k in range(1000):
        est.update(moving_sample(k, speed), DT)
    good = moving_sample(1000, speed)
    events = est.edge_events
    future = RigSample(1000, 0, good.device_time_us, good.arm_counts, good.road_counts, 0.0, 0, COUNTS)
    future.arm_edge_us, future.arm_edge_dir = good.device_time_us + 50, 1
    est.update(future, DT)
    assert est.edge_rejects == 1 and est.edge_events == events
    last = est._last_edge_us[1]
    older = moving_sample(1001, speed)
    older.road_edge_us, older.road_edge_dir = last - 1, 1
    est.update(older, DT)
    assert est.edge_rejects == 2  # the road's event left out; the arm's (a new one or the same) taken
    # the samples were used without their bad events: the estimate still tracks within the count
    assert est.theta_road_rad == pytest.approx(speed * 1001 * DT, abs=0.5 * Q)
    assert est.edge_events > 400 and not est.edge_fault  # 2 bad of over 400: below 1 %


def test_more_than_one_percent_bad_events_stop_the_run_as_a_safety_trip():
    config = default_config()
    config["model"]["name"] = "bouc-wen"
    ctl = make_controller("passive", StageParts.read(config))
    speed = 0.5
    stats = None
    with pytest.raises(SafetyTrip) as err:
        for k in range(20 * EDGE_BAD_MIN_EVENTS):
            sample = moving_sample(k, speed)
            if k % 50 == 49 and sample.road_edge_dir:  # one sample in 50 stamps its road edge in the future
                sample.road_edge_us = sample.device_time_us + 10
            ctl.step(sample, k * 10**6, 10**6)
    stats = ctl.stats()
    assert err.value.exit_code == 3 and "\n" not in str(err.value) and "more than 1 %" in str(err.value)
    rejects, events = stats["edge_rejects"], stats["edge_events"]
    assert rejects > 0.01 * (rejects + events) and rejects + events >= EDGE_BAD_MIN_EVENTS


def test_the_config_switch_turns_the_events_off():
    config = default_config()
    assert make_controller("passive", StageParts.read(config)).estimator.edge_timing is True
    config["controller"]["edge_timing"] = False
    ctl = make_controller("passive", StageParts.read(config))
    assert ctl.estimator.edge_timing is False
    for k in range(50):
        ctl.step(moving_sample(k, 0.5), k * 10**6, 10**6)
    assert ctl.stats()["edge_events"] == 0


def test_a_run_with_bad_edge_times_ends_at_zero_current_with_exit_3_and_the_counts():
    from sashil.drivers.interface import RigCommand
    from sashil.drivers.sim import SimulatedRig
    from sashil.errors import exit_code_of
    from sashil.runtime.clock import VirtualClock
    from sashil.runtime.loop import ControlLoop

    class BadEdges(SimulatedRig):
        """The simulated rig with a road turning at 0.5 rad/s, whose board stamps one edge in 30 in the future."""

        def read(self, t_ns, dt_ns):
            sample = super().read(t_ns, dt_ns)
            if sample.seq % 30 == 0 and sample.road_edge_dir:
                sample.road_edge_us = sample.device_time_us + 20
            return sample

        def write(self, cmd, t_ns, dt_ns):
            self.currents.append(cmd.current_a)
            super().write(RigCommand(cmd.current_a, 0.5), t_ns, dt_ns)

    config = default_config()
    rig = BadEdges.from_parts(rig_parts(config, "sim"))
    rig.currents = []
    ctl = make_controller(
        "passive", StageParts.read({**config, "controller": {**config["controller"], "current_a": 0.5}})
    )
    loop = ControlLoop(rig, ctl, VirtualClock(), 1000.0, 5.0)
    with pytest.raises(SafetyTrip):
        loop.run()
    assert loop.result.exit_status == "safety_trip" and exit_code_of(loop.result.exit_status) == 3
    assert rig.currents[-1] == 0.0  # the shutdown's safe command
    stats = ctl.stats()
    assert stats["edge_rejects"] > 0.01 * (stats["edge_rejects"] + stats["edge_events"])


def test_one_scalar_update_is_the_kalman_gain_whatever_the_scratch_holds():
    """x += K e, P -= K h P with K = P h / (h P h + r), against numpy's own arithmetic; the scratch
    for P h is written before it is read (a NaN left in it changes nothing)."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(6, 6))
    p0 = a @ a.T + np.eye(6)
    x0 = rng.normal(size=6)
    h = np.array([1.0, -0.002, 1.0, -0.002, 0.0, 2e-6])
    for scratch in (np.zeros(6), np.full(6, np.nan)):
        x, p = x0.copy(), p0.copy()
        _scalar_update(x, p, h, 0.3, 1e-4, scratch)
        ph = p0 @ h
        gain = ph / (h @ ph + 1e-4)
        assert np.allclose(x, x0 + gain * 0.3, rtol=1e-12, atol=0.0)
        assert np.allclose(p, p0 - np.outer(gain, ph), rtol=1e-12, atol=1e-15)

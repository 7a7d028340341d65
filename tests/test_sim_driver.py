"""The simulated backend honours the rig interface contract like a hardware backend must."""

from __future__ import annotations

import math

import pytest

from sashil.drivers import BACKENDS, backend_class, open_rig, rig_parts
from sashil.drivers.interface import FLAG_HELD, RigCommand, RigState
from sashil.drivers.sim import SimulatedRig
from sashil.errors import DriverError

MS = 1_000_000


def test_registry_is_lazy_and_names_unknown_backends(config):
    assert set(BACKENDS) == {"sim", "serial", "can", "rtdac"}
    assert backend_class("sim") is SimulatedRig
    with pytest.raises(DriverError, match="unknown backend 'usb'"):
        backend_class("usb")


def test_lifecycle_and_safe_state(config):
    rig = open_rig(rig_parts(config))
    with pytest.raises(DriverError):
        rig.read(0, 0)  # not configured
    rig.configure()
    rig.write(RigCommand(1.0), 0, MS)  # not active: ignored, stays at 0 A
    rig.read(0, 0)
    rig.read(100 * MS, 100 * MS)
    assert rig.plant.state.current_a == 0.0
    rig.activate()
    rig.write(RigCommand(0.8), 100 * MS, MS)
    rig.read(200 * MS, 100 * MS)
    assert rig.plant.state.current_a == pytest.approx(0.8, rel=1e-3)
    rig.deactivate()
    assert rig.state is RigState.CONFIGURED
    rig.read(400 * MS, 200 * MS)
    assert rig.plant.state.current_a == pytest.approx(0.0, abs=1e-6)
    rig.close()
    rig.close()  # idempotent
    rig.deactivate()  # callable from any state
    assert rig.state is RigState.CLOSED


def test_commands_are_clamped_and_nan_never_reaches_the_coil(config):
    with open_rig(rig_parts(config)) as rig:
        rig.configure()
        rig.activate()
        rig.read(0, 0)
        rig.write(RigCommand(5.0), 0, MS)
        rig.read(200 * MS, 200 * MS)
        assert rig.plant.state.current_a == pytest.approx(1.0, rel=1e-6)
        rig.write(RigCommand(float("nan")), 200 * MS, MS)
        rig.read(400 * MS, 200 * MS)
        assert rig.plant.state.current_a == pytest.approx(0.0, abs=1e-6)
    assert rig.state is RigState.CLOSED


def test_encoder_quantisation(config):
    config["rig"]["encoder_counts_per_rev"] = 360
    rig = open_rig(rig_parts(config))
    rig.configure()
    rig.operator_hold(math.radians(-5.3), 10.0)
    sample = rig.read(0, 0)
    assert sample.arm_counts == -5  # 1 count per degree, rounded
    assert sample.theta_rad == pytest.approx(math.radians(-5.0))
    assert sample.flags & FLAG_HELD


def test_seeded_noise_is_reproducible(config):
    config["rig"]["angle_noise_rad"] = 0.01
    config["rig"]["current_noise_a"] = 0.01

    def samples(seed):
        config["rig"]["noise_seed"] = seed
        rig = open_rig(rig_parts(config))
        rig.configure()
        return [(s.arm_counts, s.current_a) for s in (rig.read(k * MS, MS) for k in range(50))]

    assert samples(3) == samples(3)
    assert samples(3) != samples(4)


def test_sequence_numbers_and_device_time(config):
    rig = open_rig(rig_parts(config))
    rig.configure()
    first, second = rig.read(5 * MS, 0), rig.read(6 * MS, MS)
    assert second.seq == first.seq + 1
    assert (first.device_time_us, second.device_time_us) == (0, 1000)

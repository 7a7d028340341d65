"""Backends declare what they can do: the runner and the verbs ask, they do not probe."""

from __future__ import annotations

from sashil.drivers import open_rig, rig_parts
from sashil.drivers.interface import RigCapabilities, capabilities_of
from sashil.engine.resolve import default_config


def _config(name: str, pacing: str = "device") -> dict:
    config = default_config()
    config["driver"].update(name=name, port="/dev/not-opened-here", pacing=pacing, can_interface="virtual")
    return config


def test_each_backend_declares_its_capabilities():
    sim = open_rig(rig_parts(default_config()))
    assert sim.capabilities == RigCapabilities(
        operator_hold=True,
        initial_current=True,
        road_actuator=True,
        max_rate_hz=10_000.0,
        simulated=True,
        true_torque=True,
    )
    serial = open_rig(rig_parts(_config("serial")))  # nothing is opened before configure()
    assert serial.capabilities == RigCapabilities(road_actuator=True, device_paced=True, link=True)
    assert open_rig(rig_parts(_config("serial", "host"))).capabilities.device_paced is False
    can = open_rig(rig_parts(_config("can")))
    assert can.capabilities.can_frames and can.capabilities.link and not can.capabilities.operator_hold


def test_the_simulated_rig_reports_its_plants_true_torque_and_a_link_does_not():
    import math

    import pytest

    from sashil.drivers.interface import RigCommand

    config = default_config()
    config["controller"]["current_a"] = 0.5
    sim = open_rig(rig_parts(config))
    sim.configure()
    sim.activate()
    sim.write(RigCommand(0.5, road_speed_rad_s=2.0), 0, 0)
    for k in range(1, 40):
        sim.read(k * 1_000_000, 1_000_000)
    truth, plant = sim.plant_truth(), sim.plant
    state, p = plant.state, plant.params
    # seed 001 eq. 9: T = (alpha1 + alpha2 i) z + (c1 + c2 i) theta_dot; eq. 13: J theta2_ddot = -k theta - T
    torque = (p.alpha1 + p.alpha2 * state.current_a) * state.z + (p.c1 + p.c2 * state.current_a) * state.theta_dot_rad_s
    assert truth.damper_torque_nm == pytest.approx(torque, rel=1e-12) and abs(torque) > 1e-3
    assert truth.arm_accel_rad_s2 == pytest.approx((-p.k * state.theta_rad - torque) / p.J, rel=1e-12)
    assert math.isfinite(truth.arm_accel_rad_s2)
    serial = open_rig(rig_parts(_config("serial")))
    assert not serial.capabilities.true_torque
    with pytest.raises(NotImplementedError, match="serial: the backend does not report the plant's true torque"):
        serial.plant_truth()


def test_a_stand_in_without_a_declaration_is_a_bare_rig():
    class StandIn:
        capabilities = "not a declaration"

    assert capabilities_of(object()) == RigCapabilities() == capabilities_of(StandIn())


def test_a_can_trace_on_a_backend_without_can_frames_is_refused_in_one_line(tmp_path):
    import pytest

    from sashil.errors import ConfigError
    from sashil.recording.can_trace import CanTrace

    trace = CanTrace.for_formats(tmp_path, ["asc"])
    assert trace is not None
    with pytest.raises(ConfigError, match="the serial backend has no CAN frames to trace"):
        trace.attach(open_rig(rig_parts(_config("serial"))))

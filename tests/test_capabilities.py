"""Backends declare what they can do: the runner and the verbs ask, they do not probe."""

from __future__ import annotations

from sashil.config import default_config
from sashil.drivers import open_rig
from sashil.drivers.interface import RigCapabilities, capabilities_of


def _config(name: str, pacing: str = "device") -> dict:
    config = default_config()
    config["driver"].update(name=name, port="/dev/not-opened-here", pacing=pacing, can_interface="virtual")
    return config


def test_each_backend_declares_its_capabilities():
    sim = open_rig(default_config())
    assert sim.capabilities == RigCapabilities(
        operator_hold=True, initial_current=True, road_actuator=True, max_rate_hz=10_000.0, simulated=True
    )
    serial = open_rig(_config("serial"))  # nothing is opened before configure()
    assert serial.capabilities == RigCapabilities(road_actuator=True, device_paced=True, link=True)
    assert open_rig(_config("serial", "host")).capabilities.device_paced is False
    can = open_rig(_config("can"))
    assert can.capabilities.can_frames and can.capabilities.link and not can.capabilities.operator_hold


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
        trace.attach(open_rig(_config("serial")))

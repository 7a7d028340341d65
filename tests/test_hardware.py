"""Tests against a real rig, only when asked for (no hardware in CI).

    SASHIL_TEST_SERIAL_PORT=/dev/ttyACM0 pytest tests/test_hardware.py    # the board over serial
    SASHIL_TEST_CAN_CHANNEL=can0 SASHIL_TEST_CAN_INTERFACE=socketcan pytest tests/test_hardware.py

The rig must be free to move and nobody's hand near the arm: the tests command up to 0.2 A.
"""

from __future__ import annotations

import itertools
import os

import pytest

from sashil.drivers import open_rig, rig_parts
from sashil.drivers.interface import RigCommand
from sashil.engine import assemble
from sashil.runtime.clock import RealClock
from sashil.runtime.runner import run_plan

SERIAL_PORT = os.environ.get("SASHIL_TEST_SERIAL_PORT")
CAN_CHANNEL = os.environ.get("SASHIL_TEST_CAN_CHANNEL")


class _Probe:
    """Commands a small current for one second and keeps the samples."""

    def __init__(self, cycles: int):
        self.cycles, self.samples, self.command = cycles, [], RigCommand(0.2)

    def step(self, sample, t_ns, dt_ns):
        self.samples.append(sample)
        return self.command if len(self.samples) < self.cycles else None


def _exercise(config):
    rig = open_rig(rig_parts(config))
    probe = _Probe(cycles=int(config["loop"]["rate_hz"]))
    rate = config["loop"]["rate_hz"]
    outcome = run_plan(assemble(config), rig, probe, RealClock.for_rate(config["loop"]["spin_margin_us"], rate))
    assert outcome.exit_status == "ok" and outcome.error is None  # the safety supervisor ran beside it
    seqs = [s.seq for s in probe.samples]
    assert all((b - a) % 65536 >= 1 for a, b in itertools.pairwise(seqs)), "sequence numbers advance"
    assert abs(probe.samples[-1].current_a - 0.2) < 0.05, "the coil follows the command"


@pytest.mark.skipif(not SERIAL_PORT, reason="set SASHIL_TEST_SERIAL_PORT to test a rig over serial")
def test_serial_rig_follows_a_small_current(config):
    config["driver"].update(name="serial", port=SERIAL_PORT)
    _exercise(config)


@pytest.mark.skipif(
    not CAN_CHANNEL, reason="set SASHIL_TEST_CAN_CHANNEL (and SASHIL_TEST_CAN_INTERFACE) to test a rig over CAN"
)
def test_can_rig_follows_a_small_current(config):
    config["driver"].update(
        name="can", port=CAN_CHANNEL, can_interface=os.environ.get("SASHIL_TEST_CAN_INTERFACE", "socketcan")
    )
    _exercise(config)

"""Link gaps (drivers/link_rig.py): 0 A after the sample timeout, ride through, or end at link-lost.

A scripted device behind the LinkRig contract: ``_receive`` answers at once (it never sleeps), so
the waits spin on the clock for a few milliseconds and the outcome depends only on the script:
which samples the device sends and when it answers a command.
"""

from __future__ import annotations

import pytest

from sashil.drivers import rig_parts
from sashil.drivers.interface import RigCommand
from sashil.drivers.link_rig import LinkRig, LinkSettings
from sashil.drivers.messages import CMD_ENABLE, Command, Sample
from sashil.engine.resolve import default_config
from sashil.errors import DriverTimeoutError


class ScriptedLink(LinkRig):
    """A device that streams samples until ``silent`` is set; ``answer_zero`` ends the silence when 0 A comes."""

    def __init__(self, config: dict, answer_zero: bool):
        super().__init__(LinkSettings(rig_parts(config, "serial").values))
        self.answer_zero = answer_zero
        self.silent = False
        self.sent: list[Command] = []
        self._seq = 0
        self._queue: list = []

    def describe(self) -> str:
        return "scripted rig"

    def _open(self) -> None:
        pass

    def _close_link(self) -> None:
        pass

    def _handshake(self) -> None:  # the handshake has its own tests; this device is always willing
        pass

    def _send(self, seq: int, msg) -> None:
        if isinstance(msg, Command):
            self.sent.append(msg)
            if self.silent and self.answer_zero and msg.current_a == 0.0 and msg.flags & CMD_ENABLE:
                self.silent = False

    def _receive(self, timeout_s: float):
        if self.silent:
            return []
        self._seq += 1
        return [(self._seq, Sample(self._seq * 1000, 0, 0, 0.5, 0))]


def config(sample_timeout_ms: float, link_lost_ms: float) -> dict:
    cfg = default_config()
    cfg["driver"].update(name="serial", port="scripted", sample_timeout_ms=sample_timeout_ms, link_lost_ms=link_lost_ms)
    return cfg


def active(rig: ScriptedLink) -> ScriptedLink:
    rig.configure()
    rig.activate()
    rig.read(0, 0)
    rig.write(RigCommand(0.8), 0, 0)
    return rig


def test_a_gap_gets_zero_current_and_the_run_goes_on():
    rig = active(ScriptedLink(config(2.5, 200.0), answer_zero=True))
    rig.silent = True
    sample = rig.read(0, 0)
    assert sample.seq == 2  # the first sample after the gap
    assert rig.sent[-2:] == [Command(0.8, CMD_ENABLE), Command(0.0, CMD_ENABLE)]  # 0 A, still enabled
    stats = rig.link_stats()
    assert stats["gaps"] == 1 and stats["timeouts"] == 0
    assert 2.5 <= stats["zero_current_after_ms"] <= stats["gap_max_ms"] < 200.0
    rig.write(RigCommand(0.8), 0, 0)  # the loop's next command flows again
    assert rig.sent[-1] == Command(0.8, CMD_ENABLE)


def test_a_lost_link_ends_after_link_lost_with_the_current_already_at_zero():
    rig = active(ScriptedLink(config(2.5, 6.0), answer_zero=False))
    rig.silent = True
    with pytest.raises(DriverTimeoutError) as err:
        rig.read(0, 0)
    assert (
        str(err.value)
        == "scripted rig: no sample for 6 ms (device stalled or link lost; current set to 0 A after 2.5 ms)"
    )
    assert rig.sent[-1] == Command(0.0, CMD_ENABLE)
    assert rig.link_stats()["timeouts"] == 1 and rig.link_stats()["gaps"] == 0


def test_link_lost_at_or_below_the_sample_timeout_ends_at_the_timeout():
    rig = active(ScriptedLink(config(2.5, 0.0), answer_zero=True))
    rig.silent = True
    with pytest.raises(
        DriverTimeoutError, match=r"^scripted rig: no sample for 2.5 ms \(device stalled or link lost\)$"
    ):
        rig.read(0, 0)


def test_a_garbled_slcan_line_is_a_bad_frame_not_a_lost_link():
    """python-can's slcan raises ValueError on a line it cannot parse (and has dropped it already)."""
    import can

    from sashil.drivers.can_codec import encode
    from sashil.drivers.can_rig import CanRig

    frames = [
        can.Message(arbitration_id=i, data=d, is_extended_id=False)
        for i, d in encode(Sample(1000, 10, -3, 0.25, 0), seq=5)
    ]

    class GarbledFirst:
        def __init__(self):
            self.queue = ["garbled", *frames]

        def recv(self, timeout):
            item = self.queue.pop(0) if self.queue else None
            if item == "garbled":
                raise ValueError("non-hexadecimal number found in fromhex() arg at position 1")
            return item

    rig = CanRig(LinkSettings(rig_parts(config(2.5, 25.0), "can").values), interface="virtual")
    rig._bus = GarbledFirst()
    assert rig._receive(0.0) == []  # the garbled line: counted, nothing decoded, the link stays up
    got = rig._receive(0.0)
    assert [msg for _, msg in got] == [Sample(1000, 10, -3, 0.25, 0)]
    assert rig.codec_counters()["bad_lines"] == 1 and rig.codec_counters()["bad_frames"] == 1

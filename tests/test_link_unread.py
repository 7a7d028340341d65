"""A handshake's answer and what came with it (drivers/link_rig.py): the messages decoded in the
same read as the Status that answers Configure are the cycle's first, not dropped.

A scripted device behind the LinkRig contract: ``_receive`` hands back its chunks in order and then
nothing, at once, so a message the rig dropped would show as a missing sample, never as a wait.
"""

from __future__ import annotations

from sashil.drivers import rig_parts
from sashil.drivers.link_rig import LinkRig, LinkSettings
from sashil.drivers.messages import PROTOCOL_VERSION, Message, Sample, Status, Version
from sashil.engine.resolve import default_config


class ChunkedLink(LinkRig):
    """A device whose reads return ``chunks`` one per call, then nothing."""

    def __init__(self, chunks: list[list[Message]]):
        config = default_config()
        config["driver"].update(name="serial", port="scripted", sample_timeout_ms=1.0, link_lost_ms=1.0)
        super().__init__(LinkSettings(rig_parts(config, "serial").values))
        self.chunks = chunks
        self._seq = 0

    def describe(self) -> str:
        return "chunked rig"

    def _open(self) -> None:
        pass

    def _close_link(self) -> None:
        pass

    def _send(self, seq: int, msg: Message) -> None:
        pass

    def _receive(self, timeout_s: float) -> list[tuple[int, Message]]:
        if not self.chunks:
            return []
        out = []
        for msg in self.chunks.pop(0):
            self._seq += 1
            out.append((self._seq, msg))
        return out


VERSION = Version(PROTOCOL_VERSION, 4096, 2.0)
FIRST = Sample(1_000, 7, 0, 0.0, 0)


def test_the_sample_read_with_the_status_that_answers_configure_is_the_first_read():
    rig = ChunkedLink([[VERSION], [Status(0), FIRST]])
    rig.configure()
    rig.activate()
    sample = rig.read(0, 0)  # no chunk left: the sample can only come from the handshake's read
    assert (sample.seq, sample.arm_counts, sample.device_time_us) == (3, 7, 1_000)
    assert rig.link_stats()["samples"] == 1 and rig.link_stats()["status_frames"] == 0
    rig.close()


def test_a_status_after_the_version_in_one_read_answers_configure():
    rig = ChunkedLink([[VERSION, Status(0, bad_frames=3)], [FIRST]])
    rig.configure()
    assert rig.last_status == Status(0, bad_frames=3)
    rig.close()

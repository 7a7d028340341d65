"""The sashil CAN protocol: the messages of ``messages.py`` as the frames of ``sashil.dbc``.

Encoding and decoding go through the DBC with cantools (measured 2-6 µs per frame on the dev
machine, see ``tools/bench_link.py``; fast enough for a 1 kHz cycle, so there is no hand-packed
path). Values are quantised by the same functions as the serial codec (``messages.py``) and passed
to cantools as raw integers, so both links clamp and round identically.

A sample does not fit one classic 8-byte frame: it travels as SampleA (encoders), SampleEdges (the
encoders' last count changes) and SampleB (sequence, device time, current, flags). One node sends
the three back to back, so they arrive in order; :class:`CanDecoder` completes each SampleB with the
SampleA and SampleEdges right before it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache, lru_cache
from pathlib import Path
from typing import cast

import cantools

from sashil.drivers.messages import (
    EDGE_ARM_UP,
    EDGE_ROAD_UP,
    Command,
    Configure,
    Hello,
    Message,
    RoadSpeed,
    Sample,
    Status,
    Version,
    current_to_wire,
    edge_age_to_wire,
    edge_dirs_to_wire,
    edge_from_wire,
    road_speed_to_wire,
)

DBC_PATH = Path(__file__).with_name("sashil.dbc")

ID_COMMAND = 0x100
ID_SAMPLE_A = 0x110
ID_SAMPLE_B = 0x111
ID_SAMPLE_EDGES = 0x112
ID_ROAD_SPEED = 0x120
ID_STATUS = 0x180
ID_CONFIGURE = 0x1F0
ID_HELLO = 0x1F1
ID_VERSION = 0x1F2

#: frames the host sends / the rig sends (for receive filters)
HOST_IDS = (ID_COMMAND, ID_ROAD_SPEED, ID_CONFIGURE, ID_HELLO)
RIG_IDS = (ID_SAMPLE_A, ID_SAMPLE_EDGES, ID_SAMPLE_B, ID_STATUS, ID_VERSION)


@lru_cache(maxsize=1)
def database() -> cantools.database.can.Database:
    """The parsed ``sashil.dbc``."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, cantools.database.can.Database)  # a .dbc is a CAN database
    return db


@cache
def _message(frame_id: int) -> cantools.database.can.Message:
    return database().get_message_by_frame_id(frame_id)


def _pack(frame_id: int, raw: dict[str, int]) -> tuple[int, bytes]:
    return frame_id, bytes(_message(frame_id).encode(raw, scaling=False, strict=False))


def encode(msg: Message, seq: int = 0) -> list[tuple[int, bytes]]:
    """The CAN frames ``[(arbitration id, data), ...]`` carrying ``msg`` (three for a Sample)."""
    if isinstance(msg, Sample):
        return [
            _pack(ID_SAMPLE_A, {"ArmCounts": msg.arm_counts, "RoadCounts": msg.road_counts}),
            _pack(
                ID_SAMPLE_EDGES,
                {
                    "ArmEdgeAge": edge_age_to_wire(msg.arm_edge_age_us),
                    "RoadEdgeAge": edge_age_to_wire(msg.road_edge_age_us),
                    "EdgeDirs": edge_dirs_to_wire(msg.arm_edge_dir, msg.road_edge_dir),
                },
            ),
            _pack(
                ID_SAMPLE_B,
                {
                    "SampleSeq": seq & 0xFFFF,
                    "DeviceTimeUs": msg.device_time_us & 0xFFFFFF,
                    "CurrentMeas": current_to_wire(msg.current_a, signed=True),
                    "SampleFlags": msg.flags & 0xFF,
                },
            ),
        ]
    if isinstance(msg, Command):
        raw = {
            "CmdSeq": seq & 0xFFFF,
            "CurrentCmd": current_to_wire(msg.current_a, signed=False),
            "CmdFlags": msg.flags & 0xFF,
        }
        return [_pack(ID_COMMAND, raw)]
    if isinstance(msg, RoadSpeed):
        return [_pack(ID_ROAD_SPEED, {"RoadSpeedCmd": road_speed_to_wire(msg.speed_rad_s)})]
    if isinstance(msg, Status):
        raw = {
            "StatusFlags": msg.flags & 0xFF,
            "FaultCode": msg.fault_code & 0xFF,
            "BadFrames": msg.bad_frames & 0xFFFF,
            "WatchdogTrips": msg.watchdog_trips & 0xFFFF,
        }
        return [_pack(ID_STATUS, raw)]
    if isinstance(msg, Hello):
        return [_pack(ID_HELLO, {"HelloVersion": msg.protocol_version & 0xFF})]
    if isinstance(msg, Version):
        raw = {
            "ProtocolVersion": msg.protocol_version & 0xFF,
            "CountsPerRev": msg.counts_per_rev,
            "CurrentMax": current_to_wire(msg.current_max_a, signed=False),
        }
        return [_pack(ID_VERSION, raw)]
    if isinstance(msg, Configure):
        return [_pack(ID_CONFIGURE, {"SampleRateHz": msg.rate_hz, "WatchdogMs": msg.watchdog_ms, "Pacing": msg.pacing})]
    raise TypeError(f"not a sashil message: {msg!r}")


@dataclass
class CanCounters:
    frames: int = 0  # frames decoded
    unknown_id: int = 0  # frames with an id that is not in the DBC (ignored)
    bad_length: int = 0  # a known id with the wrong data length
    unpaired: int = 0  # a sample's frame without the others of its sample (A, edges, B), or out of order
    bad_lines: int = 0  # adapter lines the CAN library could not parse (an SLCAN line garbled on the wire)

    @property
    def bad_frames(self) -> int:
        return self.bad_length + self.unpaired + self.bad_lines

    def as_dict(self) -> dict[str, int]:
        return {
            "frames": self.frames,
            "bad_frames": self.bad_frames,
            "unknown_id": self.unknown_id,
            "bad_length": self.bad_length,
            "unpaired": self.unpaired,
            "bad_lines": self.bad_lines,
        }


@dataclass
class CanDecoder:
    """Turns received CAN frames back into ``(seq, message)``; joins SampleA, SampleEdges, SampleB."""

    counters: CanCounters = field(default_factory=CanCounters)
    _sample_a: dict[str, float] | None = None
    _sample_edges: dict[str, float] | None = None

    def feed(self, frame_id: int, data: bytes) -> tuple[int, Message] | None:
        """The message completed by this frame, or None (first half of a sample, unknown id)."""
        counters = self.counters
        try:
            spec = _message(frame_id)
        except KeyError:
            counters.unknown_id += 1
            return None
        if len(data) != spec.length:
            counters.bad_length += 1
            return None
        counters.frames += 1
        sig = cast("dict[str, float]", spec.decode(data, decode_choices=False))  # numbers: no choices decoded
        if frame_id == ID_SAMPLE_A:
            if self._sample_a is not None or self._sample_edges is not None:
                counters.unpaired += 1  # the sample before never completed
            self._sample_a, self._sample_edges = sig, None
            return None
        if frame_id == ID_SAMPLE_EDGES:
            if self._sample_a is None or self._sample_edges is not None:
                counters.unpaired += 1
                self._sample_a = None
                return None
            self._sample_edges = sig
            return None
        if frame_id == ID_SAMPLE_B:
            part_a, edges = self._sample_a, self._sample_edges
            self._sample_a = self._sample_edges = None
            if part_a is None or edges is None:
                counters.unpaired += 1
                return None
            dirs = int(edges["EdgeDirs"])
            sample = Sample(
                int(sig["DeviceTimeUs"]),
                int(part_a["ArmCounts"]),
                int(part_a["RoadCounts"]),
                float(sig["CurrentMeas"]),
                int(sig["SampleFlags"]),
                *edge_from_wire(int(edges["ArmEdgeAge"]), dirs, EDGE_ARM_UP),
                *edge_from_wire(int(edges["RoadEdgeAge"]), dirs, EDGE_ROAD_UP),
            )
            return int(sig["SampleSeq"]), sample
        if frame_id == ID_COMMAND:
            return int(sig["CmdSeq"]), Command(float(sig["CurrentCmd"]), int(sig["CmdFlags"]))
        if frame_id == ID_ROAD_SPEED:
            return 0, RoadSpeed(float(sig["RoadSpeedCmd"]))
        if frame_id == ID_STATUS:
            return 0, Status(
                int(sig["StatusFlags"]), int(sig["FaultCode"]), int(sig["BadFrames"]), int(sig["WatchdogTrips"])
            )
        if frame_id == ID_HELLO:
            return 0, Hello(int(sig["HelloVersion"]))
        if frame_id == ID_VERSION:
            return 0, Version(int(sig["ProtocolVersion"]), int(sig["CountsPerRev"]), float(sig["CurrentMax"]))
        if frame_id == ID_CONFIGURE:
            return 0, Configure(int(sig["SampleRateHz"]), int(sig["WatchdogMs"]), int(sig["Pacing"]))
        counters.unknown_id += 1  # in the DBC but not a message this protocol knows
        return None


def frame_bits(data_bytes: int, worst_case_stuffing: bool = True) -> int:
    """Bits on the bus for one classic CAN frame with an 11-bit id and ``data_bytes`` bytes.

    Fixed fields: SOF 1, id 11, RTR 1, IDE 1, r0 1, DLC 4, CRC 15, CRC delimiter 1, ACK 2, EOF 7 and
    intermission 3 = 47 bits plus 8 per data byte. Bit stuffing covers SOF..CRC (34 + 8n bits) and
    adds at most one bit per 4 after the first: floor((34 + 8n - 1) / 4).
    """
    bits = 47 + 8 * data_bytes
    if worst_case_stuffing:
        bits += (34 + 8 * data_bytes - 1) // 4
    return bits

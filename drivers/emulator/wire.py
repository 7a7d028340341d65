"""What moves between an emulated board and its link: decoded protocol messages (the Python board)
or the wire itself (the C board, which frames and parses its own bytes)."""

from __future__ import annotations

from dataclasses import dataclass

from sashil.drivers.messages import Message


@dataclass(frozen=True)
class WireBytes:
    """Bytes as the link carried them (a raw transport hands these to a board that frames itself)."""

    data: bytes


@dataclass(frozen=True)
class WireCan:
    """One classic CAN frame with an 11-bit id, as the bus carried it."""

    can_id: int
    data: bytes


#: what a transport moves: decoded messages (the Python board) or the wire itself (the C board)
Payload = Message | WireBytes | WireCan

"""How many exchanges a second the RT-DAC/USB2's USB link can carry, from its speed and packet size.

One loop cycle is one exchange (:mod:`~sashil.drivers.rtdac_codec`): a 504-byte write frame to
endpoint 2, the 4-byte read request to endpoint 2, a 504-byte read frame from endpoint 4, three
bulk transfers one after another. A bulk transfer is cut into packets of the endpoint's
``wMaxPacketSize`` (at most 64 bytes at full speed, 512 at high speed), and each packet is one bus
transaction (token, data, handshake). USB 2.0 section 5.11.3 gives the bus time of a
non-isochronous transaction of ``n`` data bytes, handshake included, with the worst-case bit
stuffing ``BitStuffTime(n) = 8 n 7/6`` bits (host delay left out: it only adds):

* full speed (12 Mbit/s): ``9107 + 83.54 floor(3.167 + BitStuffTime(n))`` ns;
* high speed (480 Mbit/s): ``55 * 8 * 2.083 + 2.083 floor(3.167 + BitStuffTime(n))`` ns.

At full speed with 64-byte packets a 504-byte frame is 7 packets of 64 bytes and one of 56:
7 x 59.23 us + 52.97 us = 467.6 us; the read request, one packet of 4 bytes, 12.4 us. An exchange
is then 467.6 + 12.4 + 467.6 = 947.6 us of bus time, so the bus carries at most 1055 exchanges a
second with nothing else on it; a loop that also leaves a fifth of each period to its own work
(:data:`LOOP_SHARE`, as ``sashil doctor`` judges a measured exchange) runs at most at 844 Hz. A
1 kHz loop does not fit on a full-speed link. At high speed with 512-byte packets the exchange is
22.4 us of bus time (35 647 Hz for the loop): the bus is then not what limits the rate.

Bulk transfers are not defined for a low-speed device (USB 2.0 section 5.8): none can be carried.
A SuperSpeed link has other formulas (USB 3.x); its limit is left unknown (None).
"""

from __future__ import annotations

import math

from sashil.drivers.rtdac_codec import FRAME_BYTES, READ_REQUEST

#: libusb's speed codes (pyusb's ``Device.speed``; ``usb.util.SPEED_*``)
SPEED_UNKNOWN, SPEED_LOW, SPEED_FULL, SPEED_HIGH, SPEED_SUPER = 0, 1, 2, 3, 4
#: each speed in words, and its bit rate
SPEED_WORDS = {
    SPEED_LOW: ("low-speed", "1.5 Mbit/s"),
    SPEED_FULL: ("full-speed", "12 Mbit/s"),
    SPEED_HIGH: ("high-speed", "480 Mbit/s"),
    SPEED_SUPER: ("SuperSpeed", "5 Gbit/s"),
}
#: the part of a period the loop's own work needs beside the exchange: the highest rate is
#: ``1 / (exchange time * (1 + LOOP_SHARE))``
LOOP_SHARE = 0.25


def speed_words(speed: int | None) -> str:
    """``"full-speed (12 Mbit/s)"``, or ``"of unknown speed"``."""
    if speed not in SPEED_WORDS:
        return "of unknown speed"
    name, rate = SPEED_WORDS[speed]
    return f"{name} ({rate})"


def bit_stuff_bits(n: int) -> float:
    """The worst-case bits on the wire for ``n`` data bytes, one stuffed bit per six (USB 2.0 5.11.3)."""
    return 8.0 * n * 7.0 / 6.0


def transaction_ns(speed: int, n: int) -> float:
    """The bus time [ns] of one bulk transaction of ``n`` data bytes at ``speed`` (USB 2.0 5.11.3)."""
    stuffed = math.floor(3.167 + bit_stuff_bits(n))
    if speed == SPEED_FULL:
        return 9107.0 + 83.54 * stuffed
    if speed == SPEED_HIGH:
        return 55 * 8 * 2.083 + 2.083 * stuffed
    raise ValueError(f"no bulk transaction time for speed code {speed}")


def transfer_ns(speed: int, size: int, max_packet: int) -> float:
    """The bus time [ns] of a bulk transfer of ``size`` bytes cut into ``max_packet``-byte packets."""
    full, rest = divmod(size, max_packet)
    return full * transaction_ns(speed, max_packet) + (transaction_ns(speed, rest) if rest else 0.0)


def exchange_ns(speed: int, out_packet: int, in_packet: int) -> float:
    """The bus time [ns] of one exchange: the write frame and the read request out, the read frame in."""
    out = transfer_ns(speed, FRAME_BYTES, out_packet) + transfer_ns(speed, len(READ_REQUEST), out_packet)
    return out + transfer_ns(speed, FRAME_BYTES, in_packet)


def highest_rate_hz(exchange_s: float) -> int:
    """The highest loop rate an exchange of ``exchange_s`` leaves room for, with :data:`LOOP_SHARE`."""
    return math.floor(1.0 / (exchange_s * (1.0 + LOOP_SHARE)))


def link_limits(speed: int | None, out_packet: int, in_packet: int) -> tuple[int | None, int | None]:
    """The exchanges a second the link carries at most, and the loop rate it leaves room for; (0, 0)
    on a low-speed link, (None, None) when the speed is unknown or SuperSpeed."""
    if speed == SPEED_LOW:
        return 0, 0
    if speed not in (SPEED_FULL, SPEED_HIGH) or out_packet <= 0 or in_packet <= 0:
        return None, None
    assert speed is not None
    seconds = exchange_ns(speed, out_packet, in_packet) * 1e-9
    return math.floor(1.0 / seconds), highest_rate_hz(seconds)

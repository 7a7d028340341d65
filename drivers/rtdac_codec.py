"""The RT-DAC/USB2's frames and register values: pure encoding and decoding, no I/O.

The board (INTECO's RT-DAC/USB2: a Cypress USB controller in front of an FPGA) exchanges its whole
register file in fixed frames on two bulk endpoints. The facts, from the public source
is-centre/rtdacusb2-bridge-app (``RTDACUSB2-Windows-UDP-Bridge_app/RTDACUSB2_Basic/``):

* ``RTDACUSB2.cs`` lines 74-77: endpoint 2 carries frames to the FPGA, endpoint 4 from it.
* ``RTDACUSB2.cs`` lines 153-164: a read sends ``FF 8F 00 00`` to endpoint 2, then reads 504 bytes
  from endpoint 4: 252 words, each little-endian (``256 * byte[2i+1] + byte[2i]``).
* ``RTDACUSB2.cs`` lines 170-181: a write sends 504 bytes to endpoint 2: ``0F 8F``, then words 1 to
  251, each low byte first and its high byte masked to 7 bits (a written word holds 15 bits).
* ``RTDACBoard.cs`` lines 837-853: an A/D value is 12 bits, two's complement, ``10 V * v / 2048 /
  gain``; gain codes 0-4 are x1, x2, x4, x8, x16 (line 811); the busy bit is bit 12 (the maps).
* ``RTDACBoard.cs`` lines 798-805: a D/A value is 14 bits, ``-10 V + 20 V * v / 16383``; a voltage
  is written as ``(uint)(16383 * (10 + V) / 20)`` after clipping to ±10 V, so 0 V is 8191.
* ``RTDACBoard.cs`` lines 127-140: a PWM width is 12 bits in 12-bit mode, 8 in 8-bit mode.
* ``RTDACUSB2_0103.cs`` lines 35-57: the header (words 0-8) holds the logic version, six characters
  of application name, the synthesis date and 4-bit module counts.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

#: bulk endpoint that carries frames to the FPGA (RTDACUSB2.cs lines 74-75)
ENDPOINT_OUT = 0x02
#: bulk endpoint that carries frames from the FPGA (RTDACUSB2.cs lines 76-77); IN direction bit set
ENDPOINT_IN = 0x84
#: words in a frame, and bytes (RTDACUSB2.cs lines 160, 170)
FRAME_WORDS = 252
FRAME_BYTES = 2 * FRAME_WORDS
#: what asks the FPGA for a read frame (RTDACUSB2.cs lines 153-157)
READ_REQUEST = bytes((0xFF, 0x8F, 0x00, 0x00))
#: the first two bytes of a write frame (RTDACUSB2.cs lines 172-173)
WRITE_MARK = bytes((0x0F, 0x8F))
#: what a written word can hold: its high byte is masked to 7 bits (RTDACUSB2.cs line 177)
WRITE_MASK = 0x7FFF

AD_BITS = 12
AD_FULL_SCALE_V = 10.0
AD_BUSY_BIT = 1 << 12
#: A/D gain code -> gain (RTDACBoard.cs line 811)
AD_GAINS = (1, 2, 4, 8, 16)
DA_MAX = 0x3FFF  # 14 bits (RTDACUSB2_0103.cs line 146)
DA_SPAN_V = 20.0
#: the D/A word for 0 V, as the public app computes it (RTDACBoard.cs line 804: truncation)
DA_ZERO = int(DA_MAX * 10.0 / DA_SPAN_V)
#: PWM width bits by mode (RTDACBoard.cs lines 130-133)
PWM_MAX = {"12-bit": 0x0FFF, "8-bit": 0x00FF}
PWM_MODE_CODE = {"8-bit": 0, "12-bit": 1}  # RTDACBoard.cs line 113

_WORDS = struct.Struct(f"<{FRAME_WORDS}H")


def decode_frame(data: Any) -> tuple[int, ...]:
    """The 252 words of a read frame (little-endian; any buffer: bytes, pyusb's array), or ValueError
    naming the wrong length."""
    if len(data) != FRAME_BYTES:
        raise ValueError(f"a frame of {len(data)} bytes, expected {FRAME_BYTES}")
    return _WORDS.unpack(data)


def encode_write(words: list[int] | tuple[int, ...]) -> bytes:
    """A write frame for ``words`` (252 of them; word 0 is replaced by the mark ``0F 8F``): each
    later word little-endian with its high byte masked to 7 bits (RTDACUSB2.cs lines 172-178)."""
    if len(words) != FRAME_WORDS:
        raise ValueError(f"{len(words)} words, expected {FRAME_WORDS}")
    frame = bytearray(_WORDS.pack(0, *(w & WRITE_MASK for w in words[1:])))
    frame[0:2] = WRITE_MARK
    return bytes(frame)


def counter32(low: int, high: int) -> int:
    """A 32-bit counter from its two words (low word first), as a signed count."""
    value = (high << 16) | low
    return value - (1 << 32) if value & 0x8000_0000 else value


def ad_volts(word: int, gain_code: int = 0) -> float:
    """An A/D word's voltage: 12-bit two's complement, ``10 V * v / 2048 / gain``."""
    raw = word & 0x0FFF
    if raw >= 2048:
        raw -= 4096
    return AD_FULL_SCALE_V * raw / 2048.0 / AD_GAINS[gain_code]


def ad_word(volts: float, gain_code: int = 0, busy: bool = False) -> int:
    """The A/D word a board reads for ``volts`` (clipped to the converter's range), busy bit optional."""
    raw = round(volts * AD_GAINS[gain_code] * 2048.0 / AD_FULL_SCALE_V)
    raw = min(max(raw, -2048), 2047) & 0x0FFF
    return raw | (AD_BUSY_BIT if busy else 0)


def da_word(volts: float) -> int:
    """The D/A word for ``volts``, clipped to ±10 V, truncated as the public app does."""
    clipped = min(max(volts, -10.0), 10.0)
    return int(DA_MAX * (10.0 + clipped) / DA_SPAN_V)


def da_volts(word: int) -> float:
    """The voltage of a D/A word."""
    return -10.0 + DA_SPAN_V * (word & DA_MAX) / DA_MAX


def pwm_width(duty: float, mode: str = "12-bit") -> int:
    """The PWM width word for ``duty`` in [0, 1] (clipped; NaN: 0)."""
    top = PWM_MAX[mode]
    if duty != duty:
        return 0
    return round(min(max(duty, 0.0), 1.0) * top)


def pwm_duty(width: int, mode: str = "12-bit") -> float:
    """The duty a PWM width word gives."""
    top = PWM_MAX[mode]
    return (width & top) / top


@dataclass(frozen=True)
class Header:
    """What the board says of itself in words 0-8 of every read frame (RTDACUSB2_0103.cs lines 33-57)."""

    logic_version: int
    application: str
    synthesis_date: str
    #: module name -> count (4 bits each)
    modules: dict[str, int]

    @property
    def logic(self) -> str:
        """The logic version as the public app shows it: four hex digits."""
        return f"{self.logic_version:04X}"

    def describe(self) -> str:
        counts = ", ".join(f"{n} {name}" for name, n in self.modules.items())
        return f"logic {self.logic}, application {self.application!r}, synthesised {self.synthesis_date} ({counts})"


#: (word, shift, module name) of the 4-bit module counts (RTDACUSB2_0103.cs lines 49-57)
MODULE_FIELDS = (
    (6, 0, "pwm"),
    (6, 4, "encoder"),
    (6, 8, "encoder_i"),
    (6, 12, "timer"),
    (7, 0, "counter"),
    (7, 4, "timer_counter"),
    (7, 8, "generator"),
    (7, 12, "frequency_meter"),
    (8, 0, "chronometer"),
)


def _chars(word: int) -> str:
    return "".join(chr(b) if 32 <= b < 127 else "?" for b in ((word >> 8) & 0xFF, word & 0xFF))


def decode_header(words: tuple[int, ...] | list[int]) -> Header:
    """The header of a read frame's words (RTDACUSB2_0103.cs lines 33-57): the application name's six
    characters are word 3's high and low byte, then word 2's, then word 1's; the synthesis date is
    the hex of ``(word 5 << 16) + word 4`` (the app shows it as YYYY-MM-DD)."""
    date = f"{(words[5] << 16) + words[4]:08X}"
    return Header(
        logic_version=words[0],
        application=_chars(words[3]) + _chars(words[2]) + _chars(words[1]),
        synthesis_date=f"{date[0:4]}-{date[4:6]}-{date[6:8]}",
        modules={name: (words[w] >> shift) & 0xF for w, shift, name in MODULE_FIELDS},
    )


def encode_header(logic_version: int, application: str, synthesis_date: str, modules: dict[str, int]) -> list[int]:
    """Words 0-8 of a read frame for these facts (the inverse of :func:`decode_header`)."""
    name = application.ljust(6)[:6].encode("ascii", "replace")
    digits = synthesis_date.replace("-", "")
    date = int(digits, 16)
    words = [0] * 9
    words[0] = logic_version & 0xFFFF
    words[3], words[2], words[1] = ((name[i] << 8) | name[i + 1] for i in (0, 2, 4))
    words[4], words[5] = date & 0xFFFF, date >> 16
    for w, shift, field in MODULE_FIELDS:
        words[w] |= (modules.get(field, 0) & 0xF) << shift
    return words

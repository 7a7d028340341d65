"""LAWICEL SLCAN ASCII protocol, adapter side (pure): what a USB-CAN adapter parses and answers.

The emulator uses it to look like an SLCAN adapter with the rig on its bus, so python-can's own
``slcan`` interface connects to it. Lines end in CR (0x0D); the adapter answers CR for OK and BEL
(0x07) for an error. Subset implemented (the LAWICEL CANUSB manual's command table):

    Sn        set a standard bit rate (S0 10k ... S8 1M), only while closed      -> CR
    sxxyy     set BTR0/BTR1, only while closed                                  -> CR
    O / L     open the channel (L: listen only; again while open: accepted)     -> CR
    C         close the channel                                                 -> CR
    V / N     hardware+software version / serial number                         -> "V1013" CR / "NSASH" CR
    F         status flags                                                      -> "F00" CR
    Zn        time stamps off/on (accepted; no time stamps are sent)            -> CR
    tiiildd.. transmit a standard frame (iii hex id, l length, dd data), open  -> "z" CR
    Tiiiiiiiildd.. transmit an extended frame                                   -> "Z" CR
    riiil / Riiiiiiiil  transmit a remote frame                                 -> "z" CR / "Z" CR

Received bus frames go to the host as the same ``t``/``T`` lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

OK = b"\r"
ERROR = b"\x07"
VERSION_REPLY = b"V1013\r"
SERIAL_REPLY = b"NSASH\r"
MAX_LINE = 32  # longest valid line: T + 8 id + 1 dlc + 16 data = 26

#: S-code -> bit rate [bit/s]
BITRATES = {0: 10_000, 1: 20_000, 2: 50_000, 3: 100_000, 4: 125_000, 5: 250_000, 6: 500_000, 7: 750_000, 8: 1_000_000}


class SlcanError(ValueError):
    """A line that is not a valid SLCAN command."""


#: what a host that expects sashil serial frames sends to learn whether an SLCAN adapter is on the
#: port: an empty line (answered CR) and ``V`` (answered with the version line)
PROBE = b"\rV\r"


def adapter_answer(data: bytes) -> bool:
    """Whether bytes read from a port are an SLCAN adapter's answers: ASCII lines ended by CR, or BEL
    (a refused line), and never the 0x00 that ends every sashil serial frame."""
    text = all(byte in (0x07, 0x0A, 0x0D) or 0x20 <= byte < 0x7F for byte in data)
    return bool(data) and text and (OK in data or ERROR in data)


def format_frame(can_id: int, data: bytes, extended: bool = False) -> bytes:
    """The SLCAN line of a received data frame, e.g. ``t1102ABCD\\r``."""
    if len(data) > 8:
        raise SlcanError(f"classic CAN frame with {len(data)} data bytes")
    head = f"T{can_id:08X}" if extended else f"t{can_id:03X}"
    return f"{head}{len(data)}{data.hex().upper()}\r".encode("ascii")


def parse_frame(line: bytes) -> tuple[int, bytes, bool]:
    """(id, data, extended) of a ``t``/``T`` line (without its CR); SlcanError if malformed."""
    text = line.decode("ascii", "replace")
    if not text or text[0] not in "tT":
        raise SlcanError(f"not a frame line: {text!r}")
    extended = text[0] == "T"
    id_len = 8 if extended else 3
    try:
        can_id = int(text[1 : 1 + id_len], 16)
        dlc = int(text[1 + id_len], 16)
        hex_data = text[2 + id_len :]
        if dlc > 8 or len(hex_data) != 2 * dlc or len(text[1 : 1 + id_len]) != id_len:
            raise ValueError
        data = bytes.fromhex(hex_data)
    except (ValueError, IndexError):
        raise SlcanError(f"malformed frame line: {text!r}") from None
    if can_id >= (1 << (29 if extended else 11)):
        raise SlcanError(f"id out of range: {text!r}")
    return can_id, data, extended


@dataclass
class SlcanAdapter:
    """The adapter's side of the line protocol: feed it host bytes, get replies and bus frames.

    ``feed`` returns ``(reply_bytes, frames)``; ``frames`` are the data frames the host transmitted
    on the bus as ``(id, data, extended)``. Counts lines it refused.
    """

    is_open: bool = False
    listen_only: bool = False
    bitrate: int | None = None
    errors: int = 0  # lines answered with BEL
    _buffer: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes) -> tuple[bytes, list[tuple[int, bytes, bool]]]:
        replies = bytearray()
        frames: list[tuple[int, bytes, bool]] = []
        self._buffer += data
        while True:
            end = self._buffer.find(b"\r")
            if end < 0:
                if len(self._buffer) > MAX_LINE:  # garbage without CR: drop it
                    self._buffer.clear()
                    self.errors += 1
                    replies += ERROR
                break
            line = bytes(self._buffer[:end]).lstrip(b"\n")
            del self._buffer[: end + 1]
            replies += self._handle(line, frames)
        return bytes(replies), frames

    def _handle(self, line: bytes, frames: list[tuple[int, bytes, bool]]) -> bytes:
        if not line:
            return OK  # an empty line (python-can and others send CR to flush)
        cmd = chr(line[0])
        if cmd in "tT":
            if not self.is_open or self.listen_only:
                return self._error()
            try:
                frames.append(parse_frame(line))
            except SlcanError:
                return self._error()
            return b"z\r" if cmd == "t" else b"Z\r"
        if cmd in "rR":
            if not self.is_open or self.listen_only:
                return self._error()
            return b"z\r" if cmd == "r" else b"Z\r"  # remote frames are not used by the rig
        if cmd == "S" and len(line) == 2 and line[1:2].isdigit() and int(line[1:2]) in BITRATES:
            if self.is_open:
                return self._error()
            self.bitrate = BITRATES[int(line[1:2])]
            return OK
        if cmd == "s" and len(line) == 5:
            if self.is_open:
                return self._error()
            return OK
        if cmd in "OL" and len(line) == 1:
            # python-can opens twice (set_bitrate ends with O, then __init__ sends O again): accept
            # a repeated open like the CANable firmware does
            self.is_open, self.listen_only = True, cmd == "L"
            return OK
        if cmd == "C" and len(line) == 1:
            self.is_open = False  # closing a closed channel is harmless
            return OK
        if cmd == "V" and len(line) == 1:
            return VERSION_REPLY
        if cmd == "N" and len(line) == 1:
            return SERIAL_REPLY
        if cmd == "F" and len(line) == 1:
            return b"F00\r"
        if cmd == "Z" and len(line) == 2:
            return OK
        if cmd == "Y" and len(line) == 2:  # CAN FD data bit rate: not supported
            return self._error()
        return self._error()

    def _error(self) -> bytes:
        self.errors += 1
        return ERROR

"""The RT-DAC/USB2's register maps: data files, one per FPGA logic, chosen from the board's header.

A map file (``drivers/rtdac_maps/*.yaml``, or a lab's own in the folder ``rtdac.map_dir`` names)
says at which words of a frame each block sits: the header, digital I/O, PWM, encoder counters, A/D
and D/A. The built-in maps hold the public facts of ``RTDACUSB2_0103.cs`` and ``RTDACUSB2_111.cs``
(is-centre/rtdacusb2-bridge-app), cited line by line in the files. The board's header (word 0: the
logic version; words 1-3: the application name) picks the map; a board no map serves is refused in
one line that names what it sent, the maps known and how to add one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sashil.config.rtdac_map_file import read_map_file
from sashil.drivers.rtdac_codec import FRAME_WORDS, Header
from sashil.errors import ConfigError, DriverError

#: the maps that ship with sashil
BUILTIN_DIR = Path(__file__).with_name("rtdac_maps")


@dataclass(frozen=True)
class RegisterMap:
    """Where each block of one FPGA logic sits in the 252-word frame."""

    logic_version: int
    #: application names the map serves; None: any
    applications: tuple[str, ...] | None
    source: str
    evidence: str
    pin_mode: int
    direction: int
    output: int
    input: int
    pwm_count: int
    pwm_base: int
    pwm_stride: int
    encoder_count: int
    encoder_reset: int
    encoder_index_active: int
    encoder_index_invert: int
    encoder_base: int
    encoder_stride: int
    ad_count: int
    ad_gain_base: int
    ad_value_base: int
    da_count: int
    da_base: int

    @property
    def logic(self) -> str:
        return f"{self.logic_version:04X}"

    def serves(self, header: Header) -> bool:
        """Whether this map reads the board whose header is ``header``."""
        if header.logic_version != self.logic_version:
            return False
        return self.applications is None or header.application.strip() in self.applications

    # word addresses ---------------------------------------------------------------------------
    def pwm_prescaler_word(self, channel: int) -> int:
        return self.pwm_base + self.pwm_stride * channel

    def pwm_mode_word(self, channel: int) -> int:
        return self.pwm_base + self.pwm_stride * channel + 1

    def pwm_width_word(self, channel: int) -> int:
        return self.pwm_base + self.pwm_stride * channel + 2

    def counter_words(self, channel: int) -> tuple[int, int]:
        """(low, high) words of encoder counter ``channel``."""
        low = self.encoder_base + self.encoder_stride * channel
        return low, low + 1

    def ad_value_word(self, channel: int) -> int:
        return self.ad_value_base + channel

    def ad_gain_word(self, channel: int) -> tuple[int, int]:
        """(word, shift) of A/D ``channel``'s 3-bit gain code (four codes a word, RTDACUSB2_0103.cs lines 120-135)."""
        return self.ad_gain_base + channel // 4, 4 * (channel % 4)

    def da_word(self, channel: int) -> int:
        return self.da_base + channel

    def describe(self) -> str:
        apps = "any application" if self.applications is None else "application " + "/".join(self.applications)
        return f"logic {self.logic} ({apps}; {self.source})"


def load_map(path: Path) -> RegisterMap:
    """One map file, checked (:func:`~sashil.config.rtdac_map_file.read_map_file`): a wrong key is
    one line naming the file and the key."""
    return RegisterMap(**read_map_file(path, FRAME_WORDS))


def known_maps(map_dir: str | None = None) -> list[RegisterMap]:
    """The built-in maps, then a lab's own from ``map_dir`` (each ``*.yaml`` there)."""
    paths = sorted(BUILTIN_DIR.glob("*.yaml"))
    if map_dir is not None:
        folder = Path(map_dir).expanduser()
        if not folder.is_dir():
            raise ConfigError(f"rtdac.map_dir: {map_dir} is not a folder")
        paths += sorted(folder.glob("*.yaml"))
    return [load_map(p) for p in paths]


def choose_map(header: Header, maps: list[RegisterMap]) -> RegisterMap:
    """The map that serves the board's header; the last one wins, so a lab's file overrides a built-in
    one. DriverError in one line when none does."""
    for candidate in reversed(maps):
        if candidate.serves(header):
            return candidate
    known = "; ".join(m.describe() for m in maps) or "none"
    raise DriverError(
        f"rtdac: the board runs FPGA logic {header.logic} with application {header.application.strip()!r}, "
        f"which no register map serves (known: {known}); add a map file for it to the folder rtdac.map_dir "
        f"names (the shape of {BUILTIN_DIR / '0103.yaml'})"
    )

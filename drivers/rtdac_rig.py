"""The rtdac backend: INTECO's RT-DAC/USB2 board over USB (pyusb), the rig's wiring from config.

One loop cycle is one exchange with the board: ``write`` sends a write frame with the cycle's
outputs, ``read`` asks for a read frame and decodes it (:mod:`~sashil.drivers.rtdac_codec`). The
register map is chosen from the header of the first frame (:mod:`~sashil.drivers.rtdac_map`); the
wiring (which counter is the arm and which the road wheel, which output drives the coil and which
the road motor, which A/D senses the coil) comes from the ``rtdac`` section, read once into plain
values here.

The coil: the commanded current becomes a PWM duty or a D/A voltage through the power stage's
calibration map, corrected by an integral loop on the sensed current where an A/D senses it
(:class:`~sashil.drivers.rtdac_outputs.CoilDrive`). A sample's ``current_a`` is that sensed current;
with no sense wired it is the commanded current through the coil's first-order lag
(``rig.coil_tau_s``), and :meth:`RtdacRig.link_stats` says which (``current_source``).

The road motor: the host closes its loop on the road encoder
(:class:`~sashil.drivers.rtdac_outputs.RoadDrive`); ``link_stats`` reports how well it tracked.

Safety: the board has no watchdog and keeps its last outputs when the host goes quiet (neither
public register map has a timeout or an enable word). So every stop path ends in
:meth:`RtdacRig.deactivate`, which writes both outputs to rest (duty 0, or the D/A's 0 V) and
confirms it from the board's readback of those registers (and the sensed current, where one is
wired). What no host code covers (the host and the loop both killed, the cable pulled) is the
hardware E-stop's to cover.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Mapping
from typing import Any, ClassVar

from sashil.drivers.interface import TWO_PI, RigCapabilities, RigCommand, RigInterface, RigSample, RigState
from sashil.drivers.rtdac_codec import (
    AD_BUSY_BIT,
    DA_ZERO,
    PWM_MODE_CODE,
    Header,
    ad_volts,
    counter32,
    da_word,
    decode_frame,
    decode_header,
    encode_write,
    pwm_width,
)
from sashil.drivers.rtdac_map import RegisterMap, choose_map, known_maps
from sashil.drivers.rtdac_outputs import CoilDrive, RoadDrive
from sashil.drivers.rtdac_usb import BoardLink, UsbSettings
from sashil.drivers.rtdac_wiring import Wiring
from sashil.errors import DriverError, DriverIOError

log = logging.getLogger("sashil")

#: a sensed coil current at most this confirms the coil at rest (as for sashil's own board)
SAFE_CURRENT_A = 0.02
#: how long deactivate resends the rest frame for a readback (and a sensed current) that confirm it
SAFE_CONFIRM_S = 0.3


class RtdacRig(RigInterface):
    """INTECO's RT-DAC/USB2 (module docstring)."""

    name = "rtdac"

    def __init__(
        self,
        usb: UsbSettings,
        wiring: Wiring,
        current_max_a: float = 1.0,
        coil_tau_s: float = 0.010,
        application: str | None = None,
        map_dir: str | None = None,
        backend: Any = None,
        busy_limit_s: float = 0.025,
    ):
        """``backend``: a pyusb backend object to find the board through (default: the one ``usb``
        names); ``busy_limit_s``: how long the coil sense A/D may stay busy before the run ends."""
        super().__init__()
        self.usb = usb
        self.wiring = wiring
        self.current_max_a = current_max_a
        self.coil_tau_s = coil_tau_s
        self.application = application
        self.map_dir = map_dir
        self.link = BoardLink(usb, backend)
        self.header: Header | None = None
        self.map: RegisterMap | None = None
        self.coil = CoilDrive(
            wiring.coil_map_current_a, wiring.coil_map_output, wiring.coil_loop_ki_per_s, current_max_a
        )
        self.road = RoadDrive(
            wiring.road_output_per_rad_s, wiring.road_kp_per_rad, wiring.road_output_limit, 0.0, wiring.road_lag_s
        )
        self._frame = bytearray()
        self._coil_word = 0
        self._road_word = 0
        self._dir_word: int | None = None
        self._seq = 0
        self._t0_ns: int | None = None
        self._last_t_ns: int | None = None
        self._road_angle = 0.0
        self._sensed_a: float | None = None
        self._modelled_a = 0.0
        self._command_a = 0.0
        self._busy_since_ns: int | None = None
        self._busy_limit_ns = round(busy_limit_s * 1e9)
        self.stats: dict[str, Any] = {"samples": 0, "samples_missed": 0, "timeouts": 0, "watchdog_samples": 0}
        self.safe_state: dict[str, bool | float | None] = {"safe_state_confirmed": None, "safe_state_ms": None}

    #: the config keys the backend is built from (:meth:`from_parts`)
    reads: ClassVar[Mapping[str, str]] = {
        "rtdac": "rtdac",
        "port": "driver.port",
        "link_lost_ms": "driver.link_lost_ms",
        "current_max_a": "rig.current_max_a",
        "coil_tau_s": "rig.coil_tau_s",
    }

    @classmethod
    def from_parts(cls, values: Mapping[str, Any], backend: Any = None) -> RtdacRig:
        """The backend the ``rtdac`` section, ``driver.port`` and the rig's coil describe (nothing
        opened); ``backend``: a pyusb backend object to find the board through."""
        section = values["rtdac"]
        usb = UsbSettings(
            manufacturer=section["manufacturer"],
            serial=section["serial"],
            vendor_id=section["vendor_id"],
            product_id=section["product_id"],
            usb_backend=section["usb_backend"],
            port=values["port"],
            timeout_ms=section["transfer_timeout_ms"],
        )
        return cls(
            usb,
            Wiring.from_section(section),
            current_max_a=values["current_max_a"],
            coil_tau_s=values["coil_tau_s"],
            application=section["application"],
            map_dir=section["map_dir"],
            backend=backend,
            busy_limit_s=max(values["link_lost_ms"], 1.0) * 1e-3,
        )

    @property
    def capabilities(self) -> RigCapabilities:  # type: ignore[override]  # depends on the wiring
        return RigCapabilities(road_actuator=self.wiring.road_output != "none", link=True)

    def describe(self) -> str:
        return self.link.where

    # lifecycle --------------------------------------------------------------------------------
    def configure(self) -> None:
        """Open the board, read its header, choose its register map, check the wiring fits it and put
        both outputs at rest (the board keeps whatever a previous host left)."""
        if self.state is RigState.CLOSED:
            raise DriverError("rtdac: configure() after close()")
        if self.state is not RigState.UNCONFIGURED:
            return
        maps = known_maps(self.map_dir)
        self.link.open()
        try:
            words = decode_frame(self.link.read_frame())
            self.header = decode_header(words)
            if self.application is not None and self.header.application.strip() != self.application:
                raise DriverError(
                    f"rtdac: the board's application is {self.header.application.strip()!r}, "
                    f"rtdac.application asks for {self.application!r} ({self.header.describe()})"
                )
            self.map = choose_map(self.header, maps)
            self._check_wiring(self.header, self.map)
            self._build_frame(words)
            self.link.write_frame(self._frame)
        except DriverError as err:
            self.link.close()
            if type(err) is DriverError:
                raise
            raise DriverError(str(err)) from None  # a board that fails its greeting: nothing energised, exit 2
        except BaseException:
            self.link.close()
            raise
        self.state = RigState.CONFIGURED

    def _check_wiring(self, header: Header, reg: RegisterMap) -> None:
        w = self.wiring
        # the header's module counts where the board reports them, else the map's (a board or an
        # emulator that leaves words 6-8 at 0 reports none)
        pwm = header.modules.get("pwm") or reg.pwm_count
        counters = header.modules.get("encoder_i") or reg.encoder_count

        def need(ok: bool, key: str, what: str) -> None:
            if not ok:
                raise DriverError(f"rtdac.{key}: the board has no {what} ({header.describe()})")

        need(w.arm_encoder < counters, "arm_encoder", f"encoder counter {w.arm_encoder}")
        if w.road_encoder is not None:
            need(w.road_encoder < counters, "road_encoder", f"encoder counter {w.road_encoder}")
        for key, kind, channel in (
            ("coil_channel", w.coil_output, w.coil_channel),
            ("road_channel", w.road_output, w.road_channel),
        ):
            if kind == "pwm":
                need(channel < pwm, key, f"PWM channel {channel}")
            elif kind == "da":
                need(channel < reg.da_count, key, f"D/A channel {channel}")
        if w.coil_sense_ad is not None:
            need(w.coil_sense_ad < reg.ad_count, "coil_sense_ad", f"A/D channel {w.coil_sense_ad}")

    def _build_frame(self, words: tuple[int, ...]) -> None:
        """The write frame: the board's own settings as read, sashil's channels set up, outputs at rest."""
        w, reg = self.wiring, self.map
        assert reg is not None
        image = list(words)
        image[reg.encoder_reset] = 0  # every counter counting
        for kind, channel in ((w.coil_output, w.coil_channel), (w.road_output, w.road_channel)):
            if kind == "pwm":
                mode_word = reg.pwm_mode_word(channel)
                if w.pwm_prescaler is not None:
                    image[reg.pwm_prescaler_word(channel)] = w.pwm_prescaler & 0x7FFF
                    high = (w.pwm_prescaler >> 15) & 1
                else:
                    high = image[mode_word] & 1  # the board's own prescaler stays
                image[mode_word] = (PWM_MODE_CODE[w.pwm_mode] << 1) | high
                image[reg.pwm_width_word(channel)] = 0
            elif kind == "da":
                image[reg.da_word(channel)] = DA_ZERO
        if w.coil_sense_ad is not None:
            word, shift = reg.ad_gain_word(w.coil_sense_ad)
            image[word] &= ~(0x7 << shift)  # gain x1: the full ±10 V range
        self._coil_word = reg.pwm_width_word(w.coil_channel) if w.coil_output == "pwm" else reg.da_word(w.coil_channel)
        if w.road_output == "pwm":
            self._road_word = reg.pwm_width_word(w.road_channel)
        elif w.road_output == "da":
            self._road_word = reg.da_word(w.road_channel)
        if w.road_output == "pwm" and w.road_direction_bit is not None:
            bit = w.road_direction_bit
            self._dir_word = reg.output + (1 if bit >= 15 else 0)
            self._dir_bit = 1 << (bit % 15)
            image[reg.pin_mode + (1 if bit >= 15 else 0)] &= ~self._dir_bit  # GPIO (RTDACBoard.cs line 13)
            image[reg.direction + (1 if bit >= 15 else 0)] &= ~self._dir_bit  # output (line 14)
        self._frame = bytearray(encode_write(image))
        self._rest_words = {self._coil_word: self._coil_rest()}
        if w.road_output != "none":
            self._rest_words[self._road_word] = self._output_word(w.road_output, self.road.rest)

    def _coil_rest(self) -> int:
        return self._output_word(self.wiring.coil_output, self.coil.rest)

    def _output_word(self, kind: str, value: float) -> int:
        if kind == "pwm":
            return pwm_width(abs(value), self.wiring.pwm_mode)
        return da_word(value)

    def _put(self, word: int, value: int) -> None:
        struct.pack_into("<H", self._frame, 2 * word, value & 0x7FFF)

    # raw access for sashil doctor's walk: the outputs by channel, one exchange at a time ------------
    def exchange_frame(self) -> bytes:
        """The write frame as it stands (the next exchange sends it)."""
        return bytes(self._frame)

    def exchange(self) -> tuple[int, ...]:
        """One exchange with the frame as it stands; the read frame's words."""
        self.link.write_frame(self._frame)
        return decode_frame(self.link.read_frame())

    def set_output(self, kind: str, channel: int, value: float) -> None:
        """Set PWM ``channel``'s duty or D/A ``channel``'s volts in the next frame (any channel: the walk
        tries the wiring it is asked to)."""
        reg = self.map
        assert reg is not None
        word = reg.pwm_width_word(channel) if kind == "pwm" else reg.da_word(channel)
        self._put(word, self._output_word(kind, value))

    def rest_outputs(self) -> None:
        """The coil's and the road motor's outputs at rest in the next frame."""
        for word, value in self._rest_words.items():
            self._put(word, value)

    def activate(self) -> None:
        if self.state is not RigState.CONFIGURED:
            raise DriverError(f"{self.describe()}: activate() in state {self.state.value} (configure() first)")
        self.coil.reset()
        self.state = RigState.ACTIVE

    def deactivate(self) -> None:
        """Both outputs to rest and the readback checked (module docstring); never raises."""
        self._command_a = 0.0
        self.road.stop()
        was_active = self.state is RigState.ACTIVE
        if was_active:
            self.state = RigState.CONFIGURED
        if self.link.dev is None or self.map is None:
            return
        start = time.monotonic()
        confirmed = False
        try:
            self.rest_outputs()
            while True:
                self.link.write_frame(self._frame)
                words = decode_frame(self.link.read_frame())
                at_rest = all(words[word] == value for word, value in self._rest_words.items())
                sensed = self._sense(words)
                if at_rest and (sensed is None or abs(sensed) <= max(SAFE_CURRENT_A, 0.02 * self.current_max_a)):
                    confirmed = True
                    break
                if time.monotonic() - start > SAFE_CONFIRM_S:
                    break
        except Exception as err:
            log.warning(
                "%s: deactivate: %s: the board keeps its last outputs (the E-stop is the answer)", self.describe(), err
            )
        self.safe_state["safe_state_confirmed"] = confirmed
        self.safe_state["safe_state_ms"] = round((time.monotonic() - start) * 1e3, 3)
        if not confirmed:
            log.warning("%s: deactivate: the board's readback did not confirm both outputs at rest", self.describe())

    def close(self) -> None:
        if self.state is RigState.CLOSED:
            return
        self.deactivate()
        self.link.close()
        self.state = RigState.CLOSED

    # cycle --------------------------------------------------------------------------------------
    def _sense(self, words: tuple[int, ...]) -> float | None:
        channel = self.wiring.coil_sense_ad
        if channel is None or self.map is None:
            return None
        value = words[self.map.ad_value_word(channel)]
        if value & AD_BUSY_BIT:
            return self._sensed_a  # a conversion under way: the last value stands
        return (ad_volts(value) - self.wiring.coil_sense_offset_v) * self.wiring.coil_sense_a_per_v

    def read(self, t_ns: int, dt_ns: int) -> RigSample:
        if self.state not in (RigState.CONFIGURED, RigState.ACTIVE):
            raise DriverError(f"{self.describe()}: read() in state {self.state.value}")
        words = decode_frame(self.link.read_frame())
        reg, w = self.map, self.wiring
        assert reg is not None
        low, high = reg.counter_words(w.arm_encoder)
        arm = counter32(words[low], words[high]) * (-1 if w.arm_reversed else 1)
        road = 0
        if w.road_encoder is not None:
            low, high = reg.counter_words(w.road_encoder)
            road_raw = counter32(words[low], words[high]) * (-1 if w.road_reversed else 1)
            self._road_angle = road_raw * TWO_PI / w.road_counts_per_rev
            road = round(road_raw * w.arm_counts_per_rev / w.road_counts_per_rev)
        if w.coil_sense_ad is not None:
            if words[reg.ad_value_word(w.coil_sense_ad)] & AD_BUSY_BIT:
                if self._busy_since_ns is None:
                    self._busy_since_ns = t_ns
                elif t_ns - self._busy_since_ns > self._busy_limit_ns:
                    raise DriverIOError(
                        f"{self.describe()}: A/D {w.coil_sense_ad} (the coil current) has stayed busy for "
                        f"{(t_ns - self._busy_since_ns) * 1e-6:.0f} ms (a stuck busy bit)"
                    )
            else:
                self._busy_since_ns = None
            self._sensed_a = self._sense(words)
            current = self._sensed_a if self._sensed_a is not None else math.nan
        else:
            if self._last_t_ns is not None and self.coil_tau_s > 0.0:
                alpha = 1.0 - math.exp(-(t_ns - self._last_t_ns) * 1e-9 / self.coil_tau_s)
                self._modelled_a += alpha * (self._command_a - self._modelled_a)
            else:
                self._modelled_a = self._command_a
            current = self._modelled_a
        if self._t0_ns is None:
            self._t0_ns = t_ns
        self._last_t_ns = t_ns
        self._seq += 1
        self.stats["samples"] += 1
        return RigSample(self._seq, t_ns, (t_ns - self._t0_ns) // 1000, arm, road, current, 0, w.arm_counts_per_rev)

    def write(self, cmd: RigCommand, t_ns: int, dt_ns: int) -> None:
        """The cycle's outputs, in one write frame: the coil's (rest unless active) and the road motor's."""
        if self.map is None or self.link.dev is None:
            return
        dt_s = dt_ns * 1e-9
        if self.state is RigState.ACTIVE:
            self._command_a = (
                min(max(cmd.current_a, 0.0), self.current_max_a) if cmd.current_a == cmd.current_a else 0.0
            )
            coil = self.coil.output(self._command_a, self._sensed_a, dt_s)
            self.road.command(cmd.road_speed_rad_s)
        else:
            self._command_a = 0.0
            coil = self.coil.rest
            self.road.stop()
        w = self.wiring
        self._put(self._coil_word, self._output_word(w.coil_output, coil))
        if w.road_output != "none":
            road = self.road.output(self._road_angle, dt_s)
            self._put(self._road_word, self._output_word(w.road_output, road))
            if self._dir_word is not None:
                offset = 2 * self._dir_word
                value = int.from_bytes(self._frame[offset : offset + 2], "little")
                value = (value | self._dir_bit) if road < 0.0 else (value & ~self._dir_bit)
                self._put(self._dir_word, value)
        self.link.write_frame(self._frame)

    # facts --------------------------------------------------------------------------------------
    def codec_counters(self) -> dict[str, int]:
        return {"bad_frames": 0}

    def link_stats(self) -> dict[str, Any]:
        """Exchanges, what ``current_a`` is, the road's tracking, the header and the last safe-state check."""
        w = self.wiring
        source = (
            f"sensed (A/D {w.coil_sense_ad})"
            if w.coil_sense_ad is not None
            else "commanded through the coil's lag (rig.coil_tau_s; no sense wired)"
        )
        facts: dict[str, Any] = {**self.stats, "bad_frames": 0, "current_source": source, **self.road.tracking()}
        if self.header is not None:
            facts["board"] = self.header.describe()
        if self.map is not None:
            facts["register_map"] = self.map.describe()
        return {**facts, **self.safe_state}


__all__ = ["RtdacRig", "Wiring"]

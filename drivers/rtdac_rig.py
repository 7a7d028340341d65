"""The rtdac backend: INTECO's RT-DAC/USB2 board over USB (pyusb), the rig's wiring from config.

One loop cycle is one exchange with the board: ``read`` asks for a read frame and decodes it
(:mod:`~sashil.drivers.rtdac_codec`), ``write`` sends a write frame built from that read: the board's
own words as read this cycle, with only sashil's words changed (the coil's and the road motor's
output words, the direction and heartbeat bits; at configure the channels' modes, the sense's gain
and the counters' reset). The register map is chosen from the header of the first frame
(:mod:`~sashil.drivers.rtdac_map`); the wiring comes from the ``rtdac`` section, read once into plain
values, and what of it ``sashil doctor --walk`` has not confirmed runs under the bring-up caps
(:mod:`~sashil.drivers.rtdac_bringup`).

The counters: configure, with both outputs at rest and before any plan asks the operator to touch
the arm, pulses the arm's and the road's reset bits, then reads the counters once more and subtracts
what they still show (a board that ignores the reset word): theta2 and theta1 read 0 at the rest the
arm hangs in.

The coil: the commanded current becomes a PWM duty or a D/A voltage through the power stage's
calibration map, corrected by an integral loop on the sensed current where an A/D senses it, within
the loop's authority (:class:`~sashil.drivers.rtdac_outputs.CoilDrive`). A sample's ``current_a`` is
that sensed current; with no sense wired it is NaN: nothing measures it, and the stop says "outputs
at rest (no current sense)".

The road motor: the host closes its loop on the road encoder
(:class:`~sashil.drivers.rtdac_outputs.RoadDrive`); each sample carries the loop's error and whether
its output, or the coil's loop, sat at a bound, for the safety supervisor's road and coil trips.

Safety: the board has no watchdog and keeps its last outputs when the host goes quiet (neither
public register map has a timeout or an enable word). Every stop path ends in
:meth:`RtdacRig.deactivate`, which writes both outputs to rest and confirms it from the board's
readback of those registers, masked to the bits each register holds (and the sensed current where
one is wired), retrying until a deadline. ``rtdac.heartbeat_bit`` toggles a digital output every
cycle for a retriggerable watchdog relay on the power stages: the one path that covers the host
killed outright or the cable pulled.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from sashil.config.parts import RigParts
from sashil.drivers.interface import (
    TWO_PI,
    RigCapabilities,
    RigCommand,
    RigInterface,
    RigSample,
    RigState,
    clamp_current,
)
from sashil.drivers.rtdac_bringup import BringUp
from sashil.drivers.rtdac_codec import (
    AD_BUSY_BIT,
    DA_MAX,
    PWM_MAX,
    PWM_MODE_CODE,
    WRITE_MARK,
    Header,
    ad_volts,
    counter32,
    da_word,
    decode_frame,
    decode_header,
    pwm_width,
)
from sashil.drivers.rtdac_map import RegisterMap, choose_map, known_maps
from sashil.drivers.rtdac_outputs import CoilDrive, RoadDrive
from sashil.drivers.rtdac_rest import rest_until_confirmed
from sashil.drivers.rtdac_usb import BoardLink, UsbSettings
from sashil.drivers.rtdac_wiring import Wiring
from sashil.errors import DriverError, DriverIOError, DriverTimeoutError

log = logging.getLogger("sashil")

#: a sensed coil current at most this confirms the coil at rest (as for sashil's own board)
SAFE_CURRENT_A = 0.02
#: how long deactivate resends the rest frame for a readback (and a sensed current) that confirm it
SAFE_CONFIRM_S = 0.3
#: how long the counters must stand still before configure zeroes them, how long it waits for that,
#: and how often it reads them meanwhile [s]
STILL_S = 0.5
STILL_WAIT_S = 20.0
STILL_POLL_S = 0.02
#: exchanges in a row whose readback of an output word differs from what was written before the
#: backend concludes the board ignores that word
IGNORED_AFTER = 3
_HIGH7 = bytes(b & 0x7F for b in range(256))  # a written word's high byte holds 7 bits (RTDACUSB2.cs line 177)
_SIGN32 = 1 << 31
_WRAP32 = 1 << 32


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
        names); ``busy_limit_s``: how long the coil sense A/D may stay busy before the run ends (the
        loop's rate, which the board's USB link must carry, is ``usb.rate_hz``)."""
        super().__init__()
        self.usb = usb
        self.wiring = wiring
        self.bringup = BringUp.of(wiring, current_max_a)
        self.current_max_a = self.bringup.current_max_a
        self.coil_tau_s = coil_tau_s
        self.application = application
        self.map_dir = map_dir
        self.link = BoardLink(usb, backend)
        self.header: Header | None = None
        self.map: RegisterMap | None = None
        self.coil = CoilDrive(
            wiring.coil_map_current_a,
            wiring.coil_map_output,
            wiring.coil_loop_ki_per_s,
            wiring.coil_loop_authority,
            coil_tau_s,
        )
        self.road = RoadDrive(
            wiring.road_output_per_rad_s,
            wiring.road_kp_per_rad,
            self.bringup.road_output_limit,
            0.0,
            wiring.road_lag_s,
            reverses=road_reverses(wiring),
        )
        self._raw: Any = None  # the latest read frame, as read
        self._frame = bytearray()  # the write frame being built
        self._coil_word = 0
        self._road_word = 0
        self._out_mask = 0x3FFF  # the bits an output word holds: the D/A's 14, or the PWM width's
        #: (word, bit mask, bits) sashil owns in a word that is otherwise the board's: the direction
        #: and heartbeat bits, and their pins' mode and direction
        self._bits: list[tuple[int, int, int]] = []
        self._dir: tuple[int, int] | None = None  # (word, bit) of the road's direction
        self._beat: tuple[int, int] | None = None  # (word, bit) of the heartbeat
        self._beat_on = False
        self._settings: dict[int, int] = {}  # words set once at configure (modes, prescalers, gain)
        self._offsets = (0, 0)  # counts the counters showed after their reset (subtracted)
        self._written: dict[int, int] = {}  # output word -> the value the last write frame carried
        self._ignored: dict[int, int] = {}  # output word -> exchanges in a row it read back otherwise
        self._seq = 0
        self._t0_ns: int | None = None
        self._road_angle = 0.0
        self._sensed_a: float | None = None
        self._command_a = 0.0
        self._busy_since_ns: int | None = None
        self._busy_limit_ns = round(busy_limit_s * 1e9)
        #: the clock and the sleep configure waits for the arm's stillness on (a test's simulated time)
        self.monotonic: Callable[[], float] = time.monotonic
        self.sleep: Callable[[float], None] = time.sleep
        self.stats: dict[str, Any] = {"samples": 0, "samples_missed": 0, "timeouts": 0, "watchdog_samples": 0}
        self.safe_state: dict[str, bool | float | None] = {"safe_state_confirmed": None, "safe_state_ms": None}

    #: the config keys the backend is built from (:meth:`from_parts`)
    reads: ClassVar[Mapping[str, str]] = {
        "rtdac": "rtdac",
        "port": "driver.port",
        "link_lost_ms": "driver.link_lost_ms",
        "current_max_a": "rig.current_max_a",
        "coil_tau_s": "rig.coil_tau_s",
        "rate_hz": "loop.rate_hz",
    }

    @classmethod
    def from_parts(cls, parts: RigParts, backend: Any = None) -> RtdacRig:
        """The backend the ``rtdac`` section, ``driver.port`` and the rig's coil describe (nothing
        opened); ``backend``: a pyusb backend object to find the board through."""
        board, values = parts.rtdac, parts.values
        if board is None:
            raise DriverError("rtdac: the rig parts carry no rtdac section (RtdacRig.reads names it)")
        usb = UsbSettings(
            manufacturer=board.manufacturer,
            serial=board.serial,
            vendor_id=board.vendor_id,
            product_id=board.product_id,
            usb_backend=board.usb_backend,
            port=values["port"],
            timeout_ms=board.transfer_timeout_ms,
            rate_hz=values.get("rate_hz"),
        )
        return cls(
            usb,
            Wiring.from_part(board),
            current_max_a=values["current_max_a"],
            coil_tau_s=values["coil_tau_s"],
            application=board.application,
            map_dir=board.map_dir,
            backend=backend,
            busy_limit_s=max(values["link_lost_ms"], 1.0) * 1e-3,
        )

    @property
    def capabilities(self) -> RigCapabilities:  # type: ignore[override]  # depends on the wiring
        return RigCapabilities(
            road_actuator=self.wiring.road_output != "none",
            link=True,
            road_reverses=road_reverses(self.wiring),
            current_sensed=self.wiring.coil_sense_ad is not None,
        )

    def describe(self) -> str:
        return self.link.where

    # lifecycle --------------------------------------------------------------------------------
    def configure(self) -> None:
        """Open the board, read its header, choose its register map, check the wiring fits it, put
        both outputs at rest (the board keeps whatever a previous host left) and zero the counters."""
        if self.state is RigState.CLOSED:
            raise DriverError("rtdac: configure() after close()")
        if self.state is not RigState.UNCONFIGURED:
            return
        maps = known_maps(self.map_dir)
        self.link.open()
        try:
            raw = self.link.read_frame()
            words = decode_frame(raw)
            self.header = decode_header(words)
            if self.application is not None and self.header.application.strip() != self.application:
                raise DriverError(
                    f"rtdac: the board's application is {self.header.application.strip()!r}, "
                    f"rtdac.application asks for {self.application!r} ({self.header.describe()})"
                )
            self.map = choose_map(self.header, maps)
            self._check_wiring(self.header, self.map)
            self._own_words(words)
            self._raw = raw
            self._zero_counters()
        except DriverError as err:
            self.link.close()
            if type(err) is DriverError:
                raise
            raise DriverError(str(err)) from None  # a board that fails its greeting: nothing energised, exit 2
        except BaseException:
            self.link.close()
            raise
        line = self.bringup.line()
        if line is not None:
            log.warning("%s", line)
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

    def _own_words(self, words: tuple[int, ...]) -> None:
        """The words and bits sashil owns: set once at configure (its channels' modes, the sense's
        gain) or every cycle (the outputs, the direction and heartbeat bits)."""
        w, reg = self.wiring, self.map
        assert reg is not None
        settings: dict[int, int] = {}
        for kind, channel in ((w.coil_output, w.coil_channel), (w.road_output, w.road_channel)):
            if kind == "pwm":
                mode_word = reg.pwm_mode_word(channel)
                if w.pwm_prescaler is not None:
                    settings[reg.pwm_prescaler_word(channel)] = w.pwm_prescaler & 0x7FFF
                    high = (w.pwm_prescaler >> 15) & 1
                else:
                    high = words[mode_word] & 1  # the board's own prescaler stays
                settings[mode_word] = (PWM_MODE_CODE[w.pwm_mode] << 1) | high
        if w.coil_sense_ad is not None:
            word, shift = reg.ad_gain_word(w.coil_sense_ad)
            settings[word] = words[word] & ~(0x7 << shift)  # gain x1: the full ±10 V range
        self._settings = settings
        self._coil_word = reg.pwm_width_word(w.coil_channel) if w.coil_output == "pwm" else reg.da_word(w.coil_channel)
        if w.road_output == "pwm":
            self._road_word = reg.pwm_width_word(w.road_channel)
        elif w.road_output == "da":
            self._road_word = reg.da_word(w.road_channel)
        self._out_mask = PWM_MAX[w.pwm_mode]
        self._bits = []
        for name, bit in (
            ("_dir", w.road_direction_bit if w.road_output == "pwm" else None),
            ("_beat", w.heartbeat_bit),
        ):
            if bit is None:
                setattr(self, name, None)
                continue
            offset, mask = (1 if bit >= 15 else 0), 1 << (bit % 15)
            setattr(self, name, (reg.output + offset, mask))
            self._bits += [(reg.pin_mode + offset, mask, 0), (reg.direction + offset, mask, 0)]  # GPIO, output
        self._rest_words = {self._coil_word: self._coil_rest()}
        if w.road_output != "none":
            self._rest_words[self._road_word] = self._output_word(w.road_output, self.road.rest)

    def _wait_still(self) -> None:
        """Both outputs at rest until the arm's and the road's counters have not moved for
        :data:`STILL_S` (the arm hangs at its rest); DriverError when they still move after
        :data:`STILL_WAIT_S` (nothing energised)."""
        monotonic = self.monotonic
        start = last_move = monotonic()
        seen: tuple[int, int] | None = None
        while True:
            try:
                self._start_frame()
                self.rest_outputs()
                self._send()
                self._raw = self.link.read_frame()
            except DriverTimeoutError:
                if monotonic() - start > STILL_WAIT_S:
                    raise
                continue  # a late answer while nothing is driven: ask again (a busy host's pause)
            words = decode_frame(self._raw)
            now_counts = (self._arm_raw(words), self._road_raw(words))
            now = monotonic()
            if now_counts != seen:
                seen, last_move = now_counts, now
            elif now - last_move >= STILL_S:
                return
            if now - start > STILL_WAIT_S:
                raise DriverError(
                    f"{self.describe()}: the arm's or the road's counter still moves after {STILL_WAIT_S:g} s with "
                    "both outputs at rest; its zero is taken with the arm hanging still: let it settle (or check "
                    f"the encoder's wiring for noise), then start again"
                )
            self.sleep(STILL_POLL_S)

    def _zero_counters(self) -> None:
        """Both outputs at rest, the arm still, the arm's and the road's counters reset, and what they
        show after the reset kept as their offsets (0 on a board that takes the reset word)."""
        w, reg = self.wiring, self.map
        assert reg is not None
        self._offsets = (0, 0)
        self._wait_still()
        bits = 1 << w.arm_encoder
        if w.road_encoder is not None:
            bits |= 1 << w.road_encoder
        for reset in (bits, 0):
            self._start_frame()
            self._put(reg.encoder_reset, reset)
            for word, value in self._rest_words.items():
                self._put(word, value)
            self._send()
            self._raw = self.link.read_frame()
        words = decode_frame(self._raw)
        self._offsets = (0, 0)
        self._offsets = (self._arm_raw(words), self._road_raw(words))

    # the write frame --------------------------------------------------------------------------
    def _start_frame(self) -> None:
        """The write frame as the latest read: the board's own words, then sashil's settings and bits."""
        frame = bytearray(self._raw)
        frame[0:2] = WRITE_MARK
        frame[3::2] = frame[3::2].translate(_HIGH7)
        self._frame = frame
        for word, value in self._settings.items():
            self._put(word, value)
        if self.map is not None:
            self._put(self.map.encoder_reset, 0)  # every counter counting
        for word, mask, bits in self._bits:
            self._put_bits(word, mask, bits)

    def _send(self) -> None:
        self.link.write_frame(self._frame)

    def _coil_rest(self) -> int:
        return self._output_word(self.wiring.coil_output, self.coil.rest)

    def _output_word(self, kind: str, value: float) -> int:
        """The register word of an output: a PWM width (a duty below 0 is 0: the wiring drives one
        way), or a D/A voltage."""
        if kind == "pwm":
            return pwm_width(value, self.wiring.pwm_mode)
        return da_word(value)

    def _put(self, word: int, value: int) -> None:
        struct.pack_into("<H", self._frame, 2 * word, value & 0x7FFF)

    def _put_bits(self, word: int, mask: int, bits: int) -> None:
        value = int.from_bytes(self._frame[2 * word : 2 * word + 2], "little")
        self._put(word, (value & ~mask) | (bits & mask))

    # raw access for sashil doctor's walk: the outputs by channel, one exchange at a time ------------
    def exchange_frame(self) -> bytes:
        """The write frame as it stands (the next exchange sends it)."""
        return bytes(self._frame)

    def exchange(self) -> tuple[int, ...]:
        """One exchange with the frame as it stands (the heartbeat toggled); the read frame's words."""
        self._beat_bit()
        self._send()
        self._raw = self.link.read_frame()
        words = decode_frame(self._raw)
        pending = bytes(self._frame)
        self._start_frame()
        for word in self._channel_words():
            self._put(word, int.from_bytes(pending[2 * word : 2 * word + 2], "little"))
        return words

    def _channel_words(self) -> list[int]:
        reg = self.map
        assert reg is not None
        out = [reg.pwm_width_word(c) for c in range(reg.pwm_count)] + [reg.da_word(c) for c in range(reg.da_count)]
        return out + ([self._dir[0]] if self._dir is not None else [])

    def set_output(self, kind: str, channel: int, value: float) -> None:
        """Set PWM ``channel``'s duty or D/A ``channel``'s volts in the next frame (any channel: the walk
        tries the wiring it is asked to)."""
        reg = self.map
        assert reg is not None
        if kind == "pwm" and reg.pwm_mode_word(channel) not in self._settings:
            # a channel the config does not name: its mode set as the config's channels' are, from here on
            mode_word = reg.pwm_mode_word(channel)
            high = int.from_bytes(self._frame[2 * mode_word : 2 * mode_word + 2], "little") & 1
            self._settings[mode_word] = (PWM_MODE_CODE[self.wiring.pwm_mode] << 1) | high
            self._put(mode_word, self._settings[mode_word])
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
        self._ignored = {}
        self._written = {}
        self.state = RigState.ACTIVE

    def deactivate(self) -> None:
        """Both outputs to rest and the readback checked (module docstring), the link recovered
        between tries (clear_halt, then a reopen) until :data:`SAFE_CONFIRM_S`; never raises."""
        self._command_a = 0.0
        self.road.stop()
        was_active = self.state is RigState.ACTIVE
        if was_active:
            self.state = RigState.CONFIGURED
        if self.map is None or self._raw is None:
            return  # never greeted: nothing was written

        def rest_and_read() -> tuple[int, ...]:
            self._start_frame()
            self.rest_outputs()
            self._send()
            self._raw = self.link.read_frame()
            return decode_frame(self._raw)

        def at_rest(words: tuple[int, ...]) -> bool:
            sensed = self._sense(words)
            quiet = sensed is None or abs(sensed) <= max(SAFE_CURRENT_A, 0.02 * self.current_max_a)
            return self._at_rest(words) and quiet

        outcome = rest_until_confirmed(
            rest_and_read, at_rest, self.link.recover, time.monotonic, SAFE_CONFIRM_S, time.sleep
        )
        self.safe_state["safe_state_confirmed"] = outcome.confirmed
        self.safe_state["safe_state_ms"] = round(outcome.elapsed_s * 1e3, 3)
        self.safe_state["safe_state_attempts"] = outcome.attempts
        if not outcome.confirmed:
            why = f" (last: {outcome.last_error})" if outcome.last_error is not None else ""
            log.warning(
                "%s: deactivate: could NOT confirm both outputs at rest in %d tries over %g s%s; the board keeps "
                "its last outputs: use the E-stop",
                self.describe(),
                outcome.attempts,
                SAFE_CONFIRM_S,
                why,
            )

    def _at_rest(self, words: tuple[int, ...]) -> bool:
        """Whether the read frame shows both outputs at rest, each word masked to the bits its register holds."""
        return all(self._read_back(words, word) == value for word, value in self._rest_words.items())

    def _read_back(self, words: tuple[int, ...], word: int) -> int:
        mask = self._out_mask if self._is_pwm(word) else DA_MAX
        return words[word] & mask

    def _is_pwm(self, word: int) -> bool:
        w = self.wiring
        return (word == self._coil_word and w.coil_output == "pwm") or (
            word == self._road_word and w.road_output == "pwm"
        )

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

    def _arm_raw(self, words: tuple[int, ...]) -> int:
        reg, w = self.map, self.wiring
        assert reg is not None
        low, high = reg.counter_words(w.arm_encoder)
        return _less(counter32(words[low], words[high]), self._offsets[0])

    def _road_raw(self, words: tuple[int, ...]) -> int:
        reg, w = self.map, self.wiring
        assert reg is not None
        if w.road_encoder is None:
            return 0
        low, high = reg.counter_words(w.road_encoder)
        return _less(counter32(words[low], words[high]), self._offsets[1])

    def read(self, t_ns: int, dt_ns: int) -> RigSample:
        if self.state not in (RigState.CONFIGURED, RigState.ACTIVE):
            raise DriverError(f"{self.describe()}: read() in state {self.state.value}")
        self._raw = raw = self.link.read_frame()
        words = decode_frame(raw)
        w = self.wiring
        if self._written:
            self._check_taken(words)
        arm = self._arm_raw(words) * (-1 if w.arm_reversed else 1)
        road = 0
        if w.road_encoder is not None:
            road_raw = self._road_raw(words) * (-1 if w.road_reversed else 1)
            self._road_angle = road_raw * TWO_PI / w.road_counts_per_rev
            road = round(road_raw * w.arm_counts_per_rev / w.road_counts_per_rev)
        current = math.nan
        if w.coil_sense_ad is not None:
            self._check_busy(words, t_ns)
            self._sensed_a = self._sense(words)
            if self._sensed_a is not None:
                current = self._sensed_a
        if self._t0_ns is None:
            self._t0_ns = t_ns
        self._seq += 1
        self.stats["samples"] += 1
        return RigSample(
            self._seq,
            t_ns,
            (t_ns - self._t0_ns) // 1000,
            arm,
            road,
            current,
            0,
            w.arm_counts_per_rev,
            road_error_rad=self.road.error_rad,
            road_at_limit=self.road.at_limit,
            coil_at_authority=self.coil.at_authority,
        )

    def _check_busy(self, words: tuple[int, ...], t_ns: int) -> None:
        reg, channel = self.map, self.wiring.coil_sense_ad
        assert reg is not None and channel is not None
        if words[reg.ad_value_word(channel)] & AD_BUSY_BIT:
            if self._busy_since_ns is None:
                self._busy_since_ns = t_ns
            elif t_ns - self._busy_since_ns > self._busy_limit_ns:
                raise DriverIOError(
                    f"{self.describe()}: A/D {channel} (the coil current) has stayed busy for "
                    f"{(t_ns - self._busy_since_ns) * 1e-6:.0f} ms (a stuck busy bit)"
                )
        else:
            self._busy_since_ns = None

    def _check_taken(self, words: tuple[int, ...]) -> None:
        """The board took the last write's output words: DriverIOError once one reads back otherwise
        :data:`IGNORED_AFTER` exchanges in a row (a word the board ignores: the wrong channel or map)."""
        for word, value in self._written.items():
            if self._read_back(words, word) == value:
                self._ignored[word] = 0
                continue
            misses = self._ignored.get(word, 0) + 1
            self._ignored[word] = misses
            if misses >= IGNORED_AFTER:
                what = "the coil's output" if word == self._coil_word else "the road motor's output"
                raise DriverIOError(
                    f"{self.describe()}: the board ignores word {word} ({what}): it reads back "
                    f"{self._read_back(words, word)} where {value} was written, {misses} exchanges in a row; check "
                    f"the register map ({self.map.describe() if self.map else '?'}) and the output's channel"
                )

    def write(self, cmd: RigCommand, t_ns: int, dt_ns: int) -> None:
        """The cycle's outputs, in one write frame built from this cycle's read: the coil's (rest
        unless active), the road motor's and its direction, and the heartbeat."""
        if self.map is None or self._raw is None:
            return
        dt_s = dt_ns * 1e-9
        if self.state is RigState.ACTIVE:
            self._command_a = clamp_current(cmd.current_a, self.current_max_a)  # the bring-up cap within
            coil = self.coil.output(self._command_a, self._sensed_a, dt_s)
            self.road.command(cmd.road_speed_rad_s)
        else:
            self._command_a = 0.0
            coil = self.coil.output(0.0, None, dt_s)
            self.road.stop()
        w = self.wiring
        self._start_frame()
        written = self._written
        word = self._output_word(w.coil_output, coil)
        self._put(self._coil_word, word)
        written[self._coil_word] = word & (self._out_mask if w.coil_output == "pwm" else DA_MAX)
        if w.road_output != "none":
            road = self.road.output(self._road_angle, dt_s)
            word = self._output_word(w.road_output, abs(road) if self._dir is not None else road)
            self._put(self._road_word, word)
            written[self._road_word] = word & (self._out_mask if w.road_output == "pwm" else DA_MAX)
            if self._dir is not None:
                self._put_bits(self._dir[0], self._dir[1], self._dir[1] if road < 0.0 else 0)
        self._beat_bit()
        self._send()

    def _beat_bit(self) -> None:
        """Toggle the heartbeat bit in the frame about to be sent (none wired: nothing)."""
        if self._beat is not None:
            self._beat_on = not self._beat_on
            self._put_bits(self._beat[0], self._beat[1], self._beat[1] if self._beat_on else 0)

    # facts --------------------------------------------------------------------------------------
    def codec_counters(self) -> dict[str, int]:
        return {"bad_frames": 0}

    def link_stats(self) -> dict[str, Any]:
        """Exchanges, what ``current_a`` is, the guesses and caps, the road's tracking, the header and
        the last safe-state check."""
        w = self.wiring
        source = f"sensed (A/D {w.coil_sense_ad})" if w.coil_sense_ad is not None else "none (no current sense)"
        facts: dict[str, Any] = {
            **self.stats,
            "bad_frames": 0,
            "current_source": source,
            **self.bringup.facts(),
            **self.road.tracking(),
        }
        facts.update(self.link.facts())
        if self.header is not None:
            facts["board"] = self.header.describe()
        if self.map is not None:
            facts["register_map"] = self.map.describe()
        return {**facts, **self.safe_state}


def road_reverses(wiring: Wiring) -> bool:
    """Whether the wiring can drive the road motor both ways: a D/A, or a PWM with a direction bit."""
    return wiring.road_output != "pwm" or wiring.road_direction_bit is not None


def _less(count: int, offset: int) -> int:
    """``count - offset`` on the 32-bit counter's circle, signed."""
    return (count - offset + _SIGN32) % _WRAP32 - _SIGN32


__all__ = ["RtdacRig", "Wiring", "road_reverses"]

"""An emulated RT-DAC/USB2: the board's register file over the simulated rig, free of I/O.

:class:`RtdacBoard` answers the bulk transfers of the public source's protocol
(:mod:`sashil.drivers.rtdac_codec`): a read request (``FF 8F 00 00`` on endpoint 2) latches the
registers, which the next read of endpoint 4 returns as 504 bytes; a write frame (``0F 8F`` then
251 words) sets the writable words the register map names (PWM, D/A, encoder resets, digital
outputs, A/D gains). Every call takes the time ``now_ns``; the plant advances to it.

Behind the registers, the emulated bench's own wiring (a :class:`~sashil.drivers.rtdac_wiring.Wiring`;
by default the one the config's ``rtdac`` section describes, so an emulator and a host on one config
fit): two encoder
counters (the arm angle theta2 and the road wheel angle theta1), a power stage that drives the coil
towards the current its calibration map gives for the duty or voltage (seed 001's coil lag in the
simulated rig), an A/D channel that senses the coil current, and a road motor whose speed follows
its voltage or duty with a first-order lag. Like the real board it has no watchdog: its outputs
stay as last written, whatever the host does.

A session starts when a host claims the board: the emulated operator (``--hold-deg``) presses the
arm to its hold angle then and lets go later, as with the serial emulator.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field, replace
from typing import Any

from sashil.config.section_parts import RtdacPart
from sashil.drivers import rig_parts
from sashil.drivers.emulator.device import Operator
from sashil.drivers.interface import RigCommand
from sashil.drivers.rtdac_codec import (
    DA_ZERO,
    ENDPOINT_IN,
    ENDPOINT_OUT,
    FRAME_BYTES,
    FRAME_WORDS,
    READ_REQUEST,
    WRITE_MARK,
    ad_word,
    da_volts,
    encode_header,
    pwm_duty,
)
from sashil.drivers.rtdac_map import RegisterMap
from sashil.drivers.rtdac_outputs import interp
from sashil.drivers.rtdac_wiring import Wiring
from sashil.drivers.sim import SimulatedRig

TWO_PI = 2.0 * math.pi
#: the road motor's dead band: below one D/A step [V] (or a duty as small) it stands still
ROAD_DEAD_BAND = 20.0 / 16383
#: an unpowered road motor slower than this [rad/s] stands still (friction), so a hand can turn the wheel
ROAD_STILL_RAD_S = 1e-6
_FRAME = struct.Struct(f"<{FRAME_WORDS}H")


#: a bench wired unlike every default guess of the ``rtdac`` section (``build_board``'s
#: ``wiring_changes``): the arm on counter 4 counting down, the coil on PWM 3 sensed on A/D 6, the road
#: motor on D/A 1 with its encoder on counter 5 counting down at 2000 a revolution
REWIRED_BENCH: dict[str, Any] = {
    "arm_encoder": 4,
    "arm_reversed": True,
    "coil_output": "pwm",
    "coil_channel": 3,
    "coil_sense_ad": 6,
    "road_output": "da",
    "road_channel": 1,
    "road_encoder": 5,
    "road_reversed": True,
    "road_counts_per_rev": 2000,
}


@dataclass(frozen=True)
class RoadMotor:
    """The emulated road motor: its speed per volt (or per unit duty) and its time constant."""

    rad_s_per_output: float = 2.0
    tau_s: float = 0.02

    @classmethod
    def from_part(cls, board: RtdacPart, tau_s: float = 0.02) -> RoadMotor:
        """The motor a config's feed-forward describes (its gain the feed-forward's inverse)."""
        per = board.road_output_per_rad_s
        return cls(1.0 / per if per > 0.0 else 0.0, tau_s)


@dataclass
class BoardFaults:
    """Fault injection; times count from the session's start (the host's claim)."""

    #: then every transfer fails as a vanished device does ("no such device")
    vanish_after_s: float | None = None
    #: then the coil sense A/D's busy bit stays set
    stuck_busy_after_s: float | None = None
    #: then read frames come two bytes short
    short_frame_after_s: float | None = None
    #: then reads go unanswered (the host's transfer times out)
    timeout_after_s: float | None = None
    #: opening the board is refused (a missing udev rule)
    permission_denied: bool = False
    #: what every counter shows at power-up: counts an earlier program left (0: none)
    counter_preset: int = 0
    #: then the arm's counter resets to 0 once, as an index pulse resets a counter
    index_reset_after_s: float | None = None
    #: words of a write frame the board does not take (they keep their value)
    ignored_words: tuple[int, ...] = ()


@dataclass
class Relay:
    """A retriggerable watchdog relay on the power stages, retriggered by a digital output's toggles.

    It closes at a toggle of ``bit`` and opens ``hold_ms`` after the last one; open, the coil's and the
    road motor's power stages are unpowered whatever the board's outputs say."""

    bit: int
    hold_ms: float = 20.0
    last_toggle_ns: int | None = None
    level: int = 0
    #: times it opened after having been closed, during a session (a host pause longer than hold_ms)
    drops: int = 0
    #: retriggered in this session: a gap longer than hold_ms from here on is a drop
    armed: bool = False

    def closed(self, now_ns: int) -> bool:
        last = self.last_toggle_ns
        return last is not None and now_ns - last <= self.hold_ms * 1e6

    def opened_at_ns(self) -> int | None:
        """When it opened (or opens) after the last toggle."""
        last = self.last_toggle_ns
        return None if last is None else last + round(self.hold_ms * 1e6)

    def take(self, level: int, now_ns: int) -> None:
        """The bit's level in a write frame at ``now_ns``: a change retriggers the relay."""
        if level != self.level:
            if self.armed and not self.closed(now_ns):
                self.drops += 1
            self.level = level
            self.last_toggle_ns = now_ns
            self.armed = True


@dataclass
class BoardIdentity:
    """What the board says of itself: its header, and its USB strings and ids."""

    logic_version: int = 0x0103
    application: str = "SASHIL"
    synthesis_date: str = "2026-11-28"
    modules: dict[str, int] = field(
        default_factory=lambda: {"pwm": 8, "encoder_i": 8, "timer_counter": 2, "frequency_meter": 8, "chronometer": 8}
    )
    manufacturer: str = "InTeCo"
    product: str = "RT-DAC/USB2"
    serial: str = "1"
    #: Cypress's vendor id; the product id is the emulator's own (the public source names neither)
    vendor_id: int = 0x04B4
    product_id: int = 0x8613


class TransferError(Exception):
    """A transfer the emulated board fails, with the errno libusb would give (19: gone, 13: access)."""

    def __init__(self, errno: int, text: str):
        super().__init__(text)
        self.errno = errno


class TransferTimeout(Exception):
    """A read the board does not answer (the host's transfer times out)."""


class RtdacBoard:
    """The emulated board (module docstring)."""

    def __init__(
        self,
        rig: SimulatedRig,
        register_map: RegisterMap,
        wiring: Wiring | None = None,
        identity: BoardIdentity | None = None,
        operator: Operator | None = None,
        faults: BoardFaults | None = None,
        motor: RoadMotor | None = None,
        relay: Relay | None = None,
        press_after_s: float = 0.2,
        press_s: float = 0.3,
    ):
        """``relay``: a watchdog relay on the power stages (None: none wired); the operator presses the
        arm ``press_after_s`` after the host's claim, moving it to the hold angle over ``press_s``, as a
        person does once the host has connected and asked."""
        self.rig = rig
        self.relay = relay
        self.press_after_s = press_after_s
        self.press_s = press_s
        self._press: tuple[float, float] | None = None  # (from rad, to rad) of the operator's press to come
        self._reset_ns: int | None = None  # the host's last counter reset this session: the operator's cue
        self._written_reset = 0  # the reset word of the host's last write frame
        self._index_done = False
        self.motor = motor or RoadMotor()
        self.map = register_map
        self.wiring = wiring or Wiring()
        self.identity = identity or BoardIdentity(logic_version=register_map.logic_version)
        self.operator = operator
        self.faults = faults or BoardFaults()
        rig.configure()
        rig.activate()  # the coil follows whatever the power stage drives
        self.words = [0] * FRAME_WORDS
        header = encode_header(
            self.identity.logic_version, self.identity.application, self.identity.synthesis_date, self.identity.modules
        )
        self.words[: len(header)] = header
        for channel in range(4):
            self.words[register_map.da_word(channel)] = DA_ZERO  # the D/A's at 0 V from power-up
        self._latched: bytes | None = None
        self._writable = self.writable()
        self._counter_zero: dict[int, int] = {}
        self._road_speed = 0.0
        self._last_ns: int | None = None
        self.session_start_ns: int | None = None
        self.claimed = False
        self.exchanges = 0
        self.bad_frames = 0
        #: the coil current the power stage drives towards, and the road motor's speed target
        self.drive_a = 0.0
        self.road_target_rad_s = 0.0

    # sessions ---------------------------------------------------------------------------------
    def open(self) -> None:
        """A host opens the device: refused when the fault says its permissions do not allow it."""
        if self.faults.permission_denied:
            raise TransferError(13, "Access denied (insufficient permissions)")

    def claim(self, now_ns: int) -> None:
        """A host claims the board's interface: a session starts (the operator's hold)."""
        self._advance(now_ns)
        self.claimed = True
        self.session_start_ns = now_ns
        self._reset_ns = None
        if self.relay is not None:
            self.relay.armed = False  # a new host: the gap since the last one's toggles is no drop
        if self.operator is not None:
            self._press = (self.rig.plant.state.theta_rad, math.radians(self.operator.next_hold_deg()))

    def release(self) -> None:
        self.claimed = False

    def _since(self, now_ns: int, after_s: float | None) -> bool:
        start = self.session_start_ns
        return after_s is not None and start is not None and (now_ns - start) * 1e-9 >= after_s

    # transfers --------------------------------------------------------------------------------
    def bulk_write(self, endpoint: int, data: bytes, now_ns: int) -> int:
        """A transfer to ``endpoint``: a read request latches the registers, a write frame sets them."""
        self._check_present(now_ns)
        if endpoint != ENDPOINT_OUT:
            return len(data)  # the JTAG endpoints: not emulated
        if bytes(data) == READ_REQUEST:
            self._advance(now_ns)
            self._latch(now_ns)
        elif len(data) == FRAME_BYTES and bytes(data[:2]) == WRITE_MARK:
            self._advance(now_ns)
            self._apply(bytes(data), now_ns)
        else:
            self.bad_frames += 1
        return len(data)

    def bulk_read(self, endpoint: int, size: int, now_ns: int) -> bytes:
        """A transfer from ``endpoint``: the latched frame (one read request, one frame)."""
        self._check_present(now_ns)
        if self._since(now_ns, self.faults.timeout_after_s) or endpoint != ENDPOINT_IN:
            raise TransferTimeout()
        frame, self._latched = self._latched, None
        if frame is None:
            raise TransferTimeout()  # nothing asked for: the FPGA sends nothing
        self.exchanges += 1
        if self._since(now_ns, self.faults.short_frame_after_s):
            frame = frame[:-2]
        return frame[:size]

    def _check_present(self, now_ns: int) -> None:
        if self._since(now_ns, self.faults.vanish_after_s):
            raise TransferError(19, "No such device (it may have been disconnected)")

    # registers --------------------------------------------------------------------------------
    def _latch(self, now_ns: int) -> None:
        w, m = self.wiring, self.map
        state = self.rig.plant.state
        road_angle = state.theta_road_rad
        self._set_counter(w.arm_encoder, state.theta_rad + road_angle, w.arm_counts_per_rev, w.arm_reversed)
        if w.road_encoder is not None:
            self._set_counter(w.road_encoder, road_angle, w.road_counts_per_rev, w.road_reversed)
        if w.coil_sense_ad is not None:
            word, shift = m.ad_gain_word(w.coil_sense_ad)
            gain = (self.words[word] >> shift) & 0x7
            volts = w.coil_sense_offset_v + state.current_a / w.coil_sense_a_per_v
            busy = self._since(now_ns, self.faults.stuck_busy_after_s)
            self.words[m.ad_value_word(w.coil_sense_ad)] = ad_word(volts, min(gain, 4), busy)
        self._latched = _FRAME.pack(*self.words)

    def _set_counter(self, channel: int, angle_rad: float, counts_per_rev: int, reversed_: bool) -> None:
        counts = round(angle_rad * counts_per_rev / TWO_PI) * (-1 if reversed_ else 1)
        preset = self.faults.counter_preset
        if (self.words[self.map.encoder_reset] >> channel) & 1:
            self._counter_zero[channel] = counts + preset  # held at 0 while its reset bit is set
        elif (
            channel == self.wiring.arm_encoder
            and not self._index_done
            and self._since(self._last_ns or 0, self.faults.index_reset_after_s)
        ):
            self._index_done = True
            self._counter_zero[channel] = counts + preset  # an index pulse: 0 from here
        value = (counts + preset - self._counter_zero.get(channel, 0)) & 0xFFFF_FFFF
        low, high = self.map.counter_words(channel)
        self.words[low], self.words[high] = value & 0xFFFF, value >> 16

    def writable(self) -> list[int]:
        """The words a write frame sets (the map's outputs and settings; the rest are the board's)."""
        m = self.map
        words = [m.pin_mode, m.pin_mode + 1, m.direction, m.direction + 1, m.output, m.output + 1]
        for channel in range(m.pwm_count):
            words += [m.pwm_prescaler_word(channel), m.pwm_mode_word(channel), m.pwm_width_word(channel)]
        words += [m.encoder_reset, m.encoder_index_active, m.encoder_index_invert]
        words += [m.ad_gain_base + k for k in range(4)]
        words += [m.da_word(channel) for channel in range(m.da_count)]
        return words

    def _apply(self, frame: bytes, now_ns: int) -> None:
        written = _FRAME.unpack(frame)
        words = self.words
        ignored = self.faults.ignored_words
        reset = written[self.map.encoder_reset]
        if self._written_reset and not reset:
            self._reset_ns = now_ns  # the reset released: the host has zeroed the counters
        self._written_reset = reset
        for word in self._writable:
            if word not in ignored:
                words[word] = written[word]
        relay = self.relay
        if relay is not None:
            word = self.map.output + (1 if relay.bit >= 15 else 0)
            relay.take((words[word] >> (relay.bit % 15)) & 1, now_ns)
        self._drive(now_ns)

    def output(self, kind: str, channel: int) -> float:
        """The duty (pwm) or volts (da) the registers set on ``channel``."""
        if kind == "pwm":
            return pwm_duty(self.words[self.map.pwm_width_word(channel)], self.wiring.pwm_mode)
        return da_volts(self.words[self.map.da_word(channel)])

    def _drive(self, now_ns: int) -> None:
        """The power stage and the road motor follow the outputs just written."""
        w = self.wiring
        powered = self.relay is None or self.relay.closed(now_ns)
        level = self.output(w.coil_output, w.coil_channel)
        self.drive_a = max(0.0, interp(level, w.coil_map_output, w.coil_map_current_a)) if powered else 0.0
        road = 0.0
        if w.road_output != "none" and powered:
            road = self.output(w.road_output, w.road_channel)
            if w.road_output == "pwm" and w.road_direction_bit is not None:
                bit = w.road_direction_bit
                word = self.map.output + (1 if bit >= 15 else 0)
                if (self.words[word] >> (bit % 15)) & 1:
                    road = -road
        if abs(road) < ROAD_DEAD_BAND:
            road = 0.0  # the D/A's 0 V word (8191) is 0.6 mV below zero: a motor does not turn on it
        self.road_target_rad_s = road * self.motor.rad_s_per_output
        self.rig.write(RigCommand(self.drive_a, None), now_ns, 0)

    def _advance(self, now_ns: int) -> None:
        """Step the plant to ``now_ns``; the road motor's speed lags its target (first order)."""
        last = self._last_ns
        self._last_ns = now_ns
        self._operator(now_ns)
        relay = self.relay
        if relay is not None and (self.drive_a or self.road_target_rad_s) and not relay.closed(now_ns):
            self.drive_a, self.road_target_rad_s = 0.0, 0.0  # the relay opened: both stages unpowered
            self.rig.write(RigCommand(0.0, None), last if last is not None else now_ns, 0)
        if last is not None and now_ns > last:
            alpha = 1.0 - math.exp(-(now_ns - last) * 1e-9 / self.motor.tau_s)
            speed = self._road_speed + alpha * (self.road_target_rad_s - self._road_speed)
            if self.road_target_rad_s == 0.0 and abs(speed) < ROAD_STILL_RAD_S:
                speed = 0.0
            if speed != self._road_speed:
                self._road_speed = speed
                self.rig.write(RigCommand(self.drive_a, speed), last, 0)
        self.rig.read(now_ns, 0)

    def _operator(self, now_ns: int) -> None:
        """The operator's press, once the host has zeroed the counters (it then asks for the hold): from
        ``press_after_s`` after that, the arm moved to the hold angle over ``press_s``, then held until
        ``release_after_s`` after it."""
        press, cue, operator = self._press, self._reset_ns, self.operator
        if press is None or cue is None or operator is None:
            return
        start = cue + round(self.press_after_s * 1e9)
        if now_ns < start:
            return
        origin, angle = press
        done = (now_ns - start) * 1e-9 / self.press_s if self.press_s > 0.0 else 1.0
        if done < 1.0:
            self.rig.plant.hold(origin + (angle - origin) * done)
            return
        self._press = None
        release = cue + round(operator.release_after_s * 1e9)
        self.rig.operator_hold(angle, max(release - now_ns, 0) * 1e-9)

    @property
    def road_speed_rad_s(self) -> float:
        return self._road_speed

    def at_rest(self) -> bool:
        """Both outputs the bench drives at rest: the coil's and the road motor's (duty 0, or 0 V)."""
        w = self.wiring
        rest = [self._is_rest(w.coil_output, w.coil_channel)]
        if w.road_output != "none":
            rest.append(self._is_rest(w.road_output, w.road_channel))
        return all(rest)

    def _is_rest(self, kind: str, channel: int) -> bool:
        if kind == "pwm":
            return self.words[self.map.pwm_width_word(channel)] == 0
        return self.words[self.map.da_word(channel)] == DA_ZERO


def build_board(
    config: Any,
    logic: str = "0103",
    identity: BoardIdentity | None = None,
    operator: Operator | None = None,
    faults: BoardFaults | None = None,
    stage_gain: float = 1.0,
    road_tau_s: float = 0.02,
    wiring_changes: dict[str, Any] | None = None,
    relay: Relay | None = None,
) -> RtdacBoard:
    """The emulated board around the simulated rig the config describes (model, rig and mismatch
    sections), laid out as FPGA logic ``logic`` (a built-in map), wired as its ``rtdac`` section says
    (with ``wiring_changes``), its road motor lagging by ``road_tau_s``; ``stage_gain`` scales the
    power stage's true current against the map the host is given (a stage the host's calibration
    does not match)."""
    from sashil.drivers.rtdac_map import known_maps

    layouts = {m.logic: m for m in known_maps()}
    if logic not in layouts:
        raise ValueError(f"logic: expected one of {', '.join(layouts)}, got {logic!r}")
    board = rig_parts(config, "rtdac").rtdac  # the board's section, as the host's backend reads it
    if board is None:
        raise ValueError("the rtdac backend's parts carry no rtdac section")
    # the bench's truth: the config's wiring, with the coil's current sensed on A/D 0 where the config
    # reads no sense (a host that reads none is the host's choice, not the bench's wiring)
    sense = board.coil_sense_ad if board.coil_sense_ad is not None else 0
    wiring = Wiring.from_part(board, **{"coil_sense_ad": sense, **(wiring_changes or {})})
    if stage_gain != 1.0:
        wiring = replace(wiring, coil_map_current_a=tuple(stage_gain * a for a in wiring.coil_map_current_a))
    motor = RoadMotor.from_part(board, road_tau_s)
    ident = identity or BoardIdentity(logic_version=layouts[logic].logic_version)
    return RtdacBoard(
        SimulatedRig.from_parts(rig_parts(config, "sim")),
        layouts[logic],
        wiring,
        ident,
        operator,
        faults,
        motor,
        relay,
    )

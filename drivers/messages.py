"""The messages between host and rig, in SI units, shared by the serial and the CAN protocol.

Both wire formats (``serial_codec``: COBS frames with CRC-16; ``can_codec``: the frames of
``sashil.dbc``) carry exactly these messages with the same scaling, documented in
``protocol.md``. A message holds physical values; the codecs quantise them to the wire units
below and clamp them to the wire range.
"""

from __future__ import annotations

from dataclasses import dataclass

#: protocol version exchanged in Hello/Version; a device that answers another version is refused
#: (version 2 added the encoder edge times to the Sample; protocol.md "Session")
PROTOCOL_VERSION = 2

#: wire units
CURRENT_LSB_A = 0.0005  # coil current (command and measurement): 0.5 mA per count
ROAD_SPEED_LSB_RAD_S = 1e-6  # road-wheel motor speed: 1 µrad/s per count

#: Configure.pacing values
PACING_DEVICE = 0  # the device streams a sample every 1/rate s; the host cycle runs on each sample
PACING_HOST = 1  # the device answers each Command with one Sample
PACING_NAMES = {"device": PACING_DEVICE, "host": PACING_HOST}

#: Sample edge age that means "no count change in the last 65.534 ms" (or none since boot)
EDGE_AGE_NONE = 0xFFFF
#: Sample edge direction bits on the wire (set: the count went up at that edge)
EDGE_ARM_UP = 0x01
EDGE_ROAD_UP = 0x02

#: Command.flags bits
CMD_ENABLE = 0x01  # without it the device drives 0 A whatever the setpoint says


@dataclass(frozen=True, slots=True)
class Sample:
    """Rig -> host: one sensor sample (sequence number travels beside it)."""

    device_time_us: int  # device clock, wraps (32 bit serial, 24 bit CAN)
    arm_counts: int  # arm encoder (theta2), signed 32 bit
    road_counts: int  # road/wheel-side encoder (theta1), signed 32 bit
    current_a: float  # measured coil current
    flags: int  # FLAG_* bits of sashil.drivers.interface
    #: microseconds from the arm encoder's last count change to this sample (EDGE_AGE_NONE: none recent)
    arm_edge_age_us: int = EDGE_AGE_NONE
    #: +1 / -1: the arm count went up / down at that change; 0 with no recent change
    arm_edge_dir: int = 0
    road_edge_age_us: int = EDGE_AGE_NONE  # the same for the road encoder
    road_edge_dir: int = 0


@dataclass(frozen=True, slots=True)
class Command:
    """Host -> rig: coil current setpoint for this cycle (also feeds the device watchdog)."""

    current_a: float
    flags: int = CMD_ENABLE


@dataclass(frozen=True, slots=True)
class RoadSpeed:
    """Host -> rig: road-wheel motor speed (sweeps)."""

    speed_rad_s: float


@dataclass(frozen=True, slots=True)
class Status:
    """Rig -> host: status/fault report; also the acknowledgement of Configure."""

    flags: int
    fault_code: int = 0  # 0: none; FAULT_* below
    bad_frames: int = 0  # frames the device rejected (CRC, framing), wraps at 2**16
    watchdog_trips: int = 0  # times the device watchdog cut the current, wraps at 2**16


#: Status.fault_code values
FAULT_NONE = 0
FAULT_BAD_CONFIGURE = 1  # a Configure the device cannot honour (rate or watchdog out of range)
FAULT_NOT_CONFIGURED = 2  # a Command before Configure
FAULT_NO_CAN = 3  # a Configure on the CAN link of a board without a CAN transmitter

#: Status.flags bits beyond the sample flags (drivers/interface.py) the board repeats in Status
STATUS_CLOCK_FALLBACK = 0x10  # the board's crystal did not start: it runs on its internal oscillator


@dataclass(frozen=True, slots=True)
class Hello:
    """Host -> rig: the host's protocol version; the rig answers with :class:`Version`."""

    protocol_version: int = PROTOCOL_VERSION


@dataclass(frozen=True, slots=True)
class Version:
    """Rig -> host: the device's protocol version and what the host needs to know of it."""

    protocol_version: int
    counts_per_rev: int
    current_max_a: float


@dataclass(frozen=True, slots=True)
class Configure:
    """Host -> rig: sample rate, watchdog timeout and pacing; the rig answers with :class:`Status`."""

    rate_hz: int
    watchdog_ms: int
    pacing: int = PACING_DEVICE


Message = Sample | Command | RoadSpeed | Status | Hello | Version | Configure


def edge_dirs_to_wire(arm_dir: int, road_dir: int) -> int:
    """The Sample's direction byte: EDGE_ARM_UP / EDGE_ROAD_UP set for a count that went up."""
    return (EDGE_ARM_UP if arm_dir > 0 else 0) | (EDGE_ROAD_UP if road_dir > 0 else 0)


def edge_from_wire(age_us: int, dirs: int, up_bit: int) -> tuple[int, int]:
    """(age, direction) of one encoder from the wire: direction 0 when the age says no recent edge."""
    if age_us >= EDGE_AGE_NONE:
        return EDGE_AGE_NONE, 0
    return age_us, 1 if dirs & up_bit else -1


def edge_age_to_wire(age_us: int) -> int:
    """An edge age [µs] as the wire's u16: ages of EDGE_AGE_NONE or more (and negative ones, which
    no board sends) saturate to EDGE_AGE_NONE."""
    return age_us if 0 <= age_us < EDGE_AGE_NONE else EDGE_AGE_NONE


def current_to_wire(current_a: float, signed: bool) -> int:
    """Coil current [A] -> wire counts (0.5 mA), rounded and clamped to 16 bit; NaN -> 0."""
    if current_a != current_a:
        return 0
    counts = round(current_a / CURRENT_LSB_A)
    low, high = (-32768, 32767) if signed else (0, 65535)
    return min(max(counts, low), high)


def road_speed_to_wire(speed_rad_s: float) -> int:
    """Road-wheel speed [rad/s] -> wire counts (1 µrad/s), clamped to signed 32 bit; NaN -> 0."""
    if speed_rad_s != speed_rad_s:
        return 0
    counts = round(speed_rad_s / ROAD_SPEED_LSB_RAD_S)
    return min(max(counts, -(2**31)), 2**31 - 1)

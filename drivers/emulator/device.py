"""The rig's interface board as seen from the host: protocol messages in, messages out.

:class:`RigDevice` is the device logic of the emulator, free of I/O and of the wall clock: every
call takes the time ``now_ns``. It runs the simulated rig (the :class:`SimulatedRig` sensor model
around :class:`RigPlant`, seed 001 eqs. 13-17; no physics here), answers Hello and Configure,
streams samples (device pacing) or answers each Command with one (host pacing), and keeps the
device watchdog: armed by the first Command, no valid Command for ``watchdog_ms`` -> drive 0 A and
set FLAG_WATCHDOG until the next valid Command.

A session starts at each Configure: the operator (``hold_deg``/``release_after_s``, or the host's
last hold prompt with a :class:`~sashil.drivers.emulator.console.HostConsole`) presses the arm to
the hold angle then, and the ``*_after_s`` fault times count from then.

With a :class:`~sashil.drivers.emulator.truth.TruthLog` in :attr:`RigDevice.truth` every sample
taken also records the plant's true state (``sashil emulate --truth``).
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass

from sashil.drivers.emulator.console import HostConsole
from sashil.drivers.emulator.truth import TruthLog
from sashil.drivers.emulator.wire import Payload
from sashil.drivers.interface import FLAG_STUCK_SENSOR, FLAG_WATCHDOG, RigCommand, RigSample, clamp_current
from sashil.drivers.messages import (
    CMD_ENABLE,
    EDGE_AGE_NONE,
    FAULT_BAD_CONFIGURE,
    FAULT_NONE,
    PACING_DEVICE,
    PACING_HOST,
    PROTOCOL_VERSION,
    Command,
    Configure,
    Hello,
    Message,
    RoadSpeed,
    Sample,
    Status,
    Version,
)
from sashil.drivers.sim import SimulatedRig

#: one encoder's last count change on the emulator's clock: (host time [ns], direction), or None
Edge = tuple[int, int] | None


def edge_age(edge: Edge, boot_ns: int, device_time_us: int) -> tuple[int, int]:
    """(age [us], direction) of an encoder's last count change in a sample taken at ``device_time_us``
    (microseconds since ``boot_ns``), as a board's timer capture gives it (sashil_board.c edge_age):
    EDGE_AGE_NONE and 0 for none or one 65.535 ms old or more."""
    if edge is None:
        return EDGE_AGE_NONE, 0
    age = device_time_us - (edge[0] - boot_ns) // 1000
    if age >= EDGE_AGE_NONE:
        return EDGE_AGE_NONE, 0
    return max(age, 0), edge[1]


@dataclass
class Faults:
    """Fault injection (emulator CLI flags). Rates are per outgoing frame; times from session start."""

    drop_rate: float = 0.0  # frames the device never sends
    corrupt_rate: float = 0.0  # frames sent with a bad CRC (serial) / rejected by the bus (CAN)
    latency_ms: float = 0.0  # every outgoing frame is delayed by this much
    stall_after_s: float | None = None  # then the device goes silent (sends nothing, reads nothing)
    disconnect_after_s: float | None = None  # then the link is closed (the pty disappears)
    stuck_sensor_after_s: float | None = None  # then both encoders freeze (FLAG_STUCK_SENSOR)
    seed: int = 0

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)

    def drop(self) -> bool:
        return self.drop_rate > 0.0 and self.rng.random() < self.drop_rate

    def corrupt(self) -> bool:
        return self.corrupt_rate > 0.0 and self.rng.random() < self.corrupt_rate


@dataclass
class Operator:
    """The person of a drop test: press the arm to ``hold_deg``, let go ``release_after_s`` later.

    With ``then_deg`` the hold angle of each later session is the next of ``hold_deg, *then_deg``,
    round and round (a calibration's plan: drops from several angles, one session each). With
    ``console`` the operator reads the host's prompts instead: each session holds at the angle of
    the last hold prompt the host has said (it says it before it connects, for a repeated step as
    for a new one), and only before the first prompt at the angles in turn."""

    hold_deg: float
    release_after_s: float
    then_deg: tuple[float, ...] = ()
    sessions: int = 0
    #: told of each hold as it starts (the board cannot know whether the host runs a drop test)
    announce: Callable[[str], None] | None = None
    #: the host's console, read at each session for its last hold prompt (``sashil emulate --prompts``)
    console: HostConsole | None = None

    def next_hold_deg(self) -> float:
        """The hold angle of the next session."""
        angles = (self.hold_deg, *self.then_deg)
        angle = angles[self.sessions % len(angles)]
        self.sessions += 1
        prompted = self.console.latest_hold_deg() if self.console is not None else None
        if prompted is not None:
            angle, why = prompted, "as the host's last prompt asks (--prompts)"
        elif self.console is not None:
            why = "no hold prompt from the host yet (--hold-deg)"
        else:
            why = "whatever the host runs (--hold-deg)"
        if self.announce is not None:
            self.announce(
                f"host connected (session {self.sessions}): the operator holds the arm at {angle:g} deg and lets go "
                f"{self.release_after_s:g} s later, {why}"
            )
        return angle


class RigDevice:
    """Device logic of the emulated interface board (see module docstring)."""

    def __init__(
        self,
        rig: SimulatedRig,
        operator: Operator | None = None,
        faults: Faults | None = None,
        fixed_rate_hz: int | None = None,
    ):
        self.rig = rig
        self.fixed_rate_hz = fixed_rate_hz  # a board with a fixed sample timer refuses other rates
        rig.configure()
        rig.activate()  # the simulated coil follows whatever this board drives
        self.operator = operator
        self.faults = faults or Faults()
        self.road = rig.wheel  # the simulated rig's road motor: Command speeds go to it
        self.configured = False
        self.rate_hz = 1000
        self.watchdog_ns = 50_000_000
        self.pacing = PACING_DEVICE
        self.session_start_ns: int | None = None
        self.boot_ns: int | None = None
        self.drive_a = 0.0  # the current the board drives the coil towards
        self.watchdog_trips = 0
        self.watchdog_tripped = False
        self.bad_frames = 0  # set by the transport (frames it could not decode)
        self._last_cmd_ns: int | None = None
        self._next_sample_ns = 0
        self._sample_seq = 0
        self._tx_seq = 0
        self._stuck: tuple[int, int, Edge, Edge] | None = None
        self.samples_sent = 0
        self.overruns = 0
        #: called with (now_ns, drive_a) whenever the drive current changes (tests, logging)
        self.on_drive: Callable[[int, float], None] | None = None
        #: the plant's true state at every sample taken (``sashil emulate --truth``), or None
        self.truth: TruthLog | None = None

    # time ------------------------------------------------------------------------------------
    def session_time_s(self, now_ns: int) -> float | None:
        return None if self.session_start_ns is None else (now_ns - self.session_start_ns) * 1e-9

    def next_event_ns(self) -> int | None:
        """When :meth:`tick` has something to do next (None: only host messages matter)."""
        events = []
        if self.configured and self.pacing == PACING_DEVICE:
            events.append(self._next_sample_ns)
        if self._last_cmd_ns is not None and not self.watchdog_tripped:
            events.append(self._last_cmd_ns + self.watchdog_ns)
        return min(events) if events else None

    # host messages ---------------------------------------------------------------------------
    def handle(self, msg: Payload, now_ns: int) -> list[tuple[int, Message]]:
        """Act on one message from the host; returns the replies as (seq, message)."""
        if self.boot_ns is None:
            self.boot_ns = now_ns
        if isinstance(msg, Command):
            return self._command(msg, now_ns)
        if isinstance(msg, Hello):
            version = Version(PROTOCOL_VERSION, self.rig.counts_per_rev, self.rig.plant.current_max_a)
            return [self._reply(version)]
        if isinstance(msg, Configure):
            return [self._reply(self._configure(msg, now_ns))]
        if isinstance(msg, RoadSpeed):
            self._advance(now_ns)
            self.road.set_speed(self.rig.plant, msg.speed_rad_s)
            return []
        return []  # device-to-host messages coming back, or raw wire (for a C board): ignore

    def _configure(self, msg: Configure, now_ns: int) -> Status:
        rate_ok = 1 <= msg.rate_hz <= 20_000 and self.fixed_rate_hz in (None, msg.rate_hz)
        if not (rate_ok and 1 <= msg.watchdog_ms and msg.pacing in (PACING_DEVICE, PACING_HOST)):
            return Status(self.flags(), FAULT_BAD_CONFIGURE, self.bad_frames, self.watchdog_trips)
        self.rate_hz, self.watchdog_ns, self.pacing = msg.rate_hz, msg.watchdog_ms * 1_000_000, msg.pacing
        self._advance(now_ns)
        self.configured = True
        self.session_start_ns = now_ns
        self._next_sample_ns = now_ns
        self._stuck = None
        self._set_drive(0.0, now_ns)
        self._last_cmd_ns = None
        self.watchdog_tripped = False
        if self.operator is not None:
            self.rig.operator_hold(math.radians(self.operator.next_hold_deg()), self.operator.release_after_s)
        return Status(self.flags(), FAULT_NONE, self.bad_frames, self.watchdog_trips)

    def _command(self, msg: Command, now_ns: int) -> list[tuple[int, Message]]:
        if not self.configured:
            return []
        self._advance(now_ns)
        self._last_cmd_ns = now_ns
        self.watchdog_tripped = False
        self._set_drive(msg.current_a if msg.flags & CMD_ENABLE else 0.0, now_ns)
        if self.pacing == PACING_HOST:
            return [self._sample(now_ns)]
        return []

    # device time -----------------------------------------------------------------------------
    def tick(self, now_ns: int) -> list[tuple[int, Message]]:
        """Watchdog, and in device pacing the sample that is due; returns what to send."""
        if self.boot_ns is None:
            self.boot_ns = now_ns
        out: list[tuple[int, Message]] = []
        if (
            self._last_cmd_ns is not None
            and not self.watchdog_tripped
            and now_ns - self._last_cmd_ns >= self.watchdog_ns
        ):
            self._advance(now_ns)
            self.watchdog_tripped = True
            self.watchdog_trips += 1
            self._set_drive(0.0, now_ns)
            if self.road.speed_rad_s != 0.0:  # coil and road to rest
                self.road.set_speed(self.rig.plant, 0.0)
            out.append(self._reply(Status(self.flags(), FAULT_NONE, self.bad_frames, self.watchdog_trips)))
        if self.configured and self.pacing == PACING_DEVICE and now_ns >= self._next_sample_ns:
            out.append(self._sample(now_ns))
            period = round(1e9 / self.rate_hz)
            self._next_sample_ns += period
            if self._next_sample_ns <= now_ns:  # fell behind by a whole period: do not burst
                self.overruns += 1
                self._next_sample_ns = now_ns + period
        return out

    def flags(self) -> int:
        flags = FLAG_WATCHDOG if self.watchdog_tripped else 0
        if self._stuck is not None:
            flags |= FLAG_STUCK_SENSOR
        return flags

    def _set_drive(self, current_a: float, now_ns: int) -> None:
        drive = clamp_current(current_a, self.rig.plant.current_max_a)
        self.rig.write(RigCommand(drive), now_ns, 0)
        if drive != self.drive_a:
            self.drive_a = drive
            if self.on_drive is not None:
                self.on_drive(now_ns, drive)

    def _advance(self, now_ns: int) -> RigSample:
        """Step the plant to ``now_ns`` (the sensor model advances with each read)."""
        return self.rig.read(now_ns, 0)

    def _sample(self, now_ns: int) -> tuple[int, Message]:
        reading = self._advance(now_ns)
        arm, road = reading.arm_counts, reading.road_counts
        arm_edge, road_edge = self.rig.arm_edge, self.rig.road_edge
        stuck_after = self.faults.stuck_sensor_after_s
        elapsed = self.session_time_s(now_ns)
        if stuck_after is not None and elapsed is not None and elapsed >= stuck_after:
            if self._stuck is None:
                self._stuck = (arm, road, arm_edge, road_edge)
            arm, road, arm_edge, road_edge = self._stuck
        self._sample_seq = (self._sample_seq + 1) & 0xFFFF
        self.samples_sent += 1
        boot = self.boot_ns if self.boot_ns is not None else now_ns
        device_time_us = (now_ns - boot) // 1000
        if self.truth is not None:
            self.truth.record(self._sample_seq, device_time_us, self.rig.plant)
        return self._sample_seq, Sample(
            device_time_us,
            arm,
            road,
            reading.current_a,
            reading.flags | self.flags(),
            *edge_age(arm_edge, boot, device_time_us),
            *edge_age(road_edge, boot, device_time_us),
        )

    def _reply(self, msg: Message) -> tuple[int, Message]:
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        return self._tx_seq, msg

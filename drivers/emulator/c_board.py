"""The emulated interface board running the firmware's C logic (``sashil emulate --board c``).

:class:`CBoardDevice` is a peer of :class:`~sashil.drivers.emulator.device.RigDevice` for the
:class:`~sashil.drivers.emulator.runner.Emulator`: the same ``handle``/``tick``/``next_event_ns``
calls on the emulator's clock, but the board between the link and the rig is ``sashil_board.c``
(loaded with ctypes, :mod:`sashil.drivers.firmware`). It takes the link's raw bytes (serial) or
CAN frames (SLCAN, python-can) as they arrive, and what it sends goes to the link unchanged: the
host talks to the very framing, session, pacing and watchdog code a real board runs.

Behind the board's hardware interface is the simulated rig of the Python board (the
:class:`~sashil.drivers.sim.SimulatedRig` sensor model around the plant of seed 001 eqs. 13-17, and
the :class:`~sashil.drivers.sim.RoadWheel`), in the wire's units: encoder counts, the
coil current in 0.5 mA counts, the road speed in µrad/s. The plant is advanced to the present
before each call into the board. What is not the board's is emulated here as before: the operator
(pressing the arm at each new session, which the board counts), a stuck encoder (the sensor
freezes; the hardware's fault flag), and the ground truth log.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable

from sashil.drivers import firmware
from sashil.drivers.emulator.device import Edge, Faults, Operator
from sashil.drivers.emulator.truth import TruthLog
from sashil.drivers.emulator.wire import WireBytes, WireCan
from sashil.drivers.interface import FLAG_STUCK_SENSOR, RigCommand, RigSample
from sashil.drivers.messages import CURRENT_LSB_A, ROAD_SPEED_LSB_RAD_S, current_to_wire
from sashil.drivers.sim import SimulatedRig

LINK_SERIAL = 0
LINK_CAN = 1
NO_EVENT_US = (1 << 64) - 1


class CBoardDevice:
    """The C board with the simulated rig behind its hardware interface (see module docstring)."""

    def __init__(
        self,
        rig: SimulatedRig,
        link: str = "serial",
        operator: Operator | None = None,
        faults: Faults | None = None,
        fixed_rate_hz: int | None = None,
        truth: TruthLog | None = None,
    ):
        self.lib = firmware.load()
        self.rig = rig
        rig.configure()
        rig.activate()  # the simulated coil follows whatever the board drives
        self.operator = operator
        self.faults = faults or Faults()
        self.truth = truth
        self.road = rig.wheel  # the simulated rig's road motor
        self.link = link
        self.drive_a = 0.0
        self._link_bad_frames = 0  # the link's own (an SLCAN adapter's garbled lines)
        self.samples_sent = 0
        self.session_start_ns: int | None = None
        self.boot_ns: int | None = None
        self.on_drive: Callable[[int, float], None] | None = None
        self._now_ns = 0
        self._reading: RigSample | None = None
        self._sample_edges: tuple[Edge, Edge] = (None, None)  # the edges of the sample being taken
        self._stuck: tuple[int, int, Edge, Edge] | None = None
        self._out: list[tuple[int, WireBytes | WireCan]] = []

        def read_encoders(_ctx: object, arm: ctypes._Pointer, road: ctypes._Pointer) -> None:
            arm[0], road[0] = self._sample_encoders()

        def read_current(_ctx: object) -> int:
            return current_to_wire(self._read().current_a, signed=True)

        def set_coil(_ctx: object, counts: int) -> None:
            self._set_drive(counts * CURRENT_LSB_A)

        def set_road_speed(_ctx: object, urad_s: int) -> None:
            self.road.set_speed(self.rig.plant, urad_s * ROAD_SPEED_LSB_RAD_S)

        def sensor_flags(_ctx: object) -> int:
            return (self._read().flags | (FLAG_STUCK_SENSOR if self._stuck is not None else 0)) & 0xFF

        def send(_ctx: object, data: ctypes._Pointer, n: int) -> None:
            self._out.append((0, WireBytes(bytes(data[:n]))))

        def send_can(_ctx: object, can_id: int, data: ctypes._Pointer, n: int) -> None:
            self._out.append((0, WireCan(can_id, bytes(data[:n]))))

        def read_edges(_ctx: object, arm: ctypes._Pointer, road: ctypes._Pointer) -> None:
            for edge, out in zip(self._sample_edges, (arm, road), strict=True):
                if edge is None:
                    out[0].time_us, out[0].dir = 0, 0
                else:  # the board's microsecond clock, as a timer capture stamps it (32 bit, wraps)
                    out[0].time_us = ((edge[0] - (self.boot_ns or 0)) // 1000) & 0xFFFFFFFF
                    out[0].dir = edge[1]

        self._callbacks = (  # ctypes callbacks live as long as the board
            firmware.ReadEncoders(read_encoders),
            firmware.ReadCurrent(read_current),
            firmware.SetCoil(set_coil),
            firmware.SetRoadSpeed(set_road_speed),
            firmware.SensorFlags(sensor_flags),
            firmware.Send(send),
            firmware.SendCan(send_can),
            firmware.ReadEdges(read_edges),
        )
        self._hal = firmware.Hal(None, *self._callbacks)
        self._board = ctypes.create_string_buffer(self.lib.sashil_board_size())
        current_max = current_to_wire(rig.plant.current_max_a, signed=False)
        self.lib.sashil_board_init(
            self._board, ctypes.byref(self._hal), rig.counts_per_rev, current_max, fixed_rate_hz or 0
        )
        self.lib.sashil_board_set_link(self._board, LINK_CAN if link == "can" else LINK_SERIAL)
        self._sessions = 0

    # the emulator's device interface ------------------------------------------------------------
    @property
    def configured(self) -> bool:
        return self._sessions > 0

    @property
    def bad_frames(self) -> int:
        """Frames from the host the board could not decode, and those the link itself rejected."""
        return int(self.lib.sashil_board_bad_frames(self._board)) + self._link_bad_frames

    @bad_frames.setter
    def bad_frames(self, link_bad_frames: int) -> None:  # the emulator passes the transport's count
        self._link_bad_frames = link_bad_frames

    @property
    def watchdog_trips(self) -> int:
        return int(self.lib.sashil_board_watchdog_trips(self._board))

    @property
    def overruns(self) -> int:
        return int(self.lib.sashil_board_overruns(self._board))

    def session_time_s(self, now_ns: int) -> float | None:
        return None if self.session_start_ns is None else (now_ns - self.session_start_ns) * 1e-9

    def next_event_ns(self) -> int | None:
        due_us = int(self.lib.sashil_board_next_event_us(self._board))
        if due_us == NO_EVENT_US or self.boot_ns is None:
            return None
        return self.boot_ns + due_us * 1000

    def handle(self, msg: object, now_ns: int) -> list[tuple[int, WireBytes | WireCan]]:
        """Hand what the link received (raw bytes, or one CAN frame) to the board."""
        self._enter(now_ns)
        if isinstance(msg, WireBytes):
            data = msg.data
            self.lib.sashil_board_receive(self._board, _buffer(data), len(data), self._now_us())
        elif isinstance(msg, WireCan):
            data = msg.data
            self.lib.sashil_board_receive_can(self._board, msg.can_id, _buffer(data), len(data), self._now_us())
        self._new_session(now_ns)
        return self._take_output()

    def tick(self, now_ns: int) -> list[tuple[int, WireBytes | WireCan]]:
        """The board's timer: watchdog, and the sample that is due."""
        self._enter(now_ns)
        self.lib.sashil_board_tick(self._board, self._now_us())
        return self._take_output()

    # hardware behind the interface ----------------------------------------------------------------
    def _enter(self, now_ns: int) -> None:
        if self.boot_ns is None:
            self.boot_ns = now_ns
        self._now_ns = now_ns
        self._reading = None  # the plant is advanced at the first read of this call

    def _now_us(self) -> int:
        return (self._now_ns - (self.boot_ns or 0)) // 1000

    def _read(self) -> RigSample:
        if self._reading is None:
            self._reading = self.rig.read(self._now_ns, 0)
        return self._reading

    def _sample_encoders(self) -> tuple[int, int]:
        """The encoders at a sample (the board reads them once per sample): frozen after the stuck
        sensor fault with their last edges, and the plant's true state logged for ``--truth``."""
        reading = self._read()
        arm, road = reading.arm_counts, reading.road_counts
        arm_edge, road_edge = self.rig.arm_edge, self.rig.road_edge
        elapsed = self.session_time_s(self._now_ns)
        stuck_after = self.faults.stuck_sensor_after_s
        if stuck_after is not None and elapsed is not None and elapsed >= stuck_after:
            if self._stuck is None:
                self._stuck = (arm, road, arm_edge, road_edge)
            arm, road, arm_edge, road_edge = self._stuck
        self._sample_edges = (arm_edge, road_edge)
        self.samples_sent += 1
        if self.truth is not None:
            self.truth.record(self.samples_sent & 0xFFFF, self._now_us(), self.rig.plant)
        return arm, road

    def _set_drive(self, current_a: float) -> None:
        self._read()  # the plant reaches the present under the old current
        self.rig.write(RigCommand(current_a), self._now_ns, 0)
        self._reading = None
        if current_a != self.drive_a:
            self.drive_a = current_a
            if self.on_drive is not None:
                self.on_drive(self._now_ns, current_a)

    def _new_session(self, now_ns: int) -> None:
        """A Configure the board honoured: the operator presses the arm, fault times count from now."""
        sessions = int(self.lib.sashil_board_sessions(self._board))
        if sessions == self._sessions:
            return
        self._sessions = sessions
        self.session_start_ns = now_ns
        self._stuck = None
        if self.operator is not None:
            self.rig.operator_hold(math.radians(self.operator.next_hold_deg()), self.operator.release_after_s)

    def _take_output(self) -> list[tuple[int, WireBytes | WireCan]]:
        out, self._out = self._out, []
        return out


def _buffer(data: bytes) -> ctypes.Array[ctypes.c_uint8]:
    return (ctypes.c_uint8 * max(len(data), 1)).from_buffer_copy(data if data else b"\0")

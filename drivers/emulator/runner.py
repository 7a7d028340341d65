"""Runs a :class:`RigDevice` on a transport in real time (own process, or a thread in tests).

One loop: wait for host bytes until the device's next event (sample due, watchdog deadline) or a
delayed frame is due; hand what arrived to the device; let the device tick; send its output
through the fault injection (drop, corrupt, latency). The stall and disconnect faults are the
link's: after ``stall_after_s`` it neither reads nor sends, after ``disconnect_after_s`` it closes
the link and returns. In both the board itself keeps running, as a real one does whatever its link
does: its timer ticks, so its watchdog still puts coil and road to rest ``watchdog_ms`` after the
last Command (the disconnect returns only once it has).
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sashil.drivers import rig_parts
from sashil.drivers.emulator.device import Faults, Operator, RigDevice
from sashil.drivers.emulator.transports import (
    DeviceTransport,
    Pty,
    SerialPtyTransport,
    SlcanPtyTransport,
    VirtualCanTransport,
)
from sashil.drivers.emulator.truth import TruthLog
from sashil.drivers.emulator.wire import Payload
from sashil.drivers.sim import SimulatedRig

MAX_WAIT_S = 0.02  # upper bound of one wait (keeps stop requests responsive)

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig
    from sashil.drivers.emulator.c_board import CBoardDevice

    Board = RigDevice | CBoardDevice


BOARDS = ("python", "c")


def build_device(
    config: RunConfig,
    operator: Operator | None = None,
    faults: Faults | None = None,
    fixed_rate_hz: int | None = None,
    truth: TruthLog | None = None,
    board: str = "python",
    link: str = "serial",
) -> Board:
    """The emulated board around the simulated rig the config describes (model, rig and mismatch
    sections: ``SimulatedRig.from_parts``); ``truth`` records the plant's state at each sample.
    ``board``: ``python`` (:class:`RigDevice`) or ``c`` (the firmware's C logic,
    :class:`~sashil.drivers.emulator.c_board.CBoardDevice`, which needs a C compiler; DriverError
    if there is none); ``link``: ``serial`` or ``can``, the frames the C board speaks."""
    rig = SimulatedRig.from_parts(rig_parts(config, "sim"))
    if board == "c":
        from sashil.drivers.emulator.c_board import CBoardDevice

        return CBoardDevice(rig, link, operator, faults, fixed_rate_hz, truth)
    if board != "python":
        raise ValueError(f"board: expected one of {', '.join(BOARDS)}, got {board!r}")
    device = RigDevice(rig, operator, faults, fixed_rate_hz)
    device.truth = truth
    return device


@dataclass
class EmulatorStats:
    stopped_by: str = ""  # "stop", "duration", "disconnect"
    stalled: bool = False
    delayed: list[tuple[int, int, int, Payload, bool]] = field(default_factory=list)


class Emulator:
    """The device loop (see module docstring)."""

    def __init__(self, device: Board, transport: DeviceTransport, clock: Callable[[], int] = time.monotonic_ns):
        self.device = device
        self.transport = transport
        self.clock = clock
        self.stop_event = threading.Event()
        #: set by a signal handler (request_stop): a plain attribute, no lock — a handler that took the
        #: Event's lock deadlocked when a second signal arrived while the first one's set() held it
        self.stop_requested = False
        self.stats = EmulatorStats()
        self._order = 0

    def stop(self) -> None:
        """Stop from another thread (wakes a wait at once)."""
        self.stop_requested = True
        self.stop_event.set()

    def request_stop(self) -> None:
        """Stop from a signal handler: async-signal-safe (no lock); seen within MAX_WAIT_S."""
        self.stop_requested = True

    def run(self, duration_s: float | None = None) -> str:
        """Serve the host until stopped, ``duration_s`` passed, or the disconnect fault; returns why."""
        device, transport, faults = self.device, self.transport, self.device.faults
        start = self.clock()
        end = None if duration_s is None else start + int(duration_s * 1e9)
        try:
            while not self.stop_requested:
                now = self.clock()
                if end is not None and now >= end:
                    return self._stopped("duration")
                session = device.session_time_s(now)
                if (
                    session is not None
                    and faults.disconnect_after_s is not None
                    and session >= faults.disconnect_after_s
                ):
                    transport.close()
                    self._run_unlinked(now)
                    return self._stopped("disconnect")
                if session is not None and faults.stall_after_s is not None and session >= faults.stall_after_s:
                    self.stats.stalled = True
                    self._tick_unlinked(now)
                    continue
                wait_ns = int(MAX_WAIT_S * 1e9)
                for event in (device.next_event_ns(), self._next_delayed_ns(), end):
                    if event is not None:
                        wait_ns = min(wait_ns, event - now)
                received = transport.receive(max(wait_ns, 0) * 1e-9)
                now = self.clock()
                device.bad_frames = transport.bad_frames
                out: list[tuple[int, Payload]] = []
                for _seq, msg in received:
                    out += device.handle(msg, now)
                out += device.tick(now)
                for seq, msg in out:
                    self._emit(seq, msg, now)
                self._flush_delayed(now)
            return self._stopped("stop")
        finally:
            transport.close()

    def _tick_unlinked(self, now: int) -> None:
        """One wait and tick of the board with its link silent: the watchdog runs, nothing is sent."""
        event = self.device.next_event_ns()
        wait_ns = int(MAX_WAIT_S * 1e9) if event is None else min(int(MAX_WAIT_S * 1e9), max(event - now, 0))
        self.stop_event.wait(wait_ns * 1e-9)
        self.device.tick(self.clock())  # what it would send goes nowhere

    def _run_unlinked(self, now: int) -> None:
        """After a disconnect: tick until the watchdog has put the coil and road at rest (or stop)."""
        device = self.device
        while not self.stop_requested and device.drive_a != 0.0 and device.configured:
            self._tick_unlinked(now)
            now = self.clock()

    def _stopped(self, why: str) -> str:
        self.stats.stopped_by = why
        return why

    # output with fault injection ---------------------------------------------------------
    def _emit(self, seq: int, msg: Payload, now: int) -> None:
        faults = self.device.faults
        if faults.drop():
            return
        corrupt = faults.corrupt()
        if faults.latency_ms > 0.0:
            self._order += 1
            due = now + int(faults.latency_ms * 1e6)
            heapq.heappush(self.stats.delayed, (due, self._order, seq, msg, corrupt))
            return
        self.transport.send(seq, msg, corrupt)

    def _next_delayed_ns(self) -> int | None:
        return self.stats.delayed[0][0] if self.stats.delayed else None

    def _flush_delayed(self, now: int) -> None:
        delayed = self.stats.delayed
        while delayed and delayed[0][0] <= now:
            _, _, seq, msg, corrupt = heapq.heappop(delayed)
            self.transport.send(seq, msg, corrupt)


def open_transport(
    transport: str, raw: bool, channel: str = "sashil-emulator", link: str | None = None
) -> DeviceTransport:
    """The device side of ``transport``: ``serial`` or ``slcan`` on a new pty (``link``: a symlink
    to it), or ``virtual`` (python-can's bus ``channel``); ``raw`` for a board that frames itself."""
    if transport == "virtual":
        return VirtualCanTransport(channel, raw)
    pty = Pty.open(link)
    return SerialPtyTransport(pty, raw) if transport == "serial" else SlcanPtyTransport(pty, raw)


class EmulatorThread:
    """An emulator serving in a thread of this process (tests, benchmarks).

    ``transport``: ``serial`` or ``slcan`` (a pty; the host opens :attr:`port`) or ``virtual``
    (python-can's virtual bus; :attr:`port` is the channel name). ``truth``, ``board``: see
    :func:`build_device`.
    """

    def __init__(
        self,
        config: RunConfig,
        transport: str = "serial",
        operator: Operator | None = None,
        faults: Faults | None = None,
        channel: str = "sashil-emulator",
        truth: TruthLog | None = None,
        board: str = "python",
    ):
        link = "serial" if transport == "serial" else "can"
        self.device = build_device(config, operator, faults, truth=truth, board=board, link=link)
        self.link = open_transport(transport, board == "c", channel)
        self.port = channel if transport == "virtual" else self.link.description
        self.emulator = Emulator(self.device, self.link)
        self.result: str | None = None
        self._thread = threading.Thread(target=self._run, name="sashil-emulator", daemon=True)

    def _run(self) -> None:
        self.result = self.emulator.run()

    def __enter__(self) -> EmulatorThread:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        self.emulator.stop()
        self._thread.join(timeout=5.0)

"""What the serial and the CAN backend share: handshake, pacing, sample bookkeeping, safe stop.

A subclass moves messages (``sashil.drivers.messages``) over its link with four methods:
``_open()``, ``_send(seq, msg)``, ``_receive(timeout_s) -> [(seq, msg)]`` and ``_close_link()``;
it wraps its library's exceptions as :class:`DriverIOError`. This class keeps the RigInterface
contract on top (protocol.md "Session"):

- ``configure()``: open, Hello -> Version (the protocol version must match, the encoder resolution
  must match the config), Configure -> Status; any failure closes the link again and raises
  :class:`DriverError` (exit 2). Nothing is energised: the device drives 0 A until a Command with
  the ENABLE flag, and it only gets one after ``activate()``.
- Pacing ``device`` (default): the device streams samples at the loop rate; ``read`` returns the
  newest sample, waiting for one if none arrived since the last read. Pacing ``host``: each
  Command is answered by one Sample; ``read`` waits for the answer to the last Command (or polls
  with the current setpoint when none is outstanding).
- A **link gap**: after ``driver.sample_timeout_ms`` without a sample ``read`` commands 0 A at
  once (the safe state, within 3 cycles at the defaults) and keeps listening. A sample within
  ``driver.link_lost_ms`` (counted from when ``read`` began to wait) ends the gap: the run goes on and the gap
  is counted (``gaps``, ``gap_max_ms``). No sample by then: :class:`DriverTimeoutError`, the run
  ends. ``link_lost_ms <= sample_timeout_ms`` ends the run at the sample timeout. A short device
  silence (a USB serial adapter batching bytes, an emulator's process paused by its machine) then
  costs a few cycles at 0 A instead of the run; a stalled or lost link still ends it.
  Time the host process itself was paused (a wait that returns well past its timeout) does not
  count: the device was not silent then, the host was not listening (``host_pauses`` in the stats).
- ``deactivate()`` sends Command(0 A, not enabled) and never raises; ``close()`` is idempotent.
"""

from __future__ import annotations

import logging
import time
from abc import abstractmethod
from collections.abc import Callable, Mapping
from typing import Any

from sashil.drivers.interface import (
    FLAG_HELD,
    FLAG_WATCHDOG,
    NO_EDGE,
    RigCapabilities,
    RigCommand,
    RigInterface,
    RigSample,
    RigState,
    clamp_current,
)
from sashil.drivers.messages import (
    CMD_ENABLE,
    FAULT_NO_CAN,
    PACING_DEVICE,
    PACING_HOST,
    PACING_NAMES,
    PROTOCOL_VERSION,
    STATUS_CLOCK_FALLBACK,
    Command,
    Configure,
    Hello,
    Message,
    RoadSpeed,
    Sample,
    Status,
    Version,
)
from sashil.errors import DriverError, DriverIOError, DriverTimeoutError

log = logging.getLogger(__name__)

#: a receive wait that overruns its timeout by more than this was a pause of the host process
HOST_PAUSE_S = 0.5e-3
#: deactivate waits this long for a sample that shows the coil at rest, resending 0 A meanwhile
SAFE_CONFIRM_S = 0.5
#: a measured coil current at most this (or 2 % of the range) confirms the coil is off
SAFE_CURRENT_A = 0.02
#: how long a probe for the protocol a silent device speaks instead waits for the answer
PROBE_S = 0.25


#: the config keys every link backend is built from (:class:`LinkSettings`)
LINK_READS: Mapping[str, str] = {
    "port": "driver.port",
    "rate_hz": "loop.rate_hz",
    "pacing": "driver.pacing",
    "watchdog_ms": "driver.watchdog_ms",
    "sample_timeout_ms": "driver.sample_timeout_ms",
    "link_lost_ms": "driver.link_lost_ms",
    "connect_timeout_s": "driver.connect_timeout_s",
    "counts_per_rev": "rig.encoder_counts_per_rev",
    "current_max_a": "rig.current_max_a",
}


class LinkSettings:
    """The values a link backend needs (:data:`LINK_READS`), checked once."""

    def __init__(self, values: Mapping[str, Any]):
        self.port: str | None = values["port"]
        self.rate_hz = int(round(values["rate_hz"]))
        self.pacing = PACING_NAMES[values["pacing"]]
        self.watchdog_ms = int(round(values["watchdog_ms"]))
        self.sample_timeout_s = values["sample_timeout_ms"] * 1e-3
        self.link_lost_s = max(values["link_lost_ms"] * 1e-3, self.sample_timeout_s)
        self.connect_timeout_s = values["connect_timeout_s"]
        self.counts_per_rev = values["counts_per_rev"]
        self.current_max_a = values["current_max_a"]


class LinkRig(RigInterface):
    """A rig on the far end of a link that carries the sashil messages."""

    #: bits of the device clock on this link (it wraps; the host unwraps it)
    device_time_bits = 32

    def __init__(self, settings: LinkSettings):
        super().__init__()
        self.settings = settings
        self.device_version: Version | None = None
        self.counts_per_rev = settings.counts_per_rev
        self.last_status: Status | None = None
        self._tx_seq = 0
        self._setpoint = 0.0
        self._road_speed: float | None = None
        self._pending = 0  # host pacing: Commands not yet answered by a Sample
        self._last_seq: int | None = None
        self._dev_time_raw: int | None = None
        self._dev_time_us = 0
        self._link_up = False
        self._held_noted = False  # said once per link that the device's operator holds the arm
        self._drop_test = False  # a drop test asked for the operator (operator_hold): a hold is expected
        #: messages decoded in the same read as a handshake's answer, after it: the next read takes them first
        self._unread: list[tuple[int, Message]] = []
        #: what the link saw (summary.json material); codec counters come from the subclass
        self.stats = {
            "samples": 0,
            "samples_missed": 0,
            "samples_skipped": 0,
            "timeouts": 0,
            "status_frames": 0,
            "host_pauses": 0,
            "gaps": 0,
            "gap_max_ms": 0.0,
            "zero_current_after_ms": 0.0,
            "clock_fallback": 0,  # 1: the board said its crystal failed (it runs on its internal oscillator)
            "watchdog_samples": 0,  # samples the board flagged: its watchdog had cut the coil
        }
        #: the last deactivate after an active session: did a sample show the coil at rest, how soon
        self.safe_state: dict[str, bool | float | None] = {"safe_state_confirmed": None, "safe_state_ms": None}

    # subclass hooks --------------------------------------------------------------------------
    @abstractmethod
    def _open(self) -> None: ...

    @abstractmethod
    def _send(self, seq: int, msg: Message) -> None: ...

    @abstractmethod
    def _receive(self, timeout_s: float) -> list[tuple[int, Message]]: ...

    @abstractmethod
    def _close_link(self) -> None: ...

    @abstractmethod
    def describe(self) -> str:
        """Where the rig is, for messages ("serial /dev/ttyACM0")."""

    def operator_hold(self, theta_rad: float, release_after_s: float) -> bool:
        """A person (or the emulator's ``--hold-deg``) holds the arm on a link rig: the drop test waits
        for the hold; a hold the device reports is then expected."""
        self._drop_test = True
        return False

    def _note_held(self) -> None:
        """Say once that the device reports its operator holding the arm when nothing asked for it
        (an emulator started with ``--hold-deg`` holds it at every connection)."""
        self._held_noted = True
        if not self._drop_test:
            log.warning(
                "%s: the device reports the arm held by its operator (an emulator's --hold-deg holds it at every "
                "connection); this run starts with the arm held until the operator lets go",
                self.describe(),
            )

    def _other_protocol(self) -> str | None:
        """When the device did not answer the handshake: the other protocol it answers instead, named
        with the driver that speaks it (from what it sent, or a probe), or None (silence, or unknown)."""
        return None

    #: the link carries CAN frames a trace can tap (CanRig)
    carries_can_frames = False

    @property
    def capabilities(self) -> RigCapabilities:  # type: ignore[override]  # depends on the configured pacing
        return RigCapabilities(
            road_actuator=True, device_paced=self.device_paced, link=True, can_frames=self.carries_can_frames
        )

    @property
    def device_paced(self) -> bool:
        """True when the device's sample timer paces the cycle (``read`` blocks until the next sample).

        A loop may then skip its own sleep to the deadline: its clock and the device's drift apart,
        and sleeping to one while waiting on the other shows up as lateness of up to a period.
        """
        return self.settings.pacing == PACING_DEVICE

    def codec_counters(self) -> dict[str, int]:
        return {}

    def link_stats(self) -> dict[str, Any]:
        """Sample bookkeeping, the decoder's counters (bad frames, ...) and the last safe-state check."""
        return {**self.stats, **self.codec_counters(), **self.safe_state}

    # lifecycle -------------------------------------------------------------------------------
    def configure(self) -> None:
        if self.state is RigState.CLOSED:
            raise DriverError(f"{self.describe()}: configure() after close()")
        if self.state is not RigState.UNCONFIGURED:
            return
        self._open()
        self._link_up = True
        try:
            self._handshake()
        except DriverError as err:
            self._shutdown_link()
            if type(err) is DriverError:
                raise
            raise DriverError(str(err)) from None  # a failed handshake is bad input: exit 2
        self.state = RigState.CONFIGURED

    def _handshake(self) -> None:
        s = self.settings
        self._send_msg(Command(0.0, 0))
        self._send_msg(Hello(PROTOCOL_VERSION))
        version = self._expect(Version, "Version (answer to Hello)")
        if version.protocol_version != PROTOCOL_VERSION:
            raise DriverError(
                f"{self.describe()}: the device speaks sashil protocol version {version.protocol_version}, "
                f"this host speaks {PROTOCOL_VERSION}"
            )
        if version.counts_per_rev != s.counts_per_rev:
            raise DriverError(
                f"{self.describe()}: the device's encoder has {version.counts_per_rev} counts/rev, "
                f"the config says rig.encoder_counts_per_rev: {s.counts_per_rev}"
            )
        self.device_version = version
        self.counts_per_rev = version.counts_per_rev
        self._send_msg(Configure(s.rate_hz, s.watchdog_ms, s.pacing))
        status = self._expect(Status, "Status (answer to Configure)")
        self.last_status = status
        if status.fault_code == FAULT_NO_CAN:
            raise DriverError(f"{self.describe()}: the device has no CAN transmitter: it refused a CAN session")
        if status.fault_code:
            raise DriverError(
                f"{self.describe()}: the device refused rate {s.rate_hz} Hz / watchdog {s.watchdog_ms} ms "
                f"(fault code {status.fault_code})"
            )
        if status.flags & STATUS_CLOCK_FALLBACK:
            self.stats["clock_fallback"] = 1
            log.warning(
                "%s: the board's crystal did not start: it runs on its internal oscillator "
                "(its sample period and watchdog within about 1 %%, not the crystal's ppm)",
                self.describe(),
            )

    def _expect(self, kind: type, what: str) -> Any:
        deadline = time.monotonic() + self.settings.connect_timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                other = self._other_protocol()
                if other is not None:
                    raise DriverError(
                        f"{self.describe()}: no {what} within {self.settings.connect_timeout_s:g} s: the board on "
                        f"this port answers {other}"
                    )
                raise DriverError(
                    f"{self.describe()}: no {what} within {self.settings.connect_timeout_s:g} s "
                    "(is a sashil rig on this port, and is it powered?)"
                )
            got = self._incoming(remaining)
            for k, (_, msg) in enumerate(got):
                if isinstance(msg, kind):
                    self._unread = got[k + 1 :]  # what came with the answer, for the cycle's reads
                    return msg

    def _incoming(self, timeout_s: float) -> list[tuple[int, Message]]:
        """The messages not yet taken: those left after a handshake's answer, then what the link has
        (without waiting when some were left)."""
        if not self._unread:
            return self._receive(timeout_s)
        got, self._unread = self._unread, []
        return got + self._receive(0.0)

    def wait_for_status(self, timeout_s: float) -> Status | None:
        """Listen without sending until the device sends a Status (a watchdog trip reports one) or
        ``timeout_s`` passes; samples that arrive meanwhile are counted as usual."""
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            before = self.stats["status_frames"]
            self._take_samples(self._incoming(remaining))
            if self.stats["status_frames"] > before:
                return self.last_status
        return None

    def activate(self) -> None:
        if self.state is not RigState.CONFIGURED:
            raise DriverError(f"{self.describe()}: activate() in state {self.state.value} (configure() first)")
        self.state = RigState.ACTIVE

    def deactivate(self) -> None:
        """0 A and the road at rest, then (after an active session) wait for a sample that shows the
        coil current at rest, resending 0 A, for up to :data:`SAFE_CONFIRM_S`; says so when none does
        (the device's watchdog still cuts the coil ``watchdog_ms`` after the last Command)."""
        self._setpoint = 0.0
        was_active = self.state is RigState.ACTIVE
        if was_active:
            self.state = RigState.CONFIGURED
        if not self._link_up:
            return
        try:
            if self._road_speed not in (None, 0.0):
                self._send_msg(RoadSpeed(0.0))
                self._road_speed = 0.0
            self._send_msg(Command(0.0, 0))
            if was_active:
                self._confirm_safe_state()
        except Exception as err:  # the link is failing: the device watchdog takes over
            log.warning("%s: deactivate: %s (the device watchdog cuts the coil)", self.describe(), error_reason(err))

    def _confirm_safe_state(self) -> None:
        """Wait for a sample that shows the coil at rest (module constants); record how it went."""
        limit = max(SAFE_CURRENT_A, 0.02 * self.settings.current_max_a)
        start = time.monotonic()
        deadline = start + SAFE_CONFIRM_S
        self._pending = 0
        while time.monotonic() < deadline:
            if self.settings.pacing == PACING_HOST:
                self._send_command()  # disabled: 0 A, and the poll for the sample that answers it
            got = self._wait_for_sample(None, min(deadline, time.monotonic() + self.settings.sample_timeout_s))
            measured = None if got is None else got[1].current_a
            # no current sense (NaN): in host pacing the sample answering a disabled Command confirms it
            unsensed = measured is not None and measured != measured and self.settings.pacing == PACING_HOST
            if measured is not None and (abs(measured) <= limit or unsensed):
                self.safe_state["safe_state_confirmed"] = True
                self.safe_state["safe_state_ms"] = round((time.monotonic() - start) * 1e3, 3)
                return
            if self.settings.pacing != PACING_HOST:
                self._send_msg(Command(0.0, 0))  # a lost frame must not leave the coil on
        self._pending = 0
        self.safe_state["safe_state_confirmed"] = False
        log.warning(
            "%s: deactivate: no sample showed the coil below %.3g A within %g ms of 0 A commanded "
            "(the device watchdog cuts it after watchdog_ms)",
            self.describe(),
            limit,
            SAFE_CONFIRM_S * 1e3,
        )

    def close(self) -> None:
        if self.state is RigState.CLOSED:
            return
        was_up = self._link_up
        self.deactivate()
        self._shutdown_link()
        self.state = RigState.CLOSED
        if was_up:
            stats = self.link_stats()
            lost = stats.get("bad_frames", 0) + stats["samples_missed"] + stats["timeouts"]
            (log.warning if lost else log.info)(
                "%s: link: %d samples, %d bad frames, %d samples missed, %d timeouts",
                self.describe(),
                stats["samples"],
                stats.get("bad_frames", 0),
                stats["samples_missed"],
                stats["timeouts"],
            )

    def _shutdown_link(self) -> None:
        self._link_up = False
        self._unread = []
        try:
            self._close_link()
        except Exception:
            pass

    # cycle -----------------------------------------------------------------------------------
    def read(self, t_ns: int, dt_ns: int) -> RigSample:
        if self.state not in (RigState.CONFIGURED, RigState.ACTIVE):
            raise DriverError(f"{self.describe()}: read() in state {self.state.value}")
        if self.settings.pacing == PACING_HOST and self._pending == 0:
            self._send_command()  # nothing outstanding: poll with the current setpoint
        newest = self._take_samples(self._incoming(0.0))
        if newest is None or self._pending:
            start = time.monotonic()
            newest = self._wait_for_sample(newest, start + self.settings.sample_timeout_s)
            if newest is None:
                newest = self._ride_through_gap(start)
        seq, sample = newest
        if sample.flags & FLAG_WATCHDOG:
            self.stats["watchdog_samples"] += 1
        if sample.flags & FLAG_HELD and not self._held_noted:
            self._note_held()
        device_time_us = self._unwrap_device_time(sample.device_time_us)
        return RigSample(
            seq=seq,
            time_ns=t_ns,
            device_time_us=device_time_us,
            arm_counts=sample.arm_counts,
            road_counts=sample.road_counts,
            current_a=sample.current_a,
            flags=sample.flags,
            counts_per_rev=self.counts_per_rev,
            # an edge's age back to the device's clock (the sample's own time minus the age)
            arm_edge_us=device_time_us - sample.arm_edge_age_us if sample.arm_edge_dir else NO_EDGE,
            arm_edge_dir=sample.arm_edge_dir,
            road_edge_us=device_time_us - sample.road_edge_age_us if sample.road_edge_dir else NO_EDGE,
            road_edge_dir=sample.road_edge_dir,
        )

    def _wait_for_sample(self, newest: tuple[int, Sample] | None, deadline: float) -> tuple[int, Sample] | None:
        """Receive until a sample (and, host-paced, the answer to the last Command) or ``deadline``."""
        while newest is None or self._pending:
            now = time.monotonic()
            remaining = deadline - now
            if remaining <= 0:
                break
            got = self._take_samples(self._incoming(remaining))
            newest = got if got is not None else newest
            # A wait that came back much later than asked means this process was not running
            # (a scheduler or VM pause, which stops an emulator on the same machine too): that
            # time was not the device's silence, so it does not count towards the timeout.
            overslept = time.monotonic() - now - remaining
            if got is None and overslept > HOST_PAUSE_S:
                deadline += overslept
                self.stats["host_pauses"] += 1
        return newest

    def _ride_through_gap(self, start: float) -> tuple[int, Sample]:
        """No sample for the sample timeout: 0 A now, then wait up to the link-lost time for one."""
        stats = self.stats
        settings = self.settings
        self._setpoint = 0.0
        self._pending = 0
        self._send_command()  # the device drives 0 A from here until the loop writes again
        stats["zero_current_after_ms"] = max(stats["zero_current_after_ms"], (time.monotonic() - start) * 1e3)
        # the rest of the link-lost time; the sample-timeout wait already added any host pause
        newest = self._wait_for_sample(None, time.monotonic() + settings.link_lost_s - settings.sample_timeout_s)
        if newest is None:
            stats["timeouts"] += 1
            self._pending = 0
            lost_ms = settings.link_lost_s * 1e3
            cut = (
                ""
                if settings.link_lost_s <= settings.sample_timeout_s
                else f"; current set to 0 A after {settings.sample_timeout_s * 1e3:g} ms"
            )
            raise DriverTimeoutError(
                f"{self.describe()}: no sample for {lost_ms:g} ms (device stalled or link lost{cut})"
            )
        gap_ms = (time.monotonic() - start) * 1e3
        stats["gaps"] += 1
        stats["gap_max_ms"] = max(stats["gap_max_ms"], round(gap_ms, 3))
        log.debug("%s: link gap of %.1f ms ridden through at 0 A", self.describe(), gap_ms)
        return newest

    def _take_samples(self, messages: list[tuple[int, Message]]) -> tuple[int, Sample] | None:
        newest = None
        stats = self.stats
        for seq, msg in messages:
            if isinstance(msg, Sample):
                if self._last_seq is not None:
                    stats["samples_missed"] += max(0, ((seq - self._last_seq) & 0xFFFF) - 1)
                self._last_seq = seq
                stats["samples"] += 1
                if newest is not None:
                    stats["samples_skipped"] += 1
                newest = (seq, msg)
                if self._pending:
                    self._pending -= 1
            elif isinstance(msg, Status):
                stats["status_frames"] += 1
                self.last_status = msg
        return newest

    def _unwrap_device_time(self, raw: int) -> int:
        if self._dev_time_raw is not None:
            self._dev_time_us += (raw - self._dev_time_raw) & ((1 << self.device_time_bits) - 1)
        else:
            self._dev_time_us = raw
        self._dev_time_raw = raw
        return self._dev_time_us

    def write(self, cmd: RigCommand, t_ns: int, dt_ns: int) -> None:
        if self.state is RigState.ACTIVE:
            current = cmd.current_a
            self._setpoint = clamp_current(current, self.settings.current_max_a)
        else:
            self._setpoint = 0.0
        speed = cmd.road_speed_rad_s
        if speed is not None and speed != self._road_speed and self.state is RigState.ACTIVE:
            self._send_msg(RoadSpeed(speed))
            self._road_speed = speed
        self._send_command()

    def _send_command(self) -> None:
        enabled = self.state is RigState.ACTIVE
        self._send_msg(Command(self._setpoint if enabled else 0.0, CMD_ENABLE if enabled else 0))
        if self.settings.pacing == PACING_HOST:
            self._pending += 1

    def _send_msg(self, msg: Message) -> None:
        if not self._link_up:
            raise DriverIOError(f"{self.describe()}: link is closed")
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        self._send(self._tx_seq, msg)


def read_raw(port: Any, seconds: float, enough: Callable[[bytes], bool]) -> bytes:
    """The bytes a pyserial port (read timeout 0) receives within ``seconds``, or fewer once ``enough``."""
    data = bytearray()
    deadline = time.monotonic() + seconds
    while not enough(bytes(data)) and time.monotonic() < deadline:
        waiting = port.in_waiting
        if waiting:
            data += port.read(waiting)
        else:
            time.sleep(0.005)
    return bytes(data)


def error_reason(err: BaseException) -> str:
    """The first line of a foreign exception's message, for a one-line DriverError."""
    text = str(err).strip() or type(err).__name__
    return text.splitlines()[0]


__all__ = ["PACING_DEVICE", "PACING_HOST", "DriverTimeoutError", "LinkRig", "LinkSettings"]

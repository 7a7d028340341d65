"""The board's session logic in C, driven through its hardware interface from Python.

The C board gets protocol frames made by serial_codec.py; what it sends is decoded with the Python
stream decoder; the hardware interface is a set of Python callbacks (encoders, current sense, coil,
road motor). Time is simulated (microseconds passed to receive/tick).
"""

from __future__ import annotations

import ctypes

import pytest

from sashil.drivers import can_codec, firmware
from sashil.drivers.can_codec import CanDecoder
from sashil.drivers.interface import FLAG_HELD, FLAG_WATCHDOG
from sashil.drivers.messages import (
    CMD_ENABLE,
    FAULT_BAD_CONFIGURE,
    FAULT_NO_CAN,
    PACING_DEVICE,
    PACING_HOST,
    PROTOCOL_VERSION,
    STATUS_CLOCK_FALLBACK,
    Command,
    Configure,
    Hello,
    RoadSpeed,
    Sample,
    Status,
    Version,
)
from sashil.drivers.serial_codec import StreamDecoder, encode_frame

if firmware.compiler() is None:  # pragma: no cover - the machine has no C compiler
    pytest.skip("no C compiler on this machine (install gcc or set CC)", allow_module_level=True)

LIB = firmware.load()
MS = 1000  # us


class Board:
    """The C board with a fake rig behind its hardware interface (``edges``: the encoders' last count
    changes the hardware reports, as ((time us, dir), (time us, dir)); None: no edge timing)."""

    def __init__(
        self,
        counts_per_rev: int = 4096,
        current_max_counts: int = 2000,
        fixed_rate_hz: int = 0,
        can: bool = True,
        edges=None,
    ):
        self.edges = edges
        self.arm, self.road, self.current_counts, self.hw_flags = 100, -7, 321, FLAG_HELD
        self.coil: list[tuple[int, int]] = []  # (time us, setpoint counts)
        self.road_speed: list[tuple[int, int]] = []
        self.now = 0
        self.out = StreamDecoder()
        self.sent: list[tuple[int, object]] = []
        self.can_frames: list[tuple[int, bytes]] = []  # what the board put on the bus, exactly
        self.can_out = CanDecoder()

        def read_encoders(_ctx, arm, road):
            arm[0], road[0] = self.arm, self.road

        def send(_ctx, data, n):
            self.sent += self.out.feed(bytes(data[:n]))

        def send_can(_ctx, can_id, data, n):
            self.can_frames.append((can_id, bytes(data[:n])))
            got = self.can_out.feed(can_id, bytes(data[:n]))
            if got is not None:
                self.sent.append(got)

        self._callbacks = (  # kept alive as long as the board
            firmware.ReadEncoders(read_encoders),
            firmware.ReadCurrent(lambda _ctx: self.current_counts),
            firmware.SetCoil(lambda _ctx, counts: self.coil.append((self.now, counts))),
            firmware.SetRoadSpeed(lambda _ctx, speed: self.road_speed.append((self.now, speed))),
            firmware.SensorFlags(lambda _ctx: self.hw_flags),
            firmware.Send(send),
            firmware.SendCan(send_can) if can else firmware.SendCan(),  # SendCan(): NULL, a HAL without CAN
        )
        if edges is not None:

            def read_edges(_ctx, arm, road):
                for (time_us, direction), out in zip(self.edges, (arm, road), strict=True):
                    out[0].time_us, out[0].dir = time_us, direction

            self._callbacks += (firmware.ReadEdges(read_edges),)
        self.hal = firmware.Hal(None, *self._callbacks)
        self.board = ctypes.create_string_buffer(LIB.sashil_board_size())
        LIB.sashil_board_init(self.board, ctypes.byref(self.hal), counts_per_rev, current_max_counts, fixed_rate_hz)
        self._seq = 0

    def use_can(self) -> Board:
        LIB.sashil_board_set_link(self.board, 1)
        return self

    def send_can(self, msg, at_us: int, seq: int = 0) -> list:
        """Deliver one host message as the DBC's CAN frames at ``at_us``; returns the board's replies."""
        self.now = at_us
        before = len(self.sent)
        for can_id, data in can_codec.encode(msg, seq):
            buf = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
            LIB.sashil_board_receive_can(self.board, can_id, buf, len(data), at_us)
        return [m for _, m in self.sent[before:]]

    def send_host(self, msg, at_us: int) -> list:
        """Deliver one host message at ``at_us``; returns what the board sent in reply."""
        self.now = at_us
        self._seq += 1
        frame = encode_frame(msg, self._seq)
        before = len(self.sent)
        LIB.sashil_board_receive(self.board, (ctypes.c_uint8 * len(frame)).from_buffer_copy(frame), len(frame), at_us)
        return [m for _, m in self.sent[before:]]

    def ticks(self, start_us: int, stop_us: int, step_us: int = MS, command=None) -> list:
        before = len(self.sent)
        for t in range(start_us, stop_us, step_us):
            if command is not None:
                self.send_host(command, t)
            self.now = t
            LIB.sashil_board_tick(self.board, t)
        return [m for _, m in self.sent[before:]]


def test_hello_and_configure_answer_as_the_protocol_says():
    b = Board()
    assert b.send_host(Hello(2), 0) == [Version(2, 4096, 1.0)]  # 2000 counts of 0.5 mA
    assert b.send_host(Configure(1000, 50, PACING_DEVICE), 0) == [Status(0, 0, 0, 0)]
    assert [s for s, _ in b.sent] == [1, 2]  # replies numbered in order
    fixed = Board(fixed_rate_hz=500)
    assert fixed.send_host(Configure(1000, 50, PACING_DEVICE), 0) == [Status(0, FAULT_BAD_CONFIGURE, 0, 0)]
    assert fixed.send_host(Configure(500, 0, PACING_DEVICE), 0) == [Status(0, FAULT_BAD_CONFIGURE, 0, 0)]


def test_device_pacing_sends_one_sample_per_period_with_the_rigs_readings():
    b = Board()
    assert b.ticks(0, 5 * MS) == []  # nothing before Configure
    b.send_host(Configure(1000, 50, PACING_DEVICE), 5 * MS)
    got = [m for m in b.ticks(5 * MS, 105 * MS, step_us=MS // 4) if isinstance(m, Sample)]
    assert len(got) == 100
    assert [s.device_time_us for s in got[:3]] == [5000, 6000, 7000]  # the clock from the board's boot
    assert got[0] == Sample(5000, 100, -7, 321 * 0.0005, FLAG_HELD)


def test_command_drives_the_coil_clamped_and_host_pacing_answers_with_a_sample():
    b = Board()
    b.send_host(Configure(1000, 50, PACING_HOST), 0)
    assert b.send_host(Command(0.8, CMD_ENABLE), MS) == [Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD)]
    assert b.coil[-1] == (MS, 1600)
    b.send_host(Command(5.0, CMD_ENABLE), 2 * MS)
    assert b.coil[-1] == (2 * MS, 2000)  # clamped to i_max
    b.send_host(Command(0.9, 0), 3 * MS)
    assert b.coil[-1] == (3 * MS, 0)  # no ENABLE bit: 0 A
    assert Board().send_host(Command(0.9, CMD_ENABLE), 0) == [] and Board().coil == []  # before Configure: nothing


def test_watchdog_rests_coil_and_road_at_its_time_and_the_next_command_clears_it():
    b = Board()
    b.send_host(Configure(1000, 50, PACING_DEVICE), 0)
    b.send_host(RoadSpeed(1.5), MS)
    b.ticks(MS, 20 * MS, command=Command(0.8, CMD_ENABLE))  # last command at 19 ms
    got = b.ticks(20 * MS, 100 * MS)
    assert b.coil[-1] == (69 * MS, 0) and b.road_speed[-1] == (69 * MS, 0)  # 19 + 50 ms
    statuses = [m for m in got if isinstance(m, Status)]
    assert statuses == [Status(FLAG_WATCHDOG, 0, 0, 1)]
    flagged = [s for s in got if isinstance(s, Sample) and s.flags & FLAG_WATCHDOG]
    assert flagged and flagged[0].device_time_us == 69 * MS
    got = b.ticks(100 * MS, 102 * MS, command=Command(0.3, CMD_ENABLE))
    assert not [s for s in got if isinstance(s, Sample)][-1].flags & FLAG_WATCHDOG and b.coil[-1][1] == 600


def test_garbage_from_the_host_is_counted_and_reported_never_drives_the_coil():
    b = Board()
    b.send_host(Configure(1000, 50, PACING_DEVICE), 0)
    junk = bytes(range(1, 200)) + b"\x00" + b"\x05\x01\x02\x00"
    LIB.sashil_board_receive(b.board, (ctypes.c_uint8 * len(junk)).from_buffer_copy(junk), len(junk), MS)
    assert b.coil == [(0, 0)]  # only Configure's 0 A
    status = b.send_host(Configure(1000, 50, PACING_DEVICE), 2 * MS)
    assert status[0].bad_frames == 2


def test_over_can_the_board_sends_exactly_the_frames_of_the_python_codec():
    b = Board().use_can()
    assert b.send_can(Hello(2), 0) == [Version(2, 4096, 1.0)]
    assert b.send_can(Configure(1000, 50, PACING_HOST), 0) == [Status(0, 0, 0, 0)]
    sample = b.send_can(Command(0.8, CMD_ENABLE), MS, seq=7)
    assert sample == [Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD)] and b.coil[-1] == (MS, 1600)
    expected = [
        *can_codec.encode(Version(2, 4096, 1.0)),
        *can_codec.encode(Status(0, 0, 0, 0)),
        *can_codec.encode(Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD), seq=1),
    ]
    assert b.can_frames == expected  # ids, lengths and bytes (the sample split in A, edges, B)
    assert b.can_frames[-3:] == [
        (0x110, bytes.fromhex("64000000f9ffffff")),  # arm 100, road -7
        (0x112, bytes.fromhex("ffffffff00")),  # no edge timing in this hardware: both ages say none
        (0x111, bytes.fromhex("0100e80300410102")),  # seq 1, 1000 us, 321 counts, flags 0x02 (held)
    ]


def test_edge_ages_are_the_sample_time_minus_the_capture_time_saturated_and_wrapping():
    b = Board(edges=((700, 1), (0, 0)))  # arm: an edge at 700 us, count up; road: none since boot
    b.send_host(Hello(2), 0)
    b.send_host(Configure(1000, 50, PACING_HOST), 0)
    assert b.send_host(Command(0.0, 0), MS) == [Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD, 300, 1)]
    b.edges = ((999, -1), (1000, 1))  # arm down 1 us before the sample, road up at the sample
    assert b.send_host(Command(0.0, 0), MS) == [Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD, 1, -1, 0, 1)]
    b.edges = ((1001, 1), (1000 - 65534, -1))  # arm stamped while the sample was taken: age 0
    assert b.send_host(Command(0.0, 0), MS) == [Sample(1000, 100, -7, 321 * 0.0005, FLAG_HELD, 0, 1, 65534, -1)]
    b.edges = ((1000 - 65535, 1), (0, 1))  # 65.535 ms old: as none
    got = b.send_host(Command(0.0, 0), 70 * MS)
    assert got == [Sample(70_000, 100, -7, 321 * 0.0005, FLAG_HELD, 65535, 0, 65535, 0)]
    # the capture clock is 32 bits: an edge just before its wrap, the sample just after
    b.edges = ((2**32 - 10, 1), (0, 0))
    now = 2**32 + 5
    frame = encode_frame(Command(0.0, 0), 99)
    before = len(b.sent)
    LIB.sashil_board_receive(b.board, (ctypes.c_uint8 * len(frame)).from_buffer_copy(frame), len(frame), now)
    sample = b.sent[before:][0][1]
    assert (sample.arm_edge_age_us, sample.arm_edge_dir, sample.road_edge_age_us) == (15, 1, 65535)


def test_over_can_the_device_clock_wraps_at_24_bits_and_road_speed_and_watchdog_act():
    b = Board().use_can()
    b.send_can(Configure(1000, 50, PACING_DEVICE), 0)
    b.send_can(RoadSpeed(-1.25), MS)
    assert b.road_speed[-1] == (MS, -1_250_000)
    LIB.sashil_board_tick(b.board, (1 << 24) + 5)  # past the 24-bit device time of SampleB
    assert b.can_frames[-1][0] == 0x111 and b.can_frames[-1][1][2:5] == bytes([5, 0, 0])


def test_a_can_frame_of_the_wrong_length_is_counted_and_ignored_others_ids_too():
    b = Board().use_can()
    b.send_can(Configure(1000, 50, PACING_HOST), 0)
    short = (ctypes.c_uint8 * 3)(1, 2, 3)
    LIB.sashil_board_receive_can(b.board, 0x100, short, 3, MS)  # a Command of 3 bytes
    LIB.sashil_board_receive_can(b.board, 0x7FF, short, 3, MS)  # another node's frame: not ours
    LIB.sashil_board_receive_can(b.board, 0x111, short, 3, MS)  # the board's own id: ignored
    assert b.coil == [(0, 0)] and LIB.sashil_board_bad_frames(b.board) == 1
    assert b.send_can(Configure(1000, 50, PACING_HOST), 2 * MS) == [Status(0, 0, 1, 0)]


def test_next_event_is_the_due_sample_or_the_watchdog_deadline_and_sessions_count():
    b = Board()
    assert LIB.sashil_board_next_event_us(b.board) == (1 << 64) - 1  # nothing to do before Configure
    b.send_host(Configure(500, 50, PACING_DEVICE), 10 * MS)
    assert LIB.sashil_board_next_event_us(b.board) == 10 * MS and LIB.sashil_board_sessions(b.board) == 1
    b.ticks(10 * MS, 11 * MS)
    assert LIB.sashil_board_next_event_us(b.board) == 12 * MS  # 500 Hz
    host = Board()
    host.send_host(Configure(1000, 20, PACING_HOST), 0)
    host.send_host(Command(0.1, CMD_ENABLE), 3 * MS)
    assert LIB.sashil_board_next_event_us(host.board) == 23 * MS  # only the watchdog, 20 ms on
    host.send_host(Configure(1000, 20, PACING_HOST), 4 * MS)
    assert LIB.sashil_board_sessions(host.board) == 2


def test_device_pacing_at_3_khz_holds_the_exact_period_over_10_s_of_device_time():
    """1e6/3000 is 333 1/3 us: the board carries the third, so sample k is due at floor(k * 1e6/3000) us
    after Configure, never a whole sample ahead or behind (a 333 us period would gain 30 samples)."""
    b = Board()
    sent = []
    b.out.feed = lambda data: sent.append(len(data)) or []  # count frames only: 30 000 of them
    b.send_host(Configure(3000, 50, PACING_DEVICE), 7)
    start, now, due = 7, 7, []
    while now < start + 10_000_000:
        due.append(now - start)
        LIB.sashil_board_tick(b.board, now)
        now = LIB.sashil_board_next_event_us(b.board)
    assert len(sent) == 1 + 30_000  # Configure's Status and one sample per period
    assert due == [k * 1_000_000 // 3000 for k in range(30_000)]
    assert now == start + 10_000_000 and LIB.sashil_board_overruns(b.board) == 0


def test_a_can_session_on_a_board_without_send_can_is_refused_and_never_acted_on():
    b = Board(can=False).use_can()
    refused = b.send_can(Configure(1000, 50, PACING_HOST), 0)
    assert refused == [Status(0, FAULT_NO_CAN, 0, 0)]  # the refusal goes out on the serial transmitter
    assert b.send_can(Command(0.8, CMD_ENABLE), MS, seq=1) == [] and b.coil == []  # no session: no drive
    assert b.ticks(MS, 100 * MS) == [] and LIB.sashil_board_refusals(b.board) == 1
    assert LIB.sashil_board_sessions(b.board) == 0
    assert b.send_can(Hello(PROTOCOL_VERSION), 100 * MS) == [Version(PROTOCOL_VERSION, 4096, 1.0)]  # never calls NULL


def test_a_refused_configure_leaves_the_running_session_as_it_was_and_is_counted():
    b = Board()
    b.send_host(Configure(1000, 50, PACING_HOST), 0)
    b.send_host(Command(0.5, CMD_ENABLE), MS)
    assert b.send_host(Configure(30000, 50, PACING_HOST), 2 * MS) == [Status(0, FAULT_BAD_CONFIGURE, 0, 0)]
    assert b.coil[-1] == (MS, 1000) and LIB.sashil_board_refusals(b.board) == 1
    assert isinstance(b.send_host(Command(0.5, CMD_ENABLE), 3 * MS)[0], Sample)  # still host-paced at 1 kHz


def test_the_hardware_layers_status_flags_go_out_in_every_status():
    b = Board()
    LIB.sashil_board_set_status_flags(b.board, STATUS_CLOCK_FALLBACK)
    assert b.send_host(Configure(1000, 50, PACING_HOST), 0) == [Status(STATUS_CLOCK_FALLBACK, 0, 0, 0)]
    b.send_host(Command(0.5, CMD_ENABLE), MS)
    trip = [m for m in b.ticks(2 * MS, 60 * MS) if isinstance(m, Status)]
    assert trip == [Status(STATUS_CLOCK_FALLBACK | FLAG_WATCHDOG, 0, 0, 1)]
    assert not [m for m in b.sent if isinstance(m[1], Sample) and m[1].flags & STATUS_CLOCK_FALLBACK]


def test_configure_takes_its_range_to_the_edges_and_refuses_one_past_them():
    for rate, watchdog in ((1, 1), (20000, 1), (1000, 65535)):
        assert Board().send_host(Configure(rate, watchdog, PACING_HOST), 0) == [Status(0, 0, 0, 0)], (rate, watchdog)
    for rate, watchdog, pacing in ((0, 50, PACING_HOST), (20001, 50, PACING_HOST), (1000, 0, PACING_HOST)):
        b = Board()
        assert b.send_host(Configure(rate, watchdog, pacing), 0) == [Status(0, FAULT_BAD_CONFIGURE, 0, 0)]
        assert b.send_host(Command(0.5, CMD_ENABLE), MS) == [] and b.coil == []  # never acted on


def test_a_rate_above_what_the_link_carries_is_refused_and_never_acted_on():
    b = Board()
    LIB.sashil_board_set_max_rate(b.board, 4000)
    assert b.send_host(Configure(4001, 50, PACING_DEVICE), 0) == [Status(0, FAULT_BAD_CONFIGURE, 0, 0)]
    assert b.ticks(0, 10 * MS) == [] and LIB.sashil_board_refusals(b.board) == 1  # no samples streamed
    assert b.send_host(Configure(4000, 50, PACING_DEVICE), 10 * MS) == [Status(0, 0, 0, 0)]  # the limit itself
    LIB.sashil_board_set_max_rate(b.board, 1)
    assert b.send_host(Configure(2, 50, PACING_HOST), 10 * MS)[0].fault_code == FAULT_BAD_CONFIGURE
    LIB.sashil_board_set_max_rate(b.board, 0)  # out of range: the protocol's 20 kHz
    assert b.send_host(Configure(20000, 50, PACING_HOST), 11 * MS) == [Status(0, 0, 0, 0)]

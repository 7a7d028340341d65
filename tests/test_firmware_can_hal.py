"""The CAN hardware layer's frame packing (``cortex-m4/bxcan_frame.c``), built for the host: the bxCAN
mailbox words of every frame the board sends, the frames it takes off the bus, and the filter that
passes exactly the host's ids of ``sashil.dbc`` (RM0090 32.9.3 and 32.7.4 for the register layouts)."""

from __future__ import annotations

import ctypes
import subprocess

import pytest

from sashil.drivers import can_codec, firmware
from sashil.drivers.messages import PROTOCOL_VERSION, Sample, Status, Version

CORTEX_M4 = firmware.HERE / "cortex-m4"


class Mailbox(ctypes.Structure):
    _fields_ = [
        ("tir", ctypes.c_uint32),
        ("tdtr", ctypes.c_uint32),
        ("tdlr", ctypes.c_uint32),
        ("tdhr", ctypes.c_uint32),
    ]


@pytest.fixture(scope="module")
def lib(tmp_path_factory) -> ctypes.CDLL:
    cc = firmware.compiler()
    if cc is None:
        pytest.skip("no C compiler on this machine")
    out = tmp_path_factory.mktemp("bxcan") / "libbxcan.so"
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-fPIC", "-shared"]
    subprocess.run([cc, *flags, "-o", str(out), str(CORTEX_M4 / "bxcan_frame.c")], check=True, capture_output=True)
    lib = ctypes.CDLL(str(out))
    u8p = ctypes.POINTER(ctypes.c_uint8)
    lib.bxcan_pack.argtypes = (ctypes.c_uint16, u8p, ctypes.c_uint8, ctypes.POINTER(Mailbox))
    lib.bxcan_pack.restype = ctypes.c_int
    lib.bxcan_unpack.argtypes = (
        *(ctypes.c_uint32,) * 4,
        ctypes.POINTER(ctypes.c_uint16),
        u8p,
        u8p,
    )
    lib.bxcan_unpack.restype = ctypes.c_int
    lib.bxcan_filter_list16.argtypes = (ctypes.POINTER(ctypes.c_uint16), *(ctypes.POINTER(ctypes.c_uint32),) * 2)
    lib.bxcan_filter_list16.restype = None
    return lib


def pack(lib: ctypes.CDLL, can_id: int, data: bytes) -> Mailbox | None:
    box = Mailbox()
    buf = (ctypes.c_uint8 * max(len(data), 1)).from_buffer_copy(data.ljust(1, b"\0"))
    return box if lib.bxcan_pack(can_id, buf, len(data), ctypes.byref(box)) else None


def unpack(lib: ctypes.CDLL, rir: int, rdtr: int, rdlr: int, rdhr: int) -> tuple[int, bytes] | None:
    can_id, data, length = ctypes.c_uint16(), (ctypes.c_uint8 * 8)(), ctypes.c_uint8()
    if not lib.bxcan_unpack(rir, rdtr, rdlr, rdhr, ctypes.byref(can_id), data, ctypes.byref(length)):
        return None
    return can_id.value, bytes(data[: length.value])


def test_a_mailbox_holds_the_id_the_length_and_the_bytes_as_rm0090_lays_them_out(lib):
    box = pack(lib, 0x1F0, bytes(range(1, 9)))
    assert box is not None
    assert box.tir == (0x1F0 << 21) | 1  # STID in bits 31:21, IDE = RTR = 0, TXRQ
    assert (box.tdtr, box.tdlr, box.tdhr) == (8, 0x04030201, 0x08070605)  # byte 0 in the low bits
    short = pack(lib, 0x180, b"\xaa\xbb\xcc")
    assert short is not None and (short.tdtr, short.tdlr, short.tdhr) == (3, 0x00CCBBAA, 0)


def test_every_frame_the_board_sends_goes_out_and_comes_back_unchanged(lib):
    frames = [
        *can_codec.encode(Sample(123456, -100, 7, 0.25, 0x03), seq=9),  # SampleA, SampleEdges, SampleB
        *can_codec.encode(Status(0x11, 3, 2, 1)),
        *can_codec.encode(Version(PROTOCOL_VERSION, 4096, 2.0)),
    ]
    assert [f[0] for f in frames] == [0x110, 0x112, 0x111, 0x180, 0x1F2]
    for can_id, data in frames:
        box = pack(lib, can_id, data)
        assert box is not None and box.tdtr == len(data)
        # what a receiving bxCAN shows: the same id bits (TXRQ's bit 0 is reserved in RIR), DLC, data
        assert unpack(lib, box.tir & ~1, box.tdtr, box.tdlr, box.tdhr) == (can_id, data)


def test_frames_no_controller_could_send_are_refused(lib):
    assert pack(lib, 0x800, b"\x01") is None  # more than 11 bits
    assert pack(lib, 0x100, bytes(9)) is None  # more than 8 bytes
    assert pack(lib, 0x7FF, b"") is not None  # the largest id, no data


def test_extended_and_remote_frames_are_not_taken_and_a_long_dlc_reads_8_bytes(lib):
    assert unpack(lib, (0x100 << 21) | 0x4, 5, 0, 0) is None  # IDE: an extended id, not the DBC's
    assert unpack(lib, (0x100 << 21) | 0x2, 5, 0, 0) is None  # RTR: a remote frame
    assert unpack(lib, 0x1F1 << 21, 15, 0x04030201, 0x08070605) == (0x1F1, bytes(range(1, 9)))


def test_the_filter_passes_exactly_the_host_ids_of_the_dbc(lib):
    db = can_codec.database()
    host_ids = sorted(m.frame_id for m in db.messages if "HOST" in m.senders)
    assert host_ids == sorted(can_codec.HOST_IDS) == [0x100, 0x120, 0x1F0, 0x1F1]
    source = (CORTEX_M4 / "hal_can_stm32f4.c").read_text()
    assert "host_ids[4] = {0x100u, 0x120u, 0x1F0u, 0x1F1u}" in source  # the HAL's list is the DBC's
    ids = (ctypes.c_uint16 * 4)(*host_ids)
    fr1, fr2 = ctypes.c_uint32(), ctypes.c_uint32()
    lib.bxcan_filter_list16(ids, ctypes.byref(fr1), ctypes.byref(fr2))
    slots = [fr1.value & 0xFFFF, fr1.value >> 16, fr2.value & 0xFFFF, fr2.value >> 16]
    assert all(slot & 0x1F == 0 for slot in slots)  # RTR = 0, IDE = 0, EXID = 0: standard data frames
    assert sorted(slot >> 5 for slot in slots) == host_ids

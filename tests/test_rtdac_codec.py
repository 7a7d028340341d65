"""The RT-DAC/USB2's frames, byte for byte, and its register maps.

Each fact is cited from is-centre/rtdacusb2-bridge-app,
``RTDACUSB2-Windows-UDP-Bridge_app/RTDACUSB2_Basic/<file>``, at the line that states it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sashil.drivers import rtdac_codec as codec
from sashil.drivers.rtdac_map import choose_map, known_maps, load_map
from sashil.errors import ConfigError, DriverError


def test_the_read_request_is_ff_8f_00_00_on_endpoint_2():
    # RTDACUSB2.cs lines 153-158: pByteBuffer[0..3] = FF 8F 00 00, XferData on eptFPGAOut (address 2, line 74)
    assert codec.READ_REQUEST == b"\xff\x8f\x00\x00"
    assert codec.ENDPOINT_OUT == 0x02
    # RTDACUSB2.cs lines 76-77, 160-161: 504 bytes read from eptFPGAIn (address 4; an IN endpoint)
    assert codec.ENDPOINT_IN & 0x7F == 4 and codec.ENDPOINT_IN & 0x80
    assert codec.FRAME_BYTES == 504


def test_a_write_frame_begins_0f_8f_and_masks_each_later_high_byte_to_7_bits():
    words = [0] * 252
    words[0] = 0xFFFF  # replaced by the mark (RTDACUSB2.cs lines 172-173)
    words[1] = 0x1234
    words[2] = 0xABCD  # high byte 0xAB & 0x7F = 0x2B (RTDACUSB2.cs line 177)
    words[251] = 0xFFFF
    frame = codec.encode_write(words)
    assert len(frame) == 504
    assert frame[:6] == bytes.fromhex("0f8f3412cd2b")
    assert frame[-2:] == bytes.fromhex("ff7f")
    assert frame[6:-2] == bytes(504 - 8)


def test_a_read_frame_is_252_little_endian_words():
    # RTDACUSB2.cs lines 163-164: word i = 256 * byte[2i+1] + byte[2i]
    data = bytes(range(256)) + bytes(range(248))
    words = codec.decode_frame(data)
    assert len(words) == 252
    assert words[0] == 0x0100 and words[1] == 0x0302 and words[127] == 0xFFFE
    with pytest.raises(ValueError, match="a frame of 502 bytes, expected 504"):
        codec.decode_frame(data[:-2])


def test_the_header_reads_name_date_and_module_counts():
    # RTDACUSB2_0103.cs lines 33-57: the name is word 3 high, low, word 2 high, low, word 1 high, low
    words = [0x0103, ord("I") << 8 | ord("G"), ord("S") << 8 | ord("R"), ord("S") << 8 | ord("A"), 0x1128, 0x2026]
    words += [0x0808 | (0 << 4), 0x8020, 0x0008]
    header = codec.decode_header(words)
    assert header.logic == "0103"
    assert header.application == "SASRIG"
    assert header.synthesis_date == "2026-11-28"
    assert header.modules["pwm"] == 8 and header.modules["encoder_i"] == 8
    assert header.modules["timer_counter"] == 2 and header.modules["frequency_meter"] == 8
    assert header.modules["chronometer"] == 8
    assert codec.encode_header(0x0103, "SASRIG", "2026-11-28", header.modules) == words


def test_converters_as_the_public_board_class_scales_them():
    # RTDACBoard.cs lines 850-852: 12-bit two's complement, 10 V * v / 2048 / gain
    assert codec.ad_volts(0x7FF) == pytest.approx(10 * 2047 / 2048)
    assert codec.ad_volts(0x800) == -10.0
    assert codec.ad_volts(0x400, gain_code=1) == pytest.approx(2.5)  # gain x2 (line 811)
    assert codec.ad_volts(0x1400) == pytest.approx(5.0)  # the busy bit (bit 12) is not part of the value
    assert codec.ad_word(5.0) == 0x400 and codec.ad_word(-10.0) == 0x800
    assert codec.ad_word(20.0) == 0x7FF  # clipped to the converter's range
    assert codec.ad_word(0.0, busy=True) == codec.AD_BUSY_BIT
    # RTDACBoard.cs lines 800-805: -10 V + 20 V * v / 16383; written as (uint)(16383 * (10 + V) / 20)
    assert codec.da_word(0.0) == 8191 == codec.DA_ZERO
    assert codec.da_word(10.0) == 16383 and codec.da_word(-10.0) == 0 and codec.da_word(99.0) == 16383
    assert codec.da_volts(16383) == 10.0
    # RTDACBoard.cs lines 127-133: 12 bits wide in 12-bit mode, 8 in 8-bit mode
    assert codec.pwm_width(1.0) == 0x0FFF and codec.pwm_width(1.0, "8-bit") == 0xFF
    assert codec.pwm_width(0.5) == 2048 and codec.pwm_width(-1.0) == 0 and codec.pwm_width(float("nan")) == 0


def test_a_counter_is_32_bits_low_word_first_and_signed():
    # RTDACUSB2_0103.cs line 76: (word 54+2i << 16) | word 53+2i
    assert codec.counter32(0x0002, 0x0001) == 0x0001_0002
    assert codec.counter32(0xFFFF, 0xFFFF) == -1


def test_the_two_public_maps_share_header_pwm_and_encoders_and_move_the_converters():
    maps = {m.logic: m for m in known_maps()}
    old, new = maps["0103"], maps["0111"]
    # RTDACUSB2_0103.cs lines 66-68 and 76; RTDACUSB2_111.cs lines 62-64 and 72
    for m in (old, new):
        assert (m.pwm_prescaler_word(1), m.pwm_mode_word(1), m.pwm_width_word(1)) == (23, 24, 25)
        assert m.counter_words(2) == (57, 58) and m.encoder_reset == 50
    # RTDACUSB2_0103.cs lines 120, 138, 146; RTDACUSB2_111.cs lines 115, 133, 141
    assert (old.ad_gain_base, old.ad_value_word(3), old.da_word(1)) == (200, 207, 221)
    assert (new.ad_gain_base, new.ad_value_word(3), new.da_word(1)) == (190, 197, 211)
    assert old.ad_gain_word(5) == (201, 4)


def test_an_unknown_logic_is_refused_in_one_line_naming_what_was_read_and_how_to_add_a_map():
    header = codec.decode_header(codec.encode_header(0x0200, "SASRIG", "2026-01-02", {"pwm": 8}))
    with pytest.raises(DriverError) as err:
        choose_map(header, known_maps())
    text = str(err.value)
    assert "\n" not in text
    assert "logic 0200 with application 'SASRIG'" in text
    assert "logic 0103" in text and "logic 0111" in text
    assert "rtdac.map_dir" in text


def test_a_labs_own_map_file_serves_its_logic_and_application(tmp_path: Path):
    text = (Path(codec.__file__).with_name("rtdac_maps") / "0103.yaml").read_text()
    (tmp_path / "0200.yaml").write_text(
        text.replace("logic_version: 0x0103", "logic_version: 0x0200").replace(
            "applications: null", "applications: [SASRIG]"
        )
    )
    maps = known_maps(str(tmp_path))
    ours = codec.decode_header(codec.encode_header(0x0200, "SASRIG", "2026-01-02", {}))
    assert choose_map(ours, maps).source == "0200.yaml"
    other = codec.decode_header(codec.encode_header(0x0200, "OTHER", "2026-01-02", {}))
    with pytest.raises(DriverError, match="application 'OTHER'"):
        choose_map(other, maps)


def test_a_bad_map_file_is_one_line_naming_file_and_key(tmp_path: Path):
    bad = tmp_path / "bad.yaml"
    text = (Path(codec.__file__).with_name("rtdac_maps") / "0103.yaml").read_text()
    bad.write_text(text.replace("value_base: 204", "value_base: 300"))
    with pytest.raises(ConfigError, match=r"bad.yaml: ad.value_base: expected an integer from 0 to 251, got 300"):
        load_map(bad)
    bad.write_text(text.replace("pwm:", "pwn:"))
    with pytest.raises(ConfigError, match=r"bad.yaml: pwn: unknown key"):
        load_map(bad)
    with pytest.raises(ConfigError, match=r"rtdac.map_dir: .* is not a folder"):
        known_maps(str(tmp_path / "nowhere"))

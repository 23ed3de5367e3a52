"""The Python face of the C core: argument checking, error messages, buffers, counters."""

from __future__ import annotations

import math
from array import array

import pytest

from _scales import MIT_V43
from servobus import Frame, ProtocolError, ServobusError
from servobus.core import (
    HOLLOW_EXT_REPLY,
    HOLLOW_FD_COMMAND,
    LAYOUTS,
    MIT_COMMAND,
    MIT_REPLY,
    FieldScale,
    HollowTransparentDeframer,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
    Packer,
    crc16_modbus,
    crc32_ieee,
)

# ---- CRC inputs ----


def test_crc_accepts_every_contiguous_buffer() -> None:
    data = b"\x3e\x01\x08\x9c" + bytes(7)
    expected16, expected32 = crc16_modbus(data), crc32_ieee(data)
    for form in (bytearray(data), memoryview(data), array("B", data)):
        assert crc16_modbus(form) == expected16
        assert crc32_ieee(form) == expected32


def test_crc_chains() -> None:
    a, b = b"hello ", b"world"
    assert crc16_modbus(b, crc16_modbus(a)) == crc16_modbus(a + b)
    assert crc32_ieee(b, crc32_ieee(a)) == crc32_ieee(a + b)
    assert crc16_modbus(b"") == 0xFFFF and crc32_ieee(b"") == 0


def test_crc_rejects_non_buffers() -> None:
    with pytest.raises(TypeError):
        crc16_modbus("text")  # type: ignore[arg-type]


# ---- FieldScale ----


def test_field_scale_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match=r"'speed'.*lo=2\.0 exceeds hi=1\.0"):
        FieldScale(name="speed", lo=2.0, hi=1.0)
    with pytest.raises(ValueError, match=r"'speed'.*finite"):
        FieldScale(name="speed", lo=0.0, hi=math.inf)
    with pytest.raises(ValueError, match="positive"):
        FieldScale(name="speed", lo=0.0, hi=1.0, codes=0)


def test_scale_must_fit_its_field() -> None:
    """A range that maps past the field's bits would saturate good values silently: refused."""
    too_wide = FieldScale(name="kp", lo=0, hi=5000)
    with pytest.raises(ValueError, match=r"kp range \[0, 5000\] maps to codes 0..5000, beyond the 12-bit"):
        Packer(MIT_COMMAND, [MIT_V43[0], MIT_V43[1], too_wide, MIT_V43[3], MIT_V43[4]])
    too_high = FieldScale(name="p", lo=-0.5, hi=65536.6)  # 1.6 codes past the top: refused
    with pytest.raises(ValueError, match=r"maps to codes -0\.5\.\.65536\.6"):
        Packer(MIT_COMMAND, [too_high, *MIT_V43[1:]])
    Packer(MIT_COMMAND, [FieldScale(name="p", lo=-0.5, hi=65536.5), *MIT_V43[1:]])  # the slack itself
    huge = FieldScale(name="p", lo=-1e308, hi=1e308, codes=4.0)
    with pytest.raises(ValueError, match="overflows its codes"):
        Packer(MIT_COMMAND, [huge, *MIT_V43[1:]])
    with pytest.raises(ValueError, match="has 5 fields, got 4 scales"):
        Packer(MIT_COMMAND, MIT_V43[:4])
    with pytest.raises(ValueError, match="stride 4 is smaller"):
        Packer(MIT_COMMAND, MIT_V43, stride=4)


# ---- packing errors: ValueError naming field, value and limit, before anything is returned ----


def test_out_of_range_names_field_value_and_limits() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(ValueError, match=r"^velocity_rad_s=45\.5 is outside \[-45\.0, 45\.0\]$"):
        packer.pack([0.0, 45.5, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"^kd is NaN$"):
        packer.pack([0.0, 0.0, 0.0, math.nan, 0.0])
    with pytest.raises(ValueError, match=r"torque_ff_nm=-inf is outside .* \(frame 2\)"):
        packer.pack_many([[0.0] * 5, [0.0] * 5, [0.0, 0.0, 0.0, 0.0, -math.inf]])


def test_saturate_clamps_but_never_accepts_nan() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    assert packer.pack([99.0, -99.0, 1e9, -1.0, math.inf], saturate=True) == packer.pack(
        [12.5, -45.0, 500.0, 0.0, 24.0]
    )
    with pytest.raises(ValueError, match="NaN"):
        packer.pack([math.nan, 0.0, 0.0, 0.0, 0.0], saturate=True)


def test_wrong_row_lengths() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(ValueError, match="takes 5 values, got 4"):
        packer.pack([0.0] * 4)
    with pytest.raises(ValueError, match="row 1 has 6 values"):
        packer.pack_many([[0.0] * 5, [0.0] * 6])
    with pytest.raises(ValueError, match="not a whole number of 5-field rows"):
        packer.pack_many(array("d", [0.0] * 7))


# ---- batches and buffers ----


def test_batch_forms_agree_with_single_frames() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    rows = [[i / 10, -i / 5, i * 3.0, i / 50, -i / 7] for i in range(40)]
    singles = b"".join(packer.pack(r) for r in rows)
    assert packer.pack_many(rows) == singles
    flat = array("d", [x for r in rows for x in r])
    assert packer.pack_many(flat) == singles
    out = bytearray(len(singles))
    assert packer.pack_into(flat, out) == 40 and bytes(out) == singles
    decoded = array("d", bytes(8 * 5 * 40))
    assert packer.unpack_into(singles, decoded) == 40
    assert [tuple(decoded[i : i + 5]) for i in range(0, 200, 5)] == packer.unpack_many(singles)
    assert packer.unpack_many(singles)[7] == packer.unpack(singles[56:64])


def test_buffers_are_checked() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(TypeError, match="float64"):
        packer.pack_into(array("f", [0.0] * 5), bytearray(8))
    with pytest.raises(ValueError, match="out holds 7 bytes"):
        packer.pack_into(array("d", [0.0] * 5), bytearray(7))
    with pytest.raises(TypeError):
        packer.pack_into(array("d", [0.0] * 5), b"\x00" * 8)  # read-only out
    with pytest.raises(ValueError, match="out holds 4 values"):
        packer.unpack_into(bytes(8), array("d", [0.0] * 4))


def test_stride_pads_with_zeros() -> None:
    """MyActuator's motion reply is the 6-byte MIT_V43 reply in an 8-byte frame, DATA[6..7] NULL."""
    scales = [FieldScale.integer("motor_id", 0, 255), MIT_V43[0], MIT_V43[1], MIT_V43[4]]
    packer = Packer(MIT_REPLY, scales, stride=8)
    frames = packer.pack_many([[1, 10.0, 1.0, 10.0], [2, -1.0, 0.0, 0.0]])
    assert len(frames) == 16 and frames[6:8] == b"\x00\x00" and frames[14:16] == b"\x00\x00"


def test_short_frames_raise_protocol_error_with_hex() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(ProtocolError, match=r"MIT_COMMAND needs 8 bytes, got 3 \(raw E6 66 82\)") as info:
        packer.unpack(b"\xe6\x66\x82")
    assert isinstance(info.value, ServobusError) and info.value.raw == b"\xe6\x66\x82"
    with pytest.raises(ProtocolError, match="not a whole number of 8-byte"):
        packer.unpack_many(bytes(12))


def test_extended_reply_position_is_signed_32_bit() -> None:
    """hollow.md §5.3 illustrative frames: +1/2 turn and X = -1."""
    scales = [
        FieldScale.integer("motor_id", 0, 255),
        FieldScale.twos_complement("x_counts", 32),
        FieldScale.offset_binary("speed_rad_s", 200.0, 12),
        FieldScale.offset_binary("current_a", 4.0, 12),
    ]
    packer = Packer(HOLLOW_EXT_REPLY, scales)
    assert packer.pack([1, 0x80000, 0.0, 0.0]) == bytes.fromhex("01 00 00 80 08 00 00 08")
    assert packer.pack([1, -1, 0.0, 0.0]) == bytes.fromhex("01 FF FF 80 08 00 FF FF")
    assert packer.unpack(bytes.fromhex("01 FF FF 80 08 00 FF FF")) == (1, -1, 0.0, 0.0)


def test_fd_position_limits_are_the_40_bit_range() -> None:
    scales = [
        FieldScale.twos_complement("position_counts", 40),
        *[FieldScale.integer(f"f{i}", 0, 1) for i in range(7)],
    ]
    packer = Packer(HOLLOW_FD_COMMAND, scales)
    assert packer.pack([2**39 - 1] + [0] * 7)[:5] == bytes.fromhex("7F FF FF FF FF")
    with pytest.raises(
        ValueError, match=r"position_counts=549755813888\.0 is outside \[-549755813888\.0, 549755813887\.0\]"
    ):
        packer.pack([2**39] + [0] * 7)


def test_layouts_table() -> None:
    assert [(layout.name, layout.size) for layout in LAYOUTS] == [
        ("MIT_COMMAND", 8),
        ("HOLLOW_SETPOINT", 8),
        ("MIT_REPLY", 6),
        ("HOLLOW_EXT_REPLY", 8),
        ("HOLLOW_FD_COMMAND", 16),
        ("HOLLOW_FD_REPLY", 16),
    ]
    assert MIT_COMMAND.bits == (16, 12, 12, 12, 12)
    assert HOLLOW_FD_COMMAND.bits == (-40, -32, -16, 8, 8, 8, 8, 8)


# ---- de-framers ----


def _rs485(motor: int, data: bytes) -> bytes:
    body = bytes([0x3E, motor, len(data)]) + data
    return body + crc16_modbus(body).to_bytes(2, "little")


def test_deframer_options_are_checked() -> None:
    with pytest.raises(ValueError, match=r"max_data_len=0 is outside \[1, 255\]"):
        MyActuatorRs485Deframer(0)
    with pytest.raises(ValueError, match="direction='sideways'"):
        ModbusRtuDeframer("sideways")  # type: ignore[arg-type]


def test_rs485_counts_noise_and_crc_errors() -> None:
    good = _rs485(1, bytes.fromhex("9C 00 00 00 00 00 00 00"))
    bad = bytearray(_rs485(2, bytes(8)))
    bad[5] ^= 0x01
    deframer = MyActuatorRs485Deframer()
    assert deframer.feed(good + bytes(bad) + b"\x00\x00" + good + good[:4]) == [good, good]
    assert (deframer.frames, deframer.crc_errors, deframer.discarded_bytes, deframer.pending) == (2, 1, 15, 4)
    deframer.clear()
    assert (deframer.pending, deframer.discarded_bytes) == (0, 19)
    assert deframer.feed(good) == [good]


def test_rs485_longer_frames_when_allowed() -> None:
    frame = _rs485(1, bytes(range(20)))
    assert MyActuatorRs485Deframer().feed(frame) == []
    assert MyActuatorRs485Deframer(max_data_len=64).feed(frame) == [frame]


def test_deframer_large_input_and_feed_into() -> None:
    frame = _rs485(3, bytes.fromhex("A2 00 00 00 10 27 00 00"))
    stream = frame * 20000  # 260 kB: several internal slices
    deframer = MyActuatorRs485Deframer()
    assert deframer.feed(stream) == [frame] * 20000
    raw = MyActuatorRs485Deframer()
    out, lens = bytearray(13 * 100), array("H", [0] * 100)
    n, consumed = raw.feed_into(stream[:1000], out, lens)
    assert n == 76 and consumed == 1000 and bytes(out[:13]) == frame and list(lens[:n]) == [13] * n
    with pytest.raises(TypeError, match="uint16"):
        raw.feed_into(stream, out, array("I", [0] * 4))


def test_feed_into_refuses_buffers_that_cannot_progress_and_empty_feed_drains() -> None:
    frame = _rs485(3, bytes.fromhex("A2 00 00 00 10 27 00 00"))
    deframer = MyActuatorRs485Deframer()
    with pytest.raises(ValueError, match="out needs at least 13 bytes"):
        deframer.feed_into(frame, bytearray(12), array("H", [0]))
    with pytest.raises(ValueError, match="lens at least one slot"):
        deframer.feed_into(frame, bytearray(13), array("H"))
    # Room for one frame per call: the second frame stays buffered, and an empty feed returns it.
    assert deframer.feed_into(frame * 2, bytearray(13), array("H", [0])) == (1, 26)
    assert deframer.pending == 13
    assert deframer.feed(b"") == [frame]


def test_idle_releases_a_frame_held_behind_a_stray_byte() -> None:
    """``55 03 ...`` reads as the start of a 0x03 reply with byte count 0x10 and waits for 21 bytes;
    when the line goes quiet (Modbus: 3.5 characters), the stray byte is dropped and the real
    frame behind it, a write reply from slave 3, comes out."""
    body = bytes([0x03, 0x10, 0x00, 0x00, 0x00, 0x10])
    frame = body + crc16_modbus(body).to_bytes(2, "little")
    deframer = ModbusRtuDeframer("replies")
    assert deframer.feed(b"\x55" + frame) == []
    assert deframer.idle() == [frame]
    assert (deframer.discarded_bytes, deframer.pending) == (1, 0)
    partial = MyActuatorRs485Deframer()
    assert partial.feed(b"\x3e\x01\x08\x9c") == [] and partial.idle() == []
    assert (partial.discarded_bytes, partial.pending) == (4, 0)


def test_transparent_resynchronises_after_a_lost_byte() -> None:
    payload = bytes([1]) + bytes(16)
    frame = payload + crc32_ieee(payload).to_bytes(4, "little")
    deframer = HollowTransparentDeframer()
    assert deframer.feed(frame[:10] + frame[11:] + frame + frame) == [frame, frame]
    assert deframer.crc_errors == 1 and deframer.discarded_bytes == 20


def test_modbus_exception_reply() -> None:
    body = bytes([0x01, 0x83, 0x02])
    frame = body + crc16_modbus(body).to_bytes(2, "little")
    assert ModbusRtuDeframer("replies").feed(frame) == [frame]
    assert ModbusRtuDeframer("requests").feed(frame) == []


# ---- Frame ----


def test_frame_equality_ignores_timestamp_and_direction_and_validates() -> None:
    assert Frame(arbitration_id=0x141, data=b"\x9c", timestamp=1.0, is_rx=False) == Frame(
        arbitration_id=0x141, data=b"\x9c"
    )
    assert Frame(arbitration_id=0x141).is_rx
    assert repr(Frame(arbitration_id=0x141, data=b"\x9c\x00")) == "Frame(0x141 [9C 00])"
    with pytest.raises(ValueError, match="outside the standard range"):
        Frame(arbitration_id=0x800)
    with pytest.raises(ValueError, match="exceeds 8 bytes"):
        Frame(arbitration_id=1, data=bytes(9))
    assert Frame(arbitration_id=1, data=bytes(16), is_fd=True).data == bytes(16)
    with pytest.raises(ValueError, match="CAN FD data length 9"):
        Frame(arbitration_id=1, data=bytes(9), is_fd=True)
    assert Frame(arbitration_id=0x1FFFFFFF, is_extended_id=True).is_extended_id
    assert Frame(arbitration_id=1, data=bytearray(b"\x01")).data == b"\x01"  # type: ignore[arg-type]

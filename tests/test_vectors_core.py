"""Every CRC-bearing frame in spec/vectors checks with the C core, and the core's bit layouts
reproduce the manuals' packed examples.

Families' own codecs test the full meaning of each vector; here it is the byte work only.
"""

from __future__ import annotations

from typing import Any

import pytest

from _scales import MIT_V43
from _spec import hexbytes, load_vectors, vector_id
from servobus.core import (
    HOLLOW_FD_COMMAND,
    HOLLOW_FD_REPLY,
    HOLLOW_SETPOINT,
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

MYACTUATOR = load_vectors("myactuator-v4")
HOLLOW = {v["id"]: v for v in load_vectors("hollow")}
RS485 = [v for v in MYACTUATOR if v["transport"] == "rs485"]


def test_every_myactuator_rs485_vector_carries_a_crc() -> None:
    """The spec computed a CRC for every RS485 frame (myactuator-v4.md §10); none is left unchecked here:
    the vectors carrying a CRC are exactly the RS485 ones the test below runs over."""
    assert RS485
    assert [v for v in MYACTUATOR if "computed_crc" in v] == RS485


@pytest.mark.parametrize("vector", RS485, ids=vector_id)
def test_myactuator_rs485_crc(vector: dict[str, Any]) -> None:
    """CRC-16/MODBUS over bytes 0..10, sent low byte first, equals the spec's computed CRC; the
    de-framer returns the frame whole, whole-fed and byte by byte. Vectors damaged in print are
    checked in the spec's resolution (``probable_data``, myactuator-v4.md §9 items 3-5)."""
    body = hexbytes(vector.get("probable_data", vector["data"]))
    frame = hexbytes(vector["frame_with_computed_crc"])
    crc = crc16_modbus(body)
    assert bytes([crc & 0xFF, crc >> 8]) == hexbytes(vector["computed_crc"])
    assert frame == body + hexbytes(vector["computed_crc"])

    whole = MyActuatorRs485Deframer()
    assert whole.feed(frame) == [frame]
    trickle = MyActuatorRs485Deframer()
    assert [f for b in frame for f in trickle.feed(bytes([b]))] == [frame]
    assert (trickle.discarded_bytes, trickle.crc_errors) == (0, 0)


def test_known_crc_values_from_the_issue() -> None:
    """The two values stated in the issue, byte for byte as sent."""
    crc16 = crc16_modbus(bytes.fromhex("3E 01 08 9C 00 00 00 00 00 00 00"))
    assert crc16.to_bytes(2, "little") == bytes.fromhex("F2 30")
    crc32 = crc32_ieee(bytes([0x01]) + bytes(16))
    assert crc32.to_bytes(4, "little") == bytes.fromhex("FE 3A 49 4E")


def test_crc_check_values() -> None:
    """The catalogue check values of both CRCs ("123456789")."""
    assert crc16_modbus(b"123456789") == 0x4B37
    assert crc32_ieee(b"123456789") == 0xCBF43926


TRANSPARENT = ["H12", "H13", "H18", "H19"]


@pytest.mark.parametrize("vid", TRANSPARENT)
def test_hollow_transparent_crc32(vid: str) -> None:
    """CRC-32 over ID + 16 bytes, LSB first. H13/H19 lost bytes in OCR: the spec's CRC-unique
    reconstruction is used (hollow.md A23, A24)."""
    vector = HOLLOW[vid]
    frame = hexbytes(vector.get("data_reconstructed", vector["data"]))
    assert len(frame) == 21
    assert crc32_ieee(frame[:17]).to_bytes(4, "little") == frame[17:]
    deframer = HollowTransparentDeframer()
    assert deframer.feed(b"\x55" + frame + frame[:7]) == [frame]
    assert deframer.pending == 7


def test_hollow_transparent_printed_frames_without_reconstruction_fail() -> None:
    """The frames as printed (bytes lost in OCR) must not check: the reconstruction is needed."""
    for vid in ("H13", "H19"):
        printed = hexbytes(HOLLOW[vid]["data"])
        assert len(printed) < 21
        assert HollowTransparentDeframer().feed(printed) == []


MODBUS = ["H14", "H15", "H16"]


@pytest.mark.parametrize("vid", MODBUS)
def test_hollow_modbus_crc16(vid: str) -> None:
    """Modbus RTU frames check with CRC-16/MODBUS, low byte first, and de-frame in their direction."""
    vector = HOLLOW[vid]
    frame = hexbytes(vector["data"])
    assert crc16_modbus(frame[:-2]).to_bytes(2, "little") == frame[-2:]
    direction = "requests" if vector["direction"] == "request" else "replies"
    assert ModbusRtuDeframer(direction).feed(frame) == [frame]
    assert ModbusRtuDeframer("both").feed(frame) == [frame]


def test_hollow_modbus_read_reply_is_unverifiable_as_the_spec_says() -> None:
    """H17 lost four registers; with them zero the CRC is 80 F4, not the printed 74 DB (A26).
    It is layout-only, so here it only proves our CRC agrees with the spec's own computation."""
    vector = HOLLOW["H17"]
    assert vector["uncertain"]
    zero_filled = hexbytes(vector["data"].replace("??", "00"))
    assert crc16_modbus(zero_filled[:-2]).to_bytes(2, "little") == bytes.fromhex("80 F4")
    assert ModbusRtuDeframer("replies").feed(zero_filled) == []


# ---- bit layouts against the manuals' packed examples ----


def test_myactuator_motion_request_example() -> None:
    """myactuator-v4.md §5.6: E6 66 82 E0 52 33 3B 55 decodes to the stated values and re-encodes.

    10 rad, 10 (kp) and 10 N·m encode exactly under round-to-nearest (58981.5 -> 58982 is a tie);
    v_des 0x82E is 1.02198 rad/s, not a round number, so it is fed back as decoded."""
    frame = bytes.fromhex("E6 66 82 E0 52 33 3B 55")
    packer = Packer(MIT_COMMAND, MIT_V43)
    p, v, kp, kd, t = packer.unpack(frame)
    assert p == pytest.approx(10.0002, abs=1e-4)
    assert v == pytest.approx(1.02198, abs=1e-5)
    assert kp == pytest.approx(10.012, abs=1e-3)
    assert kd == pytest.approx(1.0, abs=1e-3)
    assert t == pytest.approx(10.004, abs=1e-3)
    assert packer.pack([10.0, v, 10.0, kd, 10.0]) == frame
    assert packer.pack([p, v, kp, kd, t]) == frame


def test_myactuator_motion_reply_example() -> None:
    """The reply as the spec resolves it (DATA[2] 0x66, not the misprinted 0x65), 8-byte slot."""
    vector = next(v for v in MYACTUATOR if v.get("can_id") == "0x501")
    frame = hexbytes(vector["probable_data"])
    packer = Packer(
        MIT_REPLY, [FieldScale.integer("motor_id", 0, 255), *(MIT_V43[i] for i in (0, 1, 4))], stride=8
    )
    motor_id, p, v, t = packer.unpack(frame)
    assert motor_id == 1
    assert (p, v, t) == pytest.approx((10.0002, 1.02198, 10.004), abs=1e-3)
    assert packer.pack([motor_id, p, v, t]) == frame


HOLLOW_NORMAL = [
    FieldScale.offset_binary("position_deg", 360.0, 16),
    FieldScale.offset_binary("speed_rad_s", 200.0, 12),
    FieldScale.integer("kp", 0, 4095),
    FieldScale.integer("kd", 0, 4095),
    FieldScale.offset_binary("current_a", 4.0, 12),
]


def test_hollow_normal_mode_example_h1() -> None:
    """hollow.md §4.6: 180°, 100 rad/s, 2 A, kp 0x100, kd 0x020 -> c0 00 c0 01 00 02 0c 00."""
    packer = Packer(HOLLOW_SETPOINT, HOLLOW_NORMAL)
    frame = hexbytes(HOLLOW["H1"]["data"])
    assert packer.pack([180.0, 100.0, 0x100, 0x020, 2.0]) == frame
    assert packer.unpack(frame) == (180.0, 100.0, 0x100, 0x020, 2.0)


def test_hollow_c_routine_example_h2() -> None:
    """hollow.md §4.7: P 0x8000, V 0x900, KP 0x800, KD 0x800, T 0x900 -> 80 00 90 08 00 80 09 00."""
    packer = Packer(HOLLOW_SETPOINT, HOLLOW_NORMAL)
    assert packer.pack([0.0, 200.0 / 8, 0x800, 0x800, 4.0 / 8]) == hexbytes(HOLLOW["H2"]["data"])


@pytest.mark.parametrize("vid", ["H3", "H4", "H5", "H6", "H7", "H8"])
def test_hollow_setpoint_never_collides_with_special_commands(vid: str) -> None:
    """A setpoint at every field's maximum with T landing on a special code is stepped off it."""
    special = hexbytes(HOLLOW[vid]["data"])
    t_code = 0xF00 | special[7]
    packer = Packer(HOLLOW_SETPOINT, HOLLOW_NORMAL)
    current = (t_code - 0x800) / 0x800 * 4.0
    frame = packer.pack([360.0, 200.0, 4095, 4095, current])
    assert frame != special
    assert frame == special[:1] + b"\xfe" + special[2:]
    assert Packer(MIT_COMMAND, HOLLOW_NORMAL).pack([360.0, 200.0, 4095, 4095, current]) == special


FD_REQUEST = [
    FieldScale.twos_complement("position_counts", 40),
    FieldScale.twos_complement("velocity_hz", 32, codes=8388608, span=1000),
    FieldScale.twos_complement("current_raw", 16),
    FieldScale.integer("mode", 0, 2),
    FieldScale.integer("run", 0, 1),
    FieldScale.integer("kp", 0, 255),
    FieldScale.integer("kd", 0, 255),
    FieldScale.integer("zero", 0, 1),
]
FD_REPLY = [
    *FD_REQUEST[:5],
    FieldScale.integer("reserved", 0, 255),
    FieldScale.integer("temperature_c", -128, 127),
    FieldScale.integer("slave_id", 0, 255),
]


def test_hollow_canfd_request_h20() -> None:
    """The all-zero poll (torque mode, stopped) of hollow.md §7.2."""
    frame = hexbytes(HOLLOW["H20"]["data"])
    packer = Packer(HOLLOW_FD_COMMAND, FD_REQUEST)
    assert packer.pack([0] * 8) == frame
    assert packer.unpack(frame) == (0,) * 8


def test_hollow_canfd_reply_h21() -> None:
    """pos 34 counts, 30 °C, slave 1 (hollow.md §7.3), and a negative position sign-extends."""
    frame = hexbytes(HOLLOW["H21"]["data"])
    packer = Packer(HOLLOW_FD_REPLY, FD_REPLY)
    assert packer.unpack(frame) == (34, 0, 0, 0, 0, 0, 30, 1)
    assert packer.pack([34, 0, 0, 0, 0, 0, 30, 1]) == frame
    negative = packer.pack([-81266432, -1000.0, -8, 2, 1, 0, -20, 7])
    assert negative[:9] == (-81266432).to_bytes(5, "big", signed=True) + (-8388608).to_bytes(
        4, "big", signed=True
    )
    assert packer.unpack(negative) == (-81266432, -1000.0, -8, 2, 1, 0, -20, 7)

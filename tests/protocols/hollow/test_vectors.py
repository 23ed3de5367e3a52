"""Every vector of spec/vectors/hollow.json, each handled deliberately (H1-H25).

Requests are built from the vector's decoded physical values, encoded and compared byte for byte,
then decoded back; replies decode to the stated values. Vectors the manual damaged are tested with the
spec's resolution (``data_reconstructed``), and their printed forms are shown to fail as the spec says.
The SLCAN strings (H23-H25) are not frames of this codec: python-can's slcan interface owns them, so
they are checked against what it writes (see :func:`slcan_output`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import pytest

from _spec import hexbytes, load_vectors, vector_id
from servobus.core import crc16_modbus, crc32_ieee
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    CanMode,
    CanModeSwitch,
    ControlMode,
    ConverterPdGains,
    FdCommand,
    FdReply,
    ModbusRead,
    ModbusReadReply,
    ModbusWrite,
    ModbusWriteAck,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    Start,
    Stop,
    TransparentReply,
    TransparentRequest,
    decode_reply,
    decode_request,
)
from servobus.protocols.hollow.codec import request_frame
from servobus.protocols.hollow.converter import decode_converter_config
from servobus.protocols.hollow.model import COUNTS_PER_TURN
from servobus.protocols.hollow.rs485 import decode_modbus_reply, decode_modbus_request

VECTORS = {v["id"]: v for v in load_vectors("hollow")}
MOTOR = 1  # the examples' motor id where the vector leaves it open ("motor CAN id (not stated)")
HOST = 0x64

# Vectors marked uncertain in the JSON and the resolution each test applies (listed in the report).
UNCERTAIN_RESOLUTIONS = {
    "H4": "stop = FF x7 FD (A2: MIT exit code, the only free code; [C] Chinese copy and third-party code)",
    "H10": "normal-mode switch = extended id, D0 = 0x02, D1..D7 = 0 (A4: D0 bit 1, 1 = normal)",
    "H11": "PI frame padded to DLC 8 with zeros (A17); decoders also accept DLC 6 and 7",
    "H17": "layout only (A26): velocity registers lost and the printed CRC unverifiable",
    "H22": "byte 0 configurable (A19): 0x01 as printed; decoders accept 0x00 and 0x01",
    "H25": "O\\r\\n is O\\r (A38): the trailing LF is not SLCAN",
}


def _data(vector: dict[str, Any]) -> bytes:
    return hexbytes(vector["data"])


def _stated_crc(vector: dict[str, Any]) -> int:
    match = re.search(r"CRC value 0x([0-9A-Fa-f]+)", vector["crc_check"])
    assert match, vector["crc_check"]
    return int(match.group(1), 16)


def _counts_deg(counts: int) -> float:
    return counts * 360.0 / COUNTS_PER_TURN


# ---- classic CAN (H1-H11) ----


def check_h1(v: dict[str, Any]) -> None:
    d = v["decoded"]
    assert v["data_as_printed"].count("<mark>") == 2  # A9: the HTML highlight tags are stripped
    assert re.sub(r"</?mark>", "", v["data_as_printed"]).upper() == v["data"]
    command = Setpoint(
        position_deg=d["position_deg_at_pmax_1"],
        speed_rad_s=d["speed_rad_s_at_full_scale_200"],
        kp=int(d["kp"], 16),
        kd=int(d["kd"], 16),
        current_a=d["current_a_at_full_scale_4"],
    )
    _request_round_trip(command, v)
    # The codes the vector states, through the same bytes.
    frame = command.encode()
    assert (frame[0] << 8 | frame[1]) == int(d["position_code"], 16)
    assert (frame[2] << 4 | frame[3] >> 4) == int(d["speed_code"], 16)
    assert ((frame[6] & 0xF) << 8 | frame[7]) == int(d["torque_code"], 16)


def check_h2(v: dict[str, Any]) -> None:
    d = v["decoded"]
    command = Setpoint(
        position_deg=d["position_deg_at_pmax_1"],
        speed_rad_s=d["speed_fraction_of_full_scale"] * DEFAULT_MODEL.speed_full_scale_rad_s,
        kp=int(d["kp"], 16),
        kd=int(d["kd"], 16),
        current_a=d["torque_fraction_of_full_scale"] * DEFAULT_MODEL.current_full_scale_a,
    )
    _request_round_trip(command, v)


SPECIALS = {
    0xFC: Start(),
    0xFD: Stop(),
    0xF9: SelectMode(mode=ControlMode.TORQUE),
    0xFA: SelectMode(mode=ControlMode.VELOCITY),
    0xFB: SelectMode(mode=ControlMode.POSITION),
    0xFE: SetZero(),
}


def check_special(v: dict[str, Any]) -> None:
    code = int(v["decoded"]["special_command"], 16)
    _request_round_trip(SPECIALS[code], v)
    # A1: printed with FF bytes missing; the reconstruction is FF x7 + code in every case.
    printed = v.get("data_as_printed", "")
    if printed.startswith("0x"):
        assert hexbytes(printed.replace(" ", ""))[-1] == code
    for can_mode in CanMode:  # the same in extended mode (§5.2)
        assert decode_request(MOTOR, _data(v), can_mode=can_mode) == SPECIALS[code]


def check_mode_switch(v: dict[str, Any]) -> None:
    mode = CanMode.NORMAL if v["decoded"]["byte0_bit1_mask_0x02"] else CanMode.EXTENDED
    command = CanModeSwitch(mode=mode)
    assert "EXTENDED" in v["can_id"]
    _request_round_trip(command, v, extended=True)


def check_h11(v: dict[str, Any]) -> None:
    command = PiMultiplier(gain=PiGain.SPEED_KP, multiplier=1.0)
    _request_round_trip(command, v, extended=True)
    assert decode_request(MOTOR, _data(v)[:6], is_extended_id=True) == command  # DLC 6 (A17)


def _request_round_trip(command: Any, v: dict[str, Any], *, extended: bool = False, fd: bool = False) -> None:
    data = _data(v)
    assert command.encode() == data
    frame = request_frame(MOTOR, command)
    assert (frame.is_extended_id, frame.is_fd) == (extended, fd)
    assert decode_request(MOTOR, data, is_extended_id=extended, is_fd=fd) == command


# ---- transparent (H12, H13, H18, H19) ----


def _fd_command(d: dict[str, Any]) -> FdCommand:
    command = FdCommand(
        position_deg=_counts_deg(d["pos_counts"]),
        velocity_rpm=d["vel_electrical_hz"] * 60 / DEFAULT_MODEL.pole_pairs,
        current_raw=d["cur_raw_int16"],
        mode=d["mode_sel"],
        run=d["run_cmd"],
        kp=d["kp"],
        kd=d["kd"],
        zero=d["zero"],
    )
    assert command.position_counts == int(d["pos_raw_40bit"], 16)
    return command


def _check_fd_reply(reply: FdReply, d: dict[str, Any]) -> None:
    assert reply.position_counts == d["pos_counts"] == int(d["pos_raw_40bit"], 16)
    assert reply.position_deg == pytest.approx(d["pos_deg"], abs=1e-6)
    assert reply.position_counts / COUNTS_PER_TURN == pytest.approx(d["pos_turns"], rel=1e-4)
    assert reply.electrical_hz == d["vel_electrical_hz"]
    assert (reply.current_raw, reply.mode, reply.running, reply.reserved) == (
        d["cur_raw_int16"],
        d["mode"],
        d["run_status"],
        d["reserved"],
    )
    assert (reply.temperature_c, reply.slave_id) == (d["temperature_c"], d["slave_id"])


def check_transparent_request(v: dict[str, Any]) -> None:
    data = _data(v)
    d = v["decoded"]
    motor_id = d.get("motor_can_id", d.get("id"))
    request = TransparentRequest(motor_id=motor_id, command=_fd_command(d))
    assert request.encode() == data
    assert TransparentRequest.decode(data) == request
    assert int.from_bytes(data[17:], "little") == crc32_ieee(data[:17]) == _stated_crc(v)


def check_transparent_reply(v: dict[str, Any]) -> None:
    # H13 / H19: the printed frame lost bytes; the CRC-reconstructed one is the vector (A23, A24).
    printed, data = _data(v), hexbytes(v["data_reconstructed"])
    with pytest.raises(ProtocolError, match="expected 21 data bytes"):
        TransparentReply.decode(printed)
    assert _is_subsequence(printed, data)
    assert int.from_bytes(data[17:], "little") == crc32_ieee(data[:17]) == _stated_crc(v)
    d = v["decoded"]
    reply = TransparentReply.decode(data)
    header = d.get("header_id", d.get("header_id_master"))
    assert reply.header_id == (header if isinstance(header, int) else int(header.split()[0], 16))
    _check_fd_reply(reply.reply, d)
    assert reply.encode() == data


def _is_subsequence(short: bytes, long: bytes) -> bool:
    it = iter(long)
    return all(b in it for b in short)


# ---- Modbus RTU (H14-H17) ----


def check_h14(v: dict[str, Any]) -> None:
    data = _data(v)
    d = v["decoded"]
    request = ModbusWrite(
        slave_id=d["slave_address_motor_can_id"], command=_fd_command(d["canfd_payload_decoded"])
    )
    assert request.encode() == data
    assert decode_modbus_request(data) == request
    assert int.from_bytes(data[-2:], "little") == crc16_modbus(data[:-2]) == _stated_crc(v)
    assert data.hex(" ").upper().endswith(v["data_as_printed"].split("'")[1])  # the printed tail


def check_short_modbus(v: dict[str, Any]) -> None:
    data = _data(v)
    d = v["decoded"]
    assert (int(d["start_register"], 16), d["register_count"]) == (0, 16)
    message: ModbusRead | ModbusWriteAck
    if v["direction"] == "request":
        message = ModbusRead(slave_id=d["slave_address"])
        assert decode_modbus_request(data) == message
    else:
        message = ModbusWriteAck(slave_id=d["slave_address"])
        assert decode_modbus_reply(data) == message
    assert int(d["function"].split()[0], 16) == message.FUNCTION
    assert message.encode() == data
    assert int.from_bytes(data[-2:], "little") == crc16_modbus(data[:-2]) == _stated_crc(v)
    # A25: the 9-byte text line (one spurious 00) fails the CRC.
    text = re.search(r"text: '([0-9A-F ]+)'", v["data_as_printed"])
    assert text, v["data_as_printed"]
    decoder = decode_modbus_request if v["direction"] == "request" else decode_modbus_reply
    with pytest.raises(ProtocolError):
        decoder(hexbytes(text.group(1)))


def check_h17(v: dict[str, Any]) -> None:
    # A26: the velocity registers are lost and the printed CRC cannot be verified: layout only.
    cells = v["data"].split()
    assert cells.count("??") == 8
    zero_filled = bytes(int(c, 16) if c != "??" else 0 for c in cells)
    with pytest.raises(ProtocolError, match="CRC16 mismatch"):
        decode_modbus_reply(zero_filled)
    assert crc16_modbus(zero_filled[:-2]).to_bytes(2, "little") == bytes.fromhex(
        "80 F4"
    )  # as the spec computes
    # With a CRC that checks, the layout decodes to the legible values the vector states.
    framed = zero_filled[:-2] + crc16_modbus(zero_filled[:-2]).to_bytes(2, "little")
    reply = decode_modbus_reply(framed)
    assert isinstance(reply, ModbusReadReply)
    d = v["decoded"]
    assert (reply.slave_id, reply.reply.slave_id) == (d["slave_address"], d["slave_id"])
    assert reply.reply.position_counts == -81266432  # "FF FB 27 F9 00", tentative (A26)
    assert (reply.reply.current_raw, reply.reply.mode, reply.reply.running, reply.reply.reserved) == (
        d["cur_raw"],
        d["mode"],
        d["run_status"],
        d["reserved"],
    )
    assert reply.reply.temperature_c == d["temperature_c"]
    # Our encoder puts every legible cell where the manual's table has it.
    encoded = ModbusReadReply(slave_id=1, reply=reply.reply).encode()
    assert [f"{b:02X}" for b in encoded[:-2]] == [c if c != "??" else "00" for c in cells[:-2]]


# ---- CAN FD (H20, H21) ----


def check_h20(v: dict[str, Any]) -> None:
    assert v["can_id"].startswith("0x001")
    command = _fd_command(v["decoded"])
    assert command == FdCommand()  # the all-zero poll
    _request_round_trip(command, v, fd=True)


def check_h21(v: dict[str, Any]) -> None:
    assert v["can_id"].startswith("0x064")
    data = _data(v)
    reply = decode_reply(HOST, data, is_fd=True)
    assert isinstance(reply, FdReply)
    _check_fd_reply(reply, v["decoded"])
    assert reply.encode() == data


# ---- converter configuration (H22) ----


def check_h22(v: dict[str, Any]) -> None:
    d = v["decoded"]
    command = ConverterPdGains(p=d["P"], d=d["D"], header=int(d["byte0"].split()[0], 16))
    assert command.encode() == _data(v)
    assert decode_converter_config(_data(v)) == command
    # The prose's header (0x00) is the encoder's default and decodes too.
    assert ConverterPdGains(p=16, d=16).encode() == b"\x00" + _data(v)[1:]


# ---- SLCAN (H23-H25): python-can's slcan interface owns this protocol ----


def slcan_output(actions: Callable[[Any], None]) -> bytes:
    """What python-can's slcan interface writes to its serial port for ``actions(bus)``."""
    slcan = pytest.importorskip("can.interfaces.slcan")
    bus = slcan.slcanBus("loop://", sleep_after_open=0)
    try:
        port = bus.serialPortOrig
        port.read(port.in_waiting)  # the "O\r" of construction
        actions(bus)
        written: bytes = port.read(port.in_waiting)
        return written
    finally:
        bus.shutdown()


def check_slcan(v: dict[str, Any]) -> None:
    # The manual's initialisation: S8 (1 Mbit/s nominal), Y5 (5 Mbit/s data), then open.
    written = slcan_output(lambda bus: bus.set_bitrate(1_000_000, 5_000_000))
    commands = written.split(b"\r")
    expected = _data(v)
    if v["id"] == "H25":
        assert expected == b"O\r\n"
        expected = expected.rstrip(b"\n")  # A38: SLCAN ends commands with CR only
    assert expected[:-1] in commands
    assert commands.index(b"S8") < commands.index(b"Y5") < len(commands) - 1 - commands[::-1].index(b"O")


CHECKS: dict[str, Callable[[dict[str, Any]], None]] = {
    "H1": check_h1,
    "H2": check_h2,
    **{f"H{n}": check_special for n in range(3, 9)},
    "H9": check_mode_switch,
    "H10": check_mode_switch,
    "H11": check_h11,
    "H12": check_transparent_request,
    "H13": check_transparent_reply,
    "H14": check_h14,
    "H15": check_short_modbus,
    "H16": check_short_modbus,
    "H17": check_h17,
    "H18": check_transparent_request,
    "H19": check_transparent_reply,
    "H20": check_h20,
    "H21": check_h21,
    "H22": check_h22,
    "H23": check_slcan,
    "H24": check_slcan,
    "H25": check_slcan,
}

# Vectors that no test here checks. Empty: the SLCAN ones are checked against python-can above.
EXCLUDED: dict[str, str] = {}


@pytest.mark.parametrize("vector", list(VECTORS.values()), ids=vector_id)
def test_vector(vector: dict[str, Any]) -> None:
    CHECKS[vector["id"]](vector)


def test_every_vector_is_checked_or_excluded_with_a_reason() -> None:
    assert set(CHECKS) | set(EXCLUDED) == set(VECTORS)
    assert not set(CHECKS) & set(EXCLUDED)


def test_the_uncertain_list_is_exact() -> None:
    assert set(UNCERTAIN_RESOLUTIONS) == {k for k, v in VECTORS.items() if v["uncertain"]}


def test_vectors_cover_every_stated_extra_field() -> None:
    # data_reconstructed / data_as_printed / crc_check are each used by the checks above.
    with_reconstruction = {k for k, v in VECTORS.items() if "data_reconstructed" in v}
    assert with_reconstruction == {"H13", "H19"}
    with_crc = {k for k, v in VECTORS.items() if "CRC value" in v["crc_check"]}
    assert with_crc == {"H12", "H13", "H14", "H15", "H16", "H18", "H19"}


def test_slcan_formats_the_specs_frame_examples() -> None:
    # hollow.md §8 "Examples for motor id 1": python-can writes our frames as the spec shows.
    import can

    def send(frame: Frame) -> Callable[[Any], None]:
        message = can.Message(
            arbitration_id=frame.arbitration_id,
            data=frame.data,
            is_extended_id=frame.is_extended_id,
            is_fd=frame.is_fd,
            bitrate_switch=frame.bitrate_switch,
        )
        return lambda bus: bus.send(message)

    h1 = Setpoint(position_deg=180.0, speed_rad_s=100.0, kp=0x100, kd=0x020, current_a=2.0)
    assert slcan_output(send(request_frame(1, h1))) == b"t0018C000C00100020C00\r"
    assert slcan_output(send(request_frame(1, Start()))) == b"t0018FFFFFFFFFFFFFFFC\r"
    switch = CanModeSwitch(mode=CanMode.EXTENDED)
    assert slcan_output(send(request_frame(1, switch))) == b"T000000018" + b"0" * 16 + b"\r"
    assert slcan_output(send(request_frame(1, FdCommand()))) == b"b001A" + b"0" * 32 + b"\r"

"""The spec's command tables, parsed from hollow.md: every row has an encoder and a decoder, or a
documented reason why this codec does not own it. The tests follow the spec, not a list typed here:
a row added to the spec fails until it is handled."""

from __future__ import annotations

import re
from typing import Any

import pytest

from _spec import SPEC_DIR
from servobus.protocols.hollow import (
    CanMode,
    CanModeSwitch,
    ControlMode,
    ConverterGain,
    ConverterPdGains,
    ConverterPiMultiplier,
    FdCommand,
    FdReply,
    ModbusRead,
    ModbusReadReply,
    ModbusWrite,
    ModbusWriteAck,
    PiGain,
    PiMultiplier,
    SelectMode,
    SetZero,
    SpecialCommand,
    Start,
    Stop,
    decode_reply,
    decode_request,
)
from servobus.protocols.hollow.converter import decode_converter_config
from servobus.protocols.hollow.model import DEFAULT_MODEL
from servobus.protocols.hollow.rs485 import decode_modbus_reply, decode_modbus_request

SPEC = SPEC_DIR / "hollow.md"
if not SPEC.exists():
    pytest.skip(f"spec not found at {SPEC}", allow_module_level=True)
TEXT = SPEC.read_text()


def section(number: str) -> str:
    """The text of the section headed ``## number`` or ``### number`` up to the next heading."""
    match = re.search(rf"^#+ {re.escape(number)} .*?$(.*?)(?=^#+ )", TEXT, re.M | re.S)
    assert match, f"section {number} not found in {SPEC}"
    return match.group(1)


def table_rows(text: str, first_header: str) -> list[list[str]]:
    """The body rows of the table whose first header cell is ``first_header``."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == first_header:
            rows = []
            for body in lines[i + 2 :]:
                if not body.startswith("|"):
                    break
                rows.append([c.strip() for c in body.strip().strip("|").split("|")])
            return rows
    raise AssertionError(f"no table headed {first_header!r}")


def backticked_hex(cell: str) -> bytes:
    match = re.search(r"`([0-9A-F ]+)`", cell)
    assert match, cell
    return bytes.fromhex(match.group(1))


# ---- §4.1 special commands ----

# Words of each row's "Meaning" that name the command, checked against the decoded object.
SPECIAL_MEANINGS: dict[int, tuple[SpecialCommand, str]] = {
    0xFC: (Start(), "Start"),
    0xFD: (Stop(), "Stop"),
    0xF9: (SelectMode(mode=ControlMode.TORQUE), "**torque**"),
    0xFA: (SelectMode(mode=ControlMode.VELOCITY), "**speed-torque**"),
    0xFB: (SelectMode(mode=ControlMode.POSITION), "**position-velocity-torque**"),
    0xFE: (SetZero(), "mechanical zero"),
}


def test_every_special_command_row_encodes_and_decodes() -> None:
    rows = table_rows(section("4.1"), "D7")
    assert rows
    for code_cell, frame_cell, meaning, _state in rows:
        code = int(code_cell.strip("*"), 16)
        frame = backticked_hex(frame_cell)
        for can_mode in CanMode:
            decoded = decode_request(1, frame, can_mode=can_mode)
            assert isinstance(decoded, SpecialCommand) and decoded.special_code == code
        assert decoded.encode() == frame
        expected, words = SPECIAL_MEANINGS[code]
        assert decoded == expected and words in meaning
    assert {int(r[0].strip("*"), 16) for r in rows} == set(SPECIAL_MEANINGS)


# ---- §5.1 mode switch, §6 PI multipliers ----


def test_every_mode_switch_row_encodes_and_decodes() -> None:
    rows = table_rows(section("5.1"), "Frame data")
    assert len(rows) == 2
    for frame_cell, result in rows:
        frame = backticked_hex(frame_cell)
        mode = CanMode.NORMAL if "**normal mode**" in result else CanMode.EXTENDED
        assert "**extended mode**" in result or mode is CanMode.NORMAL
        assert decode_request(1, frame, is_extended_id=True) == CanModeSwitch(mode=mode)
        assert CanModeSwitch(mode=mode).encode() == frame


def _numbered_names(cell: str) -> dict[int, str]:
    return {
        int(value, 16): name for value, name in re.findall(r"(0x[0-9A-F]{2}) = ([\w -]+?)(?=[,;.]|$)", cell)
    }


def test_every_pi_gain_of_the_motor_frame_has_a_member() -> None:
    rows = {r[0]: r[1] for r in table_rows(section("6."), "Byte")}
    gains = _numbered_names(rows["D1"])
    assert len(gains) == 4
    for value, name in gains.items():
        gain = PiGain[name.upper()]
        assert gain == value
        frame = PiMultiplier(gain=gain, multiplier=1.0).encode()
        assert decode_request(1, frame, is_extended_id=True) == PiMultiplier(gain=gain, multiplier=1.0)


def test_every_selector_of_the_converter_frame_has_a_decoder() -> None:
    rows = {r[0]: r[1] for r in table_rows(section("9.3"), "Byte")}
    selectors = _numbered_names(rows["D1"])
    assert len(selectors) == 5
    for value, name in selectors.items():
        command: ConverterPdGains | ConverterPiMultiplier
        if name == "set P-D":
            command = ConverterPdGains(p=1, d=2)
        else:
            command = ConverterPiMultiplier(gain=ConverterGain[name.upper()], multiplier=2.0)
        frame = command.encode()
        assert frame[1] == value and decode_converter_config(frame) == command


# ---- §7.2 / §7.3 CAN FD fields ----

COUNT_DEG = 360.0 / (1 << 20)
MINUS_ONE_RPM = -1 / DEFAULT_MODEL.fd_velocity_counts_per_rpm  # velocity code -1: all bytes FF

# Spec field label -> (attribute, a value whose code has every byte of the field non-zero).
FD_REQUEST_FIELDS: dict[str, tuple[str, Any]] = {
    "Pos": ("position_deg", -COUNT_DEG),
    "Vel": ("velocity_rpm", MINUS_ONE_RPM),
    "Cur": ("current_raw", -1),
    "Mode Sel": ("mode", ControlMode.POSITION),
    "Run Cmd": ("run", True),
    "Kp": ("kp", 255),
    "Kd": ("kd", 255),
    "Zero": ("zero", True),
}
FD_REPLY_FIELDS: dict[str, tuple[str, Any]] = {
    "Pos": ("position_deg", -COUNT_DEG),
    "Vel": ("velocity_rpm", MINUS_ONE_RPM),
    "Cur": ("current_raw", -1),
    "Mode": ("mode", ControlMode.VELOCITY),
    "Run Status": ("running", True),
    "Reserved": ("reserved", 0xFF),
    "Temperature": ("temperature_c", -1),
    "Slave ID": ("slave_id", 100),
}


def _byte_range(cell: str) -> set[int]:
    numbers = [int(n) for n in re.findall(r"\d+", cell)]
    return set(range(numbers[0], numbers[-1] + 1))


@pytest.mark.parametrize(
    ("number", "fields", "cls"),
    [("7.2", FD_REQUEST_FIELDS, FdCommand), ("7.3", FD_REPLY_FIELDS, FdReply)],
)
def test_every_can_fd_field_sits_in_its_bytes(
    number: str, fields: dict[str, tuple[str, Any]], cls: type
) -> None:
    rows = table_rows(section(number), "Byte")
    assert [r[1] for r in rows] == list(fields)  # every spec field is mapped, in order
    base = {"slave_id": 0} if cls is FdReply else {}
    assert cls(**base).encode() == bytes(16)
    covered: set[int] = set()
    for byte_cell, label, _encoding in rows:
        attribute, value = fields[label]
        message = cls(**{**base, attribute: value})
        frame = message.encode()
        assert {i for i, b in enumerate(frame) if b} == _byte_range(byte_cell), label
        decoded = (
            decode_request(1, frame, is_fd=True) if cls is FdCommand else decode_reply(100, frame, is_fd=True)
        )
        assert getattr(decoded, attribute) == getattr(message, attribute)
        covered |= _byte_range(byte_cell)
    assert covered == set(range(16))


# ---- §9.5 Modbus frames ----

MODBUS_FRAMES: dict[str, Any] = {
    "Write request": (ModbusWrite(slave_id=7, command=FdCommand(kp=0x5A)), decode_modbus_request),
    "Write response": (ModbusWriteAck(slave_id=7), decode_modbus_reply),
    "Read request": (ModbusRead(slave_id=7), decode_modbus_request),
    "Read response": (
        ModbusReadReply(slave_id=7, reply=FdReply(slave_id=7, temperature_c=31)),
        decode_modbus_reply,
    ),
}


def _expand_template(template: str, slave: int, payload: bytes) -> list[int | None]:
    """The frame a template like ``addr 10 00 00 00 10 20 (00 XX)x16 crcLo crcHi`` describes
    (None where the CRC goes)."""
    out: list[int | None] = []
    for token in re.findall(r"\(00 XX\)\u00d716|addr|crcLo|crcHi|[0-9A-F]{2}", template):
        if token == "addr":
            out.append(slave)
        elif token.startswith("("):
            for b in payload:
                out += [0x00, b]
        elif token.startswith("crc"):
            out.append(None)
        else:
            out.append(int(token, 16))
    return out


def test_every_modbus_frame_row_encodes_and_decodes() -> None:
    rows = table_rows(section("9.5"), "Purpose")
    assert [r[0] for r in rows] == list(MODBUS_FRAMES)
    for purpose, template_cell, length_cell in rows:
        message, decoder = MODBUS_FRAMES[purpose]
        frame = message.encode()
        assert len(frame) == int(length_cell.split()[0])
        payload = message.command.encode() if purpose == "Write request" else b""
        if purpose == "Read response":
            payload = message.reply.encode()
        expected = _expand_template(template_cell.strip("`"), 7, payload)
        assert len(expected) == len(frame)
        assert [b if e is not None else None for b, e in zip(frame, expected, strict=True)] == expected
        assert decoder(frame) == message


# ---- tables of other layers: documented, and kept exact ----

# §2.2: the console is an ASCII configuration/test interface at 19200 baud, not a frame codec; the
# manual says products should use CAN. A console driver (not this family's codec) would own these.
CONSOLE_NOT_A_CODEC = {
    "`p`": "console: mode submenu",
    "`s`": "console: parameter submenu",
    "`m<float>`": "console: run with a setpoint",
    "`b<float>`": "console: same syntax, meaning unstated (A15)",
    "`r`": "console: stop",
    '"SetZeroPoint", "ClrZeroPoint"': "console: menu items without keystrokes",
}
# §8: the USB adapter speaks SLCAN, python-can's slcan interface (the transport layer); test_vectors
# checks it writes the spec's examples.
SLCAN_IN_PYTHON_CAN = {"`t`", "`T`", "`d` / `b`", "`D` / `B`"}


def test_console_commands_are_documented_as_not_codecs_of_this_family() -> None:
    assert {r[0] for r in table_rows(section("2.2"), "Input")} == set(CONSOLE_NOT_A_CODEC)


def test_slcan_frame_syntax_belongs_to_python_can() -> None:
    assert {r[0] for r in table_rows(section("8."), "Prefix")} == SLCAN_IN_PYTHON_CAN

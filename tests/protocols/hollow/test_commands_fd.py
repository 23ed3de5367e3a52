"""The CAN FD request (hollow.md §7.2)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given

from servobus.errors import ProtocolError
from servobus.protocols.hollow import DEFAULT_MODEL, ControlMode, FdCommand, HollowModel
from servobus.protocols.hollow.commands_fd import fd_position_limits_deg, fd_velocity_limits_rpm

from .._contract import assert_quantised
from ._strategies import fd_commands

COUNT_DEG = 360.0 / (1 << 20)


@given(fd_commands())
def test_fd_command_round_trip_is_quantisation(command: FdCommand) -> None:
    frame = command.encode()
    assert len(frame) == 16
    decoded = FdCommand.decode(frame, model=command.model)
    assert_quantised(decoded.position_deg, command.position_deg, COUNT_DEG, field="position_deg")
    rpm_res = 1 / command.model.fd_velocity_counts_per_rpm
    assert_quantised(decoded.velocity_rpm, command.velocity_rpm, rpm_res, field="velocity_rpm")
    assert (decoded.current_raw, decoded.mode, decoded.run, decoded.kp, decoded.kd, decoded.zero) == (
        command.current_raw,
        command.mode,
        command.run,
        command.kp,
        command.kd,
        command.zero,
    )
    assert decoded.encode() == frame


def test_fd_command_layout() -> None:
    # §7.2: Pos 40-bit BE (D0-D4), Vel int32 BE (D5-D8), Cur int16 BE (D9-D10), then five bytes.
    command = FdCommand(
        position_deg=-1.0 * COUNT_DEG,
        velocity_rpm=1000.0 * 60 / 14,  # 1000 Hz electrical at 14 pole pairs = 8388608 counts
        current_raw=-2,
        mode=ControlMode.POSITION,
        run=True,
        kp=0x10,
        kd=0x20,
        zero=False,
    )
    assert command.encode() == bytes.fromhex("FF FF FF FF FF 00 80 00 00 FF FE 02 01 10 20 00")
    assert command.position_counts == -1
    assert math.isclose(command.electrical_hz, 1000.0)


def test_fd_velocity_depends_on_pole_pairs() -> None:
    seven = HollowModel(pole_pairs=7)
    frame = FdCommand(velocity_rpm=60.0, model=seven).encode()
    # 60 rpm * 7 pole pairs / 60 = 7 Hz electrical = 58720.256 -> 58720 counts
    assert int.from_bytes(frame[5:9], "big", signed=True) == 58720
    assert FdCommand.decode(frame, model=seven).electrical_hz == pytest.approx(7.0, abs=1e-3)


def test_fd_command_accepts_ints_for_flags_and_mode() -> None:
    command = FdCommand(mode=1, run=1, zero=0)  # type: ignore[arg-type]
    assert (command.mode, command.run, command.zero) == (ControlMode.VELOCITY, True, False)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        (
            "position_deg",
            math.nextafter(fd_position_limits_deg()[1], math.inf),
            r"position_deg=.* is outside \[",
        ),
        (
            "position_deg",
            math.nextafter(fd_position_limits_deg()[0], -math.inf),
            r"position_deg=.* is outside \[",
        ),
        (
            "velocity_rpm",
            math.nextafter(fd_velocity_limits_rpm(DEFAULT_MODEL)[1], math.inf),
            "velocity_rpm=.* is outside",
        ),
        ("current_raw", 32768, r"current_raw=32768 is outside \[-32768, 32767\]"),
        ("current_raw", -32769, r"current_raw=-32769 is outside \[-32768, 32767\]"),
        ("current_raw", 1.5, "current_raw=1.5 is not an integer"),
        ("kp", 256, r"kp=256 is outside \[0, 255\]"),
        ("kd", -1, r"kd=-1 is outside \[0, 255\]"),
        ("mode", 3, "mode=3 is not one of TORQUE=0, VELOCITY=1, POSITION=2"),
        ("run", 2, "run=2 is not one of False, True"),
        ("zero", "yes", "zero='yes' is not one of False, True"),
    ],
)
def test_fd_command_out_of_range_raises(field: str, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FdCommand(**{field: value})  # type: ignore[arg-type]


def test_fd_position_limits_are_the_40_bit_codes() -> None:
    lo, hi = fd_position_limits_deg()
    assert FdCommand(position_deg=lo).encode()[:5] == bytes.fromhex("80 00 00 00 00")
    assert FdCommand(position_deg=hi).encode()[:5] == bytes.fromhex("7F FF FF FF FF")


@pytest.mark.parametrize(
    ("index", "value", "message"),
    [(11, 3, "Mode Sel: unknown value 3"), (12, 2, "run=2"), (15, 0xFF, "zero=255")],
)
def test_fd_command_decode_refuses_unknown_bytes(index: int, value: int, message: str) -> None:
    frame = bytearray(16)
    frame[index] = value
    with pytest.raises(ProtocolError, match=message):
        FdCommand.decode(bytes(frame))


def test_fd_command_decode_checks_length() -> None:
    with pytest.raises(ProtocolError, match="CAN FD request: expected 16 data bytes, got 8"):
        FdCommand.decode(bytes(8))

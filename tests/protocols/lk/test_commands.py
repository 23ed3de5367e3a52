"""LK requests (commands.py, commands_control.py): round trips, exact layouts, range errors."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import lk
from servobus.protocols.lk import LkModel, MotorType, SpinDirection
from servobus.protocols.lk.codec import COMMAND_CLASSES

from ._strategies import COMMANDS, check_round_trip

MF = MotorType.MF
MG = MotorType.MG
MH = MotorType.MH
MS = MotorType.MS


def test_every_command_class_has_a_round_trip_strategy() -> None:
    assert set(COMMANDS) == set(COMMAND_CLASSES)


@pytest.mark.parametrize("cls", sorted(COMMANDS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@given(data=st.data())
def test_command_round_trip_is_quantisation(cls: type, data: st.DataObject) -> None:
    case = COMMANDS[cls]
    check_round_trip(data.draw(case.strategy), case)


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        (lk.MotorOff(), "80 00 00 00 00 00 00 00"),
        (lk.CalibrateEncoder(), "18 00 00 00 00 00 00 00"),
        (lk.ReadAcceleration(), "33 00 00 00 00 00 00 00"),
        (lk.BrakeControl(action=lk.BrakeAction.READ), "8C 10 00 00 00 00 00 00"),
        (lk.WriteEncoderOffset(offset_counts=0x1234, encoder_bits=14), "91 00 00 00 00 00 34 12"),
        (lk.WriteAcceleration(acceleration_dps2=-2), "34 00 00 00 FE FF FF FF"),
        (lk.OpenLoopControl(power_counts=-850), "A0 00 00 00 AE FC 00 00"),
        # 1.5 A on MF = 1.5 * 4096/33 = 186.18 -> 186 = 0xBA; on MG: 93.09 -> 93 = 0x5D.
        (lk.TorqueControl(motor_type=MF, current_a=1.5), "A1 00 00 00 BA 00 00 00"),
        (lk.TorqueControl(motor_type=MG, current_a=-33.0), "A1 00 00 00 00 F8 00 00"),
        (lk.TorqueControl(motor_type=MH, iq_counts=2048), "A1 00 00 00 00 08 00 00"),
        (lk.SpeedControl(speed_dps=90, motor_type=MF, current_limit_a=16.5), "A2 00 00 08 28 23 00 00"),
        (lk.SpeedControl(speed_dps=-0.01, motor_type=MS, iq_limit_counts=850), "A2 00 52 03 FF FF FF FF"),
        (lk.SpeedControlV235(speed_dps=90), "A2 00 00 00 28 23 00 00"),
        (lk.MultiTurnPosition(angle_deg=360), "A3 00 00 00 A0 8C 00 00"),
        (lk.MultiTurnPositionSpeed(angle_deg=-360, max_speed_dps=360), "A4 00 68 01 60 73 FF FF"),
        (
            lk.SingleTurnPosition(angle_deg=400.0, direction=SpinDirection.COUNTER_CLOCKWISE),
            "A5 01 00 00 40 9C 00 00",
        ),
        (
            lk.SingleTurnPositionV235(angle_deg=359.99, direction=SpinDirection.CLOCKWISE),
            "A5 00 00 00 9F 8C 00 00",
        ),
        (
            lk.SingleTurnPositionSpeed(angle_deg=1000.0, direction=SpinDirection.CLOCKWISE, max_speed_dps=1),
            "A6 00 01 00 A0 86 01 00",
        ),
        (
            lk.SingleTurnPositionSpeedV235(
                angle_deg=90, direction=SpinDirection.CLOCKWISE, max_speed_dps=500
            ),
            "A6 00 F4 01 28 23 00 00",
        ),
        (lk.IncrementalPosition(increment_deg=-0.01), "A7 00 00 00 FF FF FF FF"),
        (lk.IncrementalPositionSpeed(increment_deg=30, max_speed_dps=3600), "A8 00 10 0E B8 0B 00 00"),
        (lk.MultiMotorTorque(motor_type=MH, iq_counts=(1, -1, 2000, -2000)), "01 00 FF FF D0 07 30 F8"),
    ],
    ids=lambda v: type(v).__name__ if not isinstance(v, str) else "",
)
def test_command_bytes(command: Any, expected: str) -> None:
    data = bytes.fromhex(expected)
    assert command.encode() == data
    model = LkModel(
        revision=next(iter(sorted(type(command).REVISIONS, key=lambda r: r.value, reverse=True))),
        motor_type=getattr(command, "motor_type", MG),
    )
    decoded = type(command).decode(data, model=model)
    assert type(decoded) is type(command)
    assert decoded.encode() == data


def test_single_turn_layouts_agree_below_360_degrees_only() -> None:
    # Spec §4.14 D8: identical bytes for targets 0..35999; the V2.36 uint32 reaches beyond.
    v236 = lk.SingleTurnPosition(angle_deg=123.45, direction=SpinDirection.CLOCKWISE)
    v235 = lk.SingleTurnPositionV235(angle_deg=123.45, direction=SpinDirection.CLOCKWISE)
    assert v236.encode() == v235.encode()
    with pytest.raises(ValueError, match=r"angle_deg=360\.0 is outside \[0, 359\.99\]"):
        lk.SingleTurnPositionV235(angle_deg=360.0, direction=SpinDirection.CLOCKWISE)
    beyond = lk.SingleTurnPosition(angle_deg=720.0, direction=SpinDirection.CLOCKWISE).encode()
    assert beyond == bytes.fromhex("A5 00 00 00 40 19 01 00")
    # V2.35 reads DATA[4..5] only (DATA[6..7] are NULL): 0x1940 = 64.64 degrees.
    assert lk.SingleTurnPositionV235.decode(beyond).angle_deg == 64.64
    with pytest.raises(ProtocolError, match=r"angle_deg=655\.35 is outside \[0, 359\.99\]"):
        lk.SingleTurnPositionV235.decode(bytes.fromhex("A5 00 00 00 FF FF 00 00"))


def test_layouts_match_the_spec_struct_formats() -> None:
    # Spec §13, rows for requests: each encoder produces exactly struct.pack(format, *fields).
    assert lk.TorqueControl(motor_type=MH, iq_counts=-5).encode() == struct.pack("<Bxxxhxx", 0xA1, -5)
    assert lk.OpenLoopControl(power_counts=7).encode() == struct.pack("<Bxxxhxx", 0xA0, 7)
    assert lk.SpeedControl(speed_dps=1.23, motor_type=MH, iq_limit_counts=-7).encode() == struct.pack(
        "<Bxhi", 0xA2, -7, 123
    )
    assert lk.SpeedControlV235(speed_dps=1.23).encode() == struct.pack("<Bxxxi", 0xA2, 123)
    assert lk.MultiTurnPosition(angle_deg=-1).encode() == struct.pack("<Bxxxi", 0xA3, -100)
    assert lk.IncrementalPosition(increment_deg=-1).encode() == struct.pack("<Bxxxi", 0xA7, -100)
    assert lk.MultiTurnPositionSpeed(angle_deg=2, max_speed_dps=9).encode() == struct.pack(
        "<BxHi", 0xA4, 9, 200
    )
    cw = SpinDirection.CLOCKWISE
    assert lk.SingleTurnPosition(angle_deg=3, direction=cw).encode() == struct.pack("<BBxxI", 0xA5, 0, 300)
    assert lk.SingleTurnPositionV235(angle_deg=3, direction=cw).encode() == struct.pack(
        "<BBxxHxx", 0xA5, 0, 300
    )
    assert lk.SingleTurnPositionSpeed(angle_deg=3, direction=cw, max_speed_dps=4).encode() == struct.pack(
        "<BBHI", 0xA6, 0, 4, 300
    )
    assert lk.SingleTurnPositionSpeedV235(angle_deg=3, direction=cw, max_speed_dps=4).encode() == struct.pack(
        "<BBHHxx", 0xA6, 0, 4, 300
    )
    assert lk.WriteEncoderOffset(offset_counts=9, encoder_bits=14).encode() == struct.pack(
        "<BxxxxxH", 0x91, 9
    )
    assert lk.WriteAcceleration(acceleration_dps2=-9).encode() == struct.pack("<Bxxxi", 0x34, -9)
    assert lk.BrakeControl(action=lk.BrakeAction.RELEASE).encode() == struct.pack("<BBxxxxxx", 0x8C, 1)
    assert lk.MultiMotorTorque(motor_type=MH, iq_counts=(1, 2, 3, 4)).encode() == struct.pack(
        "<hhhh", 1, 2, 3, 4
    )


MF_LIMIT = 2048 * 33 / 4096  # 16.5 A
MG_LIMIT = 2048 * 66 / 4096  # 33 A
OUT_OF_RANGE: list[tuple[str, Any, str, list[Any], str]] = [
    ("open loop", lambda v: lk.OpenLoopControl(power_counts=v), "power_counts", [851, -851], "850"),
    (
        "torque MF",
        lambda v: lk.TorqueControl(motor_type=MF, current_a=v),
        "current_a",
        [16.51, -16.51],
        "16.5",
    ),
    (
        "torque MG",
        lambda v: lk.TorqueControl(motor_type=MG, current_a=v),
        "current_a",
        [33.02, -33.02],
        "33.0",
    ),
    ("torque MH", lambda v: lk.TorqueControl(motor_type=MH, iq_counts=v), "iq_counts", [2049, -2049], "2048"),
    (
        "speed",
        lambda v: lk.SpeedControlV235(speed_dps=v),
        "speed_dps",
        [21474836.48, -21474836.49],
        "21474836.47",
    ),
    (
        "speed limit",
        lambda v: lk.SpeedControl(speed_dps=1, motor_type=MF, current_limit_a=v),
        "current_limit_a",
        [16.51],
        "16.5",
    ),
    ("multi-turn", lambda v: lk.MultiTurnPosition(angle_deg=v), "angle_deg", [21474836.48], "21474836.47"),
    (
        "max speed",
        lambda v: lk.MultiTurnPositionSpeed(angle_deg=0, max_speed_dps=v),
        "max_speed_dps",
        [65535.5, -0.6],
        "65535",
    ),
    (
        "single turn v2.35",
        lambda v: lk.SingleTurnPositionV235(angle_deg=v, direction=SpinDirection.CLOCKWISE),
        "angle_deg",
        [359.996, -0.006],
        "359.99",
    ),
    (
        "single turn v2.36",
        lambda v: lk.SingleTurnPosition(angle_deg=v, direction=SpinDirection.CLOCKWISE),
        "angle_deg",
        [42949672.96, -0.01],
        "42949672.95",
    ),
    (
        "increment",
        lambda v: lk.IncrementalPositionSpeed(increment_deg=v, max_speed_dps=1),
        "increment_deg",
        [-21474836.49],
        "-21474836.48",
    ),
    (
        "multi-motor",
        lambda v: lk.MultiMotorTorque(motor_type=MG, currents_a=(0, v, 0, 0)),
        "currents_a",
        [32.3],
        "32.2265625",
    ),
    (
        "encoder offset",
        lambda v: lk.WriteEncoderOffset(offset_counts=v, encoder_bits=14),
        "offset_counts",
        [16384, -1],
        "16383",
    ),
    (
        "acceleration",
        lambda v: lk.WriteAcceleration(acceleration_dps2=v),
        "acceleration_dps2",
        [2**31, float("nan")],
        "2147483647",
    ),
]


@pytest.mark.parametrize(
    ("factory", "field", "values", "limit"), [c[1:] for c in OUT_OF_RANGE], ids=[c[0] for c in OUT_OF_RANGE]
)
def test_out_of_range_raises_value_error_naming_field_and_limit(
    factory: Any, field: str, values: list[Any], limit: str
) -> None:
    for value in values:
        with pytest.raises(ValueError) as info:
            factory(value)
        assert f"{field}=" in str(info.value)
        assert limit in str(info.value)


def test_limits_are_inclusive() -> None:
    assert lk.TorqueControl(motor_type=MF, current_a=MF_LIMIT).encode()[4:6] == (2048).to_bytes(2, "little")
    assert lk.TorqueControl(motor_type=MG, current_a=-MG_LIMIT).encode()[4:6] == (-2048).to_bytes(
        2, "little", signed=True
    )
    assert lk.OpenLoopControl(power_counts=850).encode()[4:6] == (850).to_bytes(2, "little")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"motor_type": MS, "current_a": 1.0}, "motor_type=MS does not carry"),
        ({"motor_type": MH, "current_a": 1.0}, "current_a=1.0 given for motor_type=MH, which uses iq_counts"),
        ({"motor_type": MF, "iq_counts": 5}, "iq_counts=5 given for motor_type=MF, which uses current_a"),
        ({"motor_type": MF}, "current_a is required for motor_type=MF"),
        ({"motor_type": "MF", "current_a": 1.0}, "motor_type='MF' is not one of"),
        ({"motor_type": MF, "current_a": "1"}, "current_a='1' is not a number"),
    ],
)
def test_torque_control_takes_the_field_of_its_motor_type(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        lk.TorqueControl(**kwargs)


def test_typed_choices_refuse_bare_values() -> None:
    with pytest.raises(ValueError, match="direction=1 is not one of SpinDirection"):
        lk.SingleTurnPosition(angle_deg=0, direction=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="action=16 is not one of BrakeAction"):
        lk.BrakeControl(action=0x10)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="encoder_bits=17 is not one of 14, 15, 16, 18"):
        lk.WriteEncoderOffset(offset_counts=0, encoder_bits=17)
    with pytest.raises(ValueError, match="not a tuple of 4"):
        lk.MultiMotorTorque(motor_type=MF, currents_a=(1.0, 2.0))  # type: ignore[arg-type]


@pytest.mark.parametrize("bits", [14, 15, 16, 18])
def test_encoder_offset_range_follows_the_encoder_width(bits: int) -> None:
    top = (1 << min(bits, 16)) - 1
    assert lk.WriteEncoderOffset(offset_counts=top, encoder_bits=bits).offset_counts == top
    if bits < 16:
        with pytest.raises(ValueError, match=f"offset_counts={top + 1} is outside \\[0, {top}\\]"):
            lk.WriteEncoderOffset(offset_counts=top + 1, encoder_bits=bits)


@pytest.mark.parametrize(
    ("cls", "data", "message"),
    [
        (lk.MotorOff, "80 00 00 00 00 00 00", "expected 8 data bytes, got 7"),
        (lk.MotorOff, "81 00 00 00 00 00 00 00", "command byte is not 0x80"),
        (lk.BrakeControl, "8C 02 00 00 00 00 00 00", r"DATA\[1\]=0x02 is not a BrakeAction"),
        (lk.SingleTurnPosition, "A5 02 00 00 00 00 00 00", r"DATA\[1\]=0x02 is not a SpinDirection"),
        (lk.WriteEncoderOffset, "91 00 00 00 00 00 00 40", "offset_counts=16384 is outside"),
        (lk.MultiMotorTorque, "00 00 00 00 00 00 00", "expected 8 data bytes"),
        (lk.MultiMotorTorque, "D1 07 00 00 00 00 00 00", "motor 1: currents_a"),
        (lk.TorqueControl, "A1 00 00 00 01 08 00 00", "current_a"),
    ],
)
def test_request_decoders_raise_protocol_errors(cls: Any, data: str, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        cls.decode(bytes.fromhex(data))


def test_request_decoders_ignore_null_bytes() -> None:
    # Spec §0: a decoder should not rely on NULL bytes; re-encoding writes them as 0x00.
    decoded = lk.MotorStop.decode(bytes.fromhex("81 FF FF FF FF FF FF FF"))
    assert decoded == lk.MotorStop()
    assert decoded.encode() == bytes.fromhex("81 00 00 00 00 00 00 00")
    torque = lk.TorqueControl.decode(bytes.fromhex("A1 AA BB CC 10 00 DD EE"), model=LkModel(motor_type=MH))
    assert torque == lk.TorqueControl(motor_type=MH, iq_counts=16)


def test_multi_motor_decodes_with_the_models_motor_type() -> None:
    data = bytes.fromhex("00 01 00 00 00 00 00 FF")
    mg = lk.MultiMotorTorque.decode(data, model=LkModel(revision=lk.Revision.V2_35, motor_type=MG))
    assert mg.currents_a == (256 * 66 / 4096, 0.0, 0.0, -256 * 66 / 4096)
    with pytest.raises(ProtocolError, match="MS does not carry"):
        lk.MultiMotorTorque.decode(data, model=LkModel(motor_type=MS))

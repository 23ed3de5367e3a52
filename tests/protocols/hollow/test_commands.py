"""Classic-CAN requests: special commands, setpoints, the mode switch, PI multipliers (hollow.md §4-§6)."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    CanMode,
    CanModeSwitch,
    ControlMode,
    HollowModel,
    IncrementalSetpoint,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    SpecialCommand,
    Start,
    Stop,
)
from servobus.protocols.hollow.commands import decode_extended_request, decode_special, is_special_command

from .._contract import assert_quantised
from ._strategies import (
    MODELS,
    incremental_setpoints,
    mode_switches,
    pi_multipliers,
    setpoints,
    special_commands,
)

SPECIAL = b"\xff" * 7


def _resolutions(model: HollowModel) -> tuple[float, float, float]:
    return (
        2 * model.position_full_scale_deg / 0x10000,
        2 * model.speed_full_scale_rad_s / 0x1000,
        2 * model.current_full_scale_a / 0x1000,
    )


def _was_lowered(frame: bytes) -> bool:
    """The packer lowered P from 0xFFFF to 0xFFFE to leave the special pattern (§4.1, A35)."""
    return frame[:2] == b"\xff\xfe" and frame[2:7] == b"\xff" * 5 and 0xF9 <= frame[7] <= 0xFE


# ---- special commands ----


@given(special_commands)
def test_special_commands_round_trip(command: SpecialCommand) -> None:
    frame = command.encode()
    assert frame[:7] == SPECIAL and is_special_command(frame)
    assert decode_special(frame) == command
    assert type(command).decode(frame) == command


@pytest.mark.parametrize(
    ("code", "command"),
    [
        (0xF9, SelectMode(mode=ControlMode.TORQUE)),
        (0xFA, SelectMode(mode=ControlMode.VELOCITY)),
        (0xFB, SelectMode(mode=ControlMode.POSITION)),
        (0xFC, Start()),
        (0xFD, Stop()),
        (0xFE, SetZero()),
    ],
)
def test_special_codes(code: int, command: SpecialCommand) -> None:
    assert command.encode() == SPECIAL + bytes([code])
    assert command.special_code == code


@pytest.mark.parametrize("code", [0x00, 0xF8, 0xFF])
def test_codes_outside_f9_fe_are_not_special(code: int) -> None:
    frame = SPECIAL + bytes([code])
    assert not is_special_command(frame)
    with pytest.raises(ProtocolError, match="not a special command"):
        decode_special(frame)
    # ... so they are setpoints.
    assert isinstance(Setpoint.decode(frame), Setpoint)


def test_special_decode_checks_length_and_class() -> None:
    with pytest.raises(ProtocolError, match="expected 8 data bytes, got 7"):
        decode_special(SPECIAL)
    with pytest.raises(ProtocolError, match="0xFC is not Stop"):
        Stop.decode(SPECIAL + b"\xfc")


def test_select_mode_validates() -> None:
    assert SelectMode(mode=2).mode is ControlMode.POSITION  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"mode=3 is not one of TORQUE=0, VELOCITY=1, POSITION=2"):
        SelectMode(mode=3)  # type: ignore[arg-type]


# ---- setpoints ----


@given(setpoints())
def test_setpoint_round_trip_is_quantisation(command: Setpoint) -> None:
    frame = command.encode()
    assert not is_special_command(frame)
    decoded = Setpoint.decode(frame, model=command.model)
    p_res, v_res, i_res = _resolutions(command.model)
    # One position code lower when the special pattern had to be avoided.
    tolerance = 3 * p_res if _was_lowered(frame) else p_res
    assert_quantised(decoded.position_deg, command.position_deg, tolerance, field="position_deg")
    assert_quantised(decoded.speed_rad_s, command.speed_rad_s, v_res, field="speed_rad_s")
    assert_quantised(decoded.current_a, command.current_a, i_res, field="current_a")
    assert (decoded.kp, decoded.kd, decoded.model) == (command.kp, command.kd, command.model)
    assert decoded.encode() == frame


@given(incremental_setpoints())
def test_incremental_setpoint_round_trip_is_quantisation(command: IncrementalSetpoint) -> None:
    frame = command.encode()
    decoded = IncrementalSetpoint.decode(frame, model=command.model)
    p_res, v_res, i_res = _resolutions(command.model)
    tolerance = 3 * p_res if _was_lowered(frame) else p_res
    assert_quantised(decoded.step_deg, command.step_deg, tolerance, field="step_deg")
    assert_quantised(decoded.speed_rad_s, command.speed_rad_s, v_res, field="speed_rad_s")
    assert_quantised(decoded.current_a, command.current_a, i_res, field="current_a")
    assert decoded.encode() == frame


def test_incremental_setpoint_shares_the_setpoint_bytes() -> None:
    absolute = Setpoint(position_deg=90.0, speed_rad_s=10.0, kp=1, kd=2, current_a=1.0)
    step = IncrementalSetpoint(step_deg=90.0, speed_rad_s=10.0, kp=1, kd=2, current_a=1.0)
    assert absolute.encode() == step.encode() == bytes.fromhex("A0 00 86 60 01 00 2A 00")


@pytest.mark.parametrize("torque_code", range(0xFF9, 0xFFF))
def test_setpoint_never_encodes_a_special_command(torque_code: int) -> None:
    # §4.1 collision: P = 0xFFFF, V = KP = KD = 0xFFF, T = 0xFF9..0xFFE would read as FF x7 + F9..FE.
    model = DEFAULT_MODEL
    current = (torque_code - 0x800) / 0x800 * model.current_full_scale_a
    command = Setpoint(position_deg=360.0, speed_rad_s=200.0, kp=0xFFF, kd=0xFFF, current_a=current)
    frame = command.encode()
    assert frame == bytes.fromhex("FF FE FF FF FF FF FF") + bytes([torque_code & 0xFF])
    assert not is_special_command(frame)
    # One code below the top: P = 0xFFFE is 360 * (0x7FFE / 0x8000) degrees.
    assert Setpoint.decode(frame).position_deg == 360.0 * 0x7FFE / 0x8000


@pytest.mark.parametrize("code", range(0xF9, 0xFF))
def test_a_special_pattern_never_decodes_as_a_setpoint(code: int) -> None:
    frame = SPECIAL + bytes([code])
    with pytest.raises(ProtocolError, match="special command"):
        Setpoint.decode(frame)
    with pytest.raises(ProtocolError, match="special command"):
        IncrementalSetpoint.decode(frame)


def test_the_max_setpoint_without_collision_keeps_p_ffff() -> None:
    # T = 0xFFF (not F9..FE): FF x8 is a legitimate setpoint, not a special command.
    command = Setpoint(position_deg=360.0, speed_rad_s=200.0, kp=0xFFF, kd=0xFFF, current_a=4.0)
    assert command.encode() == b"\xff" * 8
    assert Setpoint.decode(b"\xff" * 8).kp == 0xFFF


def test_plus_full_scale_clamps_to_the_last_code() -> None:
    # §4.3: +full scale is 2**n, one code past the last; it is clamped (+200 rad/s -> 0xFFF).
    frame = Setpoint(position_deg=360.0, speed_rad_s=200.0, kp=0, kd=0, current_a=4.0).encode()
    assert frame == bytes.fromhex("FF FF FF F0 00 00 0F FF")
    frame = Setpoint(position_deg=-360.0, speed_rad_s=-200.0, kp=0, kd=0, current_a=-4.0).encode()
    assert frame == bytes.fromhex("00 00 00 00 00 00 00 00")


def test_setpoint_scales_with_the_model() -> None:
    model = HollowModel(pmax_turns=2.0, speed_full_scale_rad_s=50.0, current_full_scale_a=10.0)
    command = Setpoint(position_deg=360.0, speed_rad_s=25.0, kp=0x100, kd=0x020, current_a=5.0, model=model)
    assert command.encode() == bytes.fromhex("C0 00 C0 01 00 02 0C 00")
    assert Setpoint.decode(command.encode(), model=model) == command


def _just_outside(limit: float) -> float:
    return math.nextafter(limit, math.copysign(math.inf, limit))


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
@pytest.mark.parametrize("sign", [1, -1])
@pytest.mark.parametrize(
    ("field", "limit_of"),
    [
        ("position_deg", lambda m: m.position_full_scale_deg),
        ("speed_rad_s", lambda m: m.speed_full_scale_rad_s),
        ("current_a", lambda m: m.current_full_scale_a),
    ],
)
def test_setpoint_values_just_outside_raise(
    model: HollowModel, sign: int, field: str, limit_of: object
) -> None:
    limit = sign * limit_of(model)  # type: ignore[operator]
    values: dict[str, object] = {"position_deg": 0.0, "speed_rad_s": 0.0, "kp": 0, "kd": 0, "current_a": 0.0}
    values[field] = limit
    Setpoint(**values, model=model)  # type: ignore[arg-type]
    values[field] = _just_outside(limit)
    # (the limits come from the model, and the error names it)
    where = rf"\[-{abs(limit)!r}, {abs(limit)!r}\] for model {model.name}$"
    with pytest.raises(ValueError, match=rf"^{field}=.* is outside {where}"):
        Setpoint(**values, model=model)  # type: ignore[arg-type]


@pytest.mark.parametrize(("field", "value"), [("kp", 4096), ("kp", -1), ("kd", 4096), ("kd", -1)])
def test_setpoint_gains_outside_raise(field: str, value: int) -> None:
    values: dict[str, object] = {"position_deg": 0.0, "speed_rad_s": 0.0, "kp": 0, "kd": 0, "current_a": 0.0}
    values[field] = value
    with pytest.raises(ValueError, match=rf"^{field}={value} is outside \[0, 4095\]$"):
        Setpoint(**values)  # type: ignore[arg-type]


def test_incremental_setpoint_names_its_step_field() -> None:
    message = r"^step_deg=361\.0 is outside \[-360\.0, 360\.0\] for model default$"
    with pytest.raises(ValueError, match=message):
        IncrementalSetpoint(step_deg=361.0, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), "1", True, None])
def test_setpoint_rejects_non_numbers(bad: object) -> None:
    with pytest.raises(ValueError, match="position_deg="):
        Setpoint(position_deg=bad, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0)  # type: ignore[arg-type]


def test_setpoint_rejects_a_non_model() -> None:
    with pytest.raises(ValueError, match="is not a HollowModel"):
        Setpoint(position_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0, model="x")  # type: ignore[arg-type]


def test_setpoint_decode_checks_length() -> None:
    with pytest.raises(ProtocolError, match="setpoint: expected 8 data bytes, got 6"):
        Setpoint.decode(bytes(6))


# ---- mode switch and PI multipliers ----


@given(mode_switches)
def test_mode_switch_round_trip(command: CanModeSwitch) -> None:
    assert command.EXTENDED_ID
    frame = command.encode()
    assert len(frame) == 8 and frame[1:] == bytes(7)
    assert CanModeSwitch.decode(frame) == command
    assert decode_extended_request(frame) == command


def test_mode_switch_bit() -> None:
    assert CanModeSwitch(mode=CanMode.EXTENDED).encode() == bytes(8)
    assert CanModeSwitch(mode=CanMode.NORMAL).encode() == b"\x02" + bytes(7)
    with pytest.raises(ValueError, match="mode=5 is not one of EXTENDED=0, NORMAL=1"):
        CanModeSwitch(mode=5)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "frame",
    [
        "01 00 00 00 00 00 00 00",
        "04 00 00 00 00 00 00 00",
        "80 00 00 00 00 00 00 00",
        "02 00 00 01 00 00 00 00",
    ],
)
def test_mode_switch_refuses_reserved_bits(frame: str) -> None:
    with pytest.raises(ProtocolError, match="reserved bits are not zero"):
        CanModeSwitch.decode(bytes.fromhex(frame))


def test_mode_switch_is_not_a_pi_frame() -> None:
    with pytest.raises(ProtocolError, match="is a PI multiplier frame"):
        CanModeSwitch.decode(bytes.fromhex("00 03 3F 80 00 00 00 00"))
    with pytest.raises(ProtocolError, match="expected 8 data bytes, got 6"):
        CanModeSwitch.decode(bytes(6))


@given(pi_multipliers)
def test_pi_multiplier_round_trip(command: PiMultiplier) -> None:
    assert command.EXTENDED_ID
    frame = command.encode()
    assert frame[:2] == bytes([0, command.gain]) and frame[6:] == b"\x00\x00"
    assert PiMultiplier.decode(frame) == command
    assert decode_extended_request(frame) == command
    # A17: DLC 6 (no padding) and DLC 7 decode the same.
    assert PiMultiplier.decode(frame[:6]) == command
    assert PiMultiplier.decode(frame[:7]) == command


@given(st.floats(min_value=0.0, max_value=1e30, allow_nan=False))
def test_pi_multiplier_quantises_to_float32(value: float) -> None:
    decoded = PiMultiplier.decode(PiMultiplier(gain=PiGain.CURRENT_KI, multiplier=value).encode())
    assert decoded.multiplier == struct.unpack(">f", struct.pack(">f", value))[0]


@pytest.mark.parametrize("value", [-1e-45, -1.0, 3.5e38, float("nan"), float("inf")])
def test_pi_multiplier_range(value: float) -> None:
    with pytest.raises(ValueError, match=r"^multiplier=.* is outside \[0\.0, 3\.4028234663852886e\+38\]$"):
        PiMultiplier(gain=PiGain.SPEED_KP, multiplier=value)


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        ("00 01 3F 80 00", "expected 6 to 8 data bytes, got 5"),
        ("00 01 3F 80 00 00 00 00 00", "expected 6 to 8 data bytes, got 9"),
        ("01 01 3F 80 00 00", r"DATA\[0\] is not 0x00"),
        ("00 05 3F 80 00 00", "gain=0x05 is not one of PiGain"),
        ("00 01 7F C0 00 00", "multiplier=nan"),
        ("00 01 BF 80 00 00", r"multiplier=-1\.0 is outside"),
    ],
)
def test_pi_multiplier_decode_errors(frame: str, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        PiMultiplier.decode(bytes.fromhex(frame))


def test_a_member_of_another_enum_is_refused() -> None:
    with pytest.raises(ValueError, match=r"mode=<CanMode\.NORMAL: 1> is not one of TORQUE, VELOCITY"):
        SelectMode(mode=CanMode.NORMAL)  # type: ignore[arg-type]

"""CAN motion (MIT) mode (motion.py): ranges per revision, packing through the C core, limits."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from _scales import MIT_V43
from servobus.errors import ProtocolError
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.motion import command_packer, reply_packer

from .._contract import assert_quantised

V43 = ma.MOTION_SCALES[ma.Revision.V4_3]
V44 = ma.MOTION_SCALES[ma.Revision.V4_4]
EXAMPLE = bytes.fromhex("E6 66 82 E0 52 33 3B 55")  # §5.6, both manuals


def test_v43_scales_are_the_ones_the_core_tests_use() -> None:
    assert list(V43.command_scales()) == MIT_V43


def test_revision_defaults() -> None:
    # §5.5 / §9 item 24: V4.4 defaults p ±12.566, kd 0..50; t ±Motor Max Torque (24 N·m unless given).
    assert ma.MotionScales(p_max_rad=12.566, v_max_rad_s=45, kp_max=500, kd_max=50, t_max_nm=24) == V44
    assert ma.MotionScales.for_revision(ma.Revision.V4_4) is V44
    assert ma.MotionScales.for_revision(ma.Revision.V4_4, max_torque_nm=33.0).t_max_nm == 33.0
    with pytest.raises(ValueError, match=r"V4\.3 fixes the motion torque range"):
        ma.MotionScales.for_revision(ma.Revision.V4_3, max_torque_nm=33.0)
    with pytest.raises(ValueError, match="kd_max=0 must be a positive finite number"):
        ma.MotionScales(p_max_rad=1, v_max_rad_s=1, kp_max=1, kd_max=0, t_max_nm=1)
    assert ma.MotionCommand(position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0).scales is V44


def test_packers_are_built_once_per_scales() -> None:
    assert command_packer(V43) is command_packer(ma.MotionScales.for_revision(ma.Revision.V4_3))
    assert reply_packer(V44) is reply_packer(V44)
    assert reply_packer(V44).stride == 8


def test_worked_example_per_revision() -> None:
    """§5.6: the same bytes mean kd 1.0 under V4.3 and 10.0 under V4.4, p 10.0002 or 10.053 rad."""
    v43 = ma.MotionCommand.decode(EXAMPLE, V43)
    assert (v43.position_rad, v43.kd, v43.torque_ff_nm) == pytest.approx((10.0002, 1.0, 10.0044), abs=1e-4)
    v44 = ma.MotionCommand.decode(EXAMPLE, V44)
    assert (v44.position_rad, v44.kd, v44.torque_ff_nm / 24) == pytest.approx(
        (10.053, 10.0, 0.41685), abs=1e-3
    )
    assert (
        ma.MotionCommand(
            position_rad=10.0,
            velocity_rad_s=v43.velocity_rad_s,
            kp=10.0,
            kd=1.0,
            torque_ff_nm=10.0,
            scales=V43,
        ).encode()
        == EXAMPLE
    )


@pytest.mark.parametrize(
    ("field", "value", "limits"),
    [
        ("position_rad", 12.51, "[-12.5, 12.5]"),
        ("position_rad", -12.51, "[-12.5, 12.5]"),
        ("velocity_rad_s", 45.1, "[-45.0, 45.0]"),
        ("kp", -0.1, "[0.0, 500.0]"),
        ("kd", 5.01, "[0.0, 5.0]"),
        ("torque_ff_nm", -24.5, "[-24.0, 24.0]"),
        ("torque_ff_nm", float("nan"), "[-24.0, 24.0]"),
    ],
)
def test_out_of_range_names_field_and_limits(field: str, value: float, limits: str) -> None:
    values = {
        "position_rad": 0.0,
        "velocity_rad_s": 0.0,
        "kp": 0.0,
        "kd": 0.0,
        "torque_ff_nm": 0.0,
        field: value,
    }
    with pytest.raises(ValueError, match=rf"{field}=.* is outside \{limits[:-1]}\]"):
        ma.MotionCommand(**values, scales=V43)


def test_v44_accepts_what_v43_refuses() -> None:
    ma.MotionCommand(position_rad=12.566, velocity_rad_s=0, kp=0, kd=50, torque_ff_nm=0)
    with pytest.raises(ValueError, match="kd=50"):
        ma.MotionCommand(position_rad=0, velocity_rad_s=0, kp=0, kd=50, torque_ff_nm=0, scales=V43)


def test_reply_layout_and_checks() -> None:
    reply = ma.MotionReply.decode(bytes.fromhex("01 E6 66 82 EB 55 00 00"), V43)
    assert reply.motor_id == 1
    assert (reply.position_rad, reply.velocity_rad_s, reply.torque_nm) == pytest.approx(
        (10.0002, 1.02198, 10.0044), abs=1e-4
    )
    assert reply.encode() == bytes.fromhex("01 E6 66 82 EB 55 00 00")
    # DATA[6..7] are NULL: ignored on decode.
    assert ma.MotionReply.decode(bytes.fromhex("01 E6 66 82 EB 55 FF FF"), V43) == reply
    with pytest.raises(ProtocolError, match="DATA\\[0\\]=0 is not a motor id"):
        ma.MotionReply.decode(bytes.fromhex("00 E6 66 82 EB 55 00 00"), V43)
    with pytest.raises(ProtocolError, match="expected 8 data bytes, got 6"):
        ma.MotionReply.decode(bytes.fromhex("01 E6 66 82 EB 55"), V43)
    with pytest.raises(ValueError, match=r"motor_id=33 is outside \[1, 32\]"):
        ma.MotionReply(motor_id=33, position_rad=0, velocity_rad_s=0, torque_nm=0)


@pytest.mark.parametrize("scales", [V43, V44], ids=["V4_3", "V4_4"])
@pytest.mark.parametrize("data", ["FF FF FF FF FF FF FF FF", "00 00 00 00 00 00 00 00"])
def test_end_codes_decode_inside_the_range(scales: ma.MotionScales, data: str) -> None:
    """The top code maps to hi (an ulp over for ±12.566 before clamping): any frame decodes."""
    command = ma.MotionCommand.decode(bytes.fromhex(data), scales)
    assert command.encode() == bytes.fromhex(data)
    assert abs(command.position_rad) == scales.p_max_rad


@given(st.floats(-12.566, 12.566), st.floats(0.0, 50.0))
def test_quantisation_is_one_code(p: float, kd: float) -> None:
    command = ma.MotionCommand(position_rad=p, velocity_rad_s=0, kp=0, kd=kd, torque_ff_nm=0)
    decoded = ma.MotionCommand.decode(command.encode(), V44)
    assert_quantised(decoded.position_rad, p, V44.resolution("position_rad"), field="position_rad")
    assert_quantised(decoded.kd, kd, V44.resolution("kd"), field="kd")
    assert V44.resolution("kd") == 50 / 4095


def test_resolution_of_an_unknown_field() -> None:
    with pytest.raises(KeyError):
        V44.resolution("speed_dps")

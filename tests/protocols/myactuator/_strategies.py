"""Hypothesis strategies for every MyActuator message class, derived from the classes' own field specs.

A class declares its layout once (``FIELDS``); the strategy for each field follows from the field's kind
and limits, so a new field is covered without touching the tests. Classes whose fields are not all
declared that way (0x20's per-index value, motion mode's scales, ``Echo``) have a strategy here.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from enum import IntEnum
from typing import Any

from hypothesis import strategies as st

from servobus.protocols import Message
from servobus.protocols import myactuator as ma
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator._layout import (
    AsciiField,
    BoolField,
    EnumField,
    FlagsField,
    Float32Field,
    OpenEnumField,
    StepField,
)
from servobus.protocols.myactuator.codec import ECHO_COMMANDS
from servobus.protocols.myactuator.rs485_motion import RS485_MOTION_BROADCAST_ID

from .._contract import assert_quantised

FLOAT32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]


def float32(value: float) -> float:
    result: float = struct.unpack("<f", struct.pack("<f", value))[0]
    return result


def field_strategy(spec: Any) -> st.SearchStrategy[Any]:
    """Any valid value of one field."""
    if isinstance(spec, SpecialZero):  # the explicit None, or a number off the special code
        numbers = field_strategy(spec.inner).filter(lambda v: spec.code_of(v) != spec.raw)
        return st.one_of(st.none(), numbers) if spec.explicit else numbers
    if isinstance(spec, ScaledField):
        lo, hi = spec.limits
        return st.floats(min_value=lo, max_value=hi, allow_nan=False)
    if isinstance(spec, IntField):
        return st.integers(*spec.limits)
    if isinstance(spec, EnumField):
        return st.sampled_from(list(spec.enum))
    if isinstance(spec, OpenEnumField):
        return st.integers(0, (1 << (8 * spec.size)) - 1).map(lambda c: _maybe_enum(spec.enum, c))
    if isinstance(spec, FlagsField):
        return st.integers(0, (1 << (8 * spec.size)) - 1).map(spec.flags)
    if isinstance(spec, BoolField):
        return st.booleans()
    if isinstance(spec, Float32Field):
        return st.floats(min_value=-FLOAT32_MAX, max_value=FLOAT32_MAX, allow_nan=False)
    if isinstance(spec, AsciiField):
        alphabet = st.characters(min_codepoint=0x20, max_codepoint=0x7E)
        return st.text(alphabet, max_size=spec.size).filter(lambda s: s == s.rstrip(" "))
    if isinstance(spec, StepField):
        return st.integers(*spec.limits)
    raise TypeError(f"no strategy for field spec {spec!r}")


def _maybe_enum(enum: type[IntEnum], code: int) -> IntEnum | int:
    try:
        return enum(code)
    except ValueError:
        return code


def minimal_value(spec: Any) -> Any:
    """A valid value of one field, chosen without randomness (the low end of its range)."""
    if isinstance(spec, SpecialZero):
        if spec.explicit:
            return None
        return spec.raw + 1 if isinstance(spec.inner, IntField) else (spec.raw + 1) * spec.resolution
    if isinstance(spec, ScaledField | IntField | StepField):
        return spec.limits[0]
    if isinstance(spec, EnumField | OpenEnumField):
        return next(iter(spec.enum))
    if isinstance(spec, FlagsField):
        return spec.flags(0)
    if isinstance(spec, BoolField):
        return False
    if isinstance(spec, Float32Field):
        return 0.0
    if isinstance(spec, AsciiField):
        return ""
    raise TypeError(f"no value for field spec {spec!r}")


def fixed_strategy(cls: type, **overrides: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    specs = cls.field_specs()  # type: ignore[attr-defined]
    kwargs = {name: field_strategy(spec) for name, spec in specs.items()}
    kwargs.update(overrides)
    return st.builds(cls, **kwargs)


def _function_control() -> st.SearchStrategy[ma.FunctionControl]:
    def build(index: ma.FunctionIndex) -> st.SearchStrategy[ma.FunctionControl]:
        meaning = ma.FUNCTION_VALUES[index]
        return st.builds(ma.FunctionControl, index=st.just(index), value=st.integers(meaning.lo, meaning.hi))

    return st.sampled_from(list(ma.FunctionIndex)).flatmap(build)


_ACCELERATION = st.one_of(
    st.floats(min_value=0.0, max_value=0.49),  # quantises to 0: "no planning"
    st.floats(min_value=100.0, max_value=60000.0),
)
# The 0x43 request asks for "no planning" only with None (issue 19).
_ACCELERATION_WRITE = st.one_of(st.none(), st.floats(min_value=99.5, max_value=60000.0))


def _active_reply() -> st.SearchStrategy[ma.ActiveReply]:
    # An enabled stream needs an interval of at least one 10 ms step; None only disables.
    interval = field_strategy(ma.ActiveReply.field_specs()["interval_ms"])
    return st.booleans().flatmap(
        lambda enabled: st.builds(
            ma.ActiveReply,
            command=st.sampled_from(list(ma.StreamableCommand)),
            enabled=st.just(enabled),
            interval_ms=interval.filter(lambda v: v is not None) if enabled else interval,
        )
    )


scales_strategy = st.one_of(
    st.sampled_from(list(ma.MOTION_SCALES.values())),
    st.floats(min_value=1.0, max_value=200.0).map(
        lambda t: ma.MotionScales.for_revision(ma.Revision.V4_4, max_torque_nm=t)
    ),
)


def _motion_command(scales: ma.MotionScales) -> st.SearchStrategy[ma.MotionCommand]:
    return st.builds(
        ma.MotionCommand,
        position_rad=st.floats(-scales.p_max_rad, scales.p_max_rad),
        velocity_rad_s=st.floats(-scales.v_max_rad_s, scales.v_max_rad_s),
        kp=st.floats(0.0, scales.kp_max),
        kd=st.floats(0.0, scales.kd_max),
        torque_ff_nm=st.floats(-scales.t_max_nm, scales.t_max_nm),
        scales=st.just(scales),
    )


def _motion_reply(scales: ma.MotionScales) -> st.SearchStrategy[ma.MotionReply]:
    return st.builds(
        ma.MotionReply,
        motor_id=st.integers(1, 32),
        position_rad=st.floats(-scales.p_max_rad, scales.p_max_rad),
        velocity_rad_s=st.floats(-scales.v_max_rad_s, scales.v_max_rad_s),
        torque_nm=st.floats(-scales.t_max_nm, scales.t_max_nm),
        scales=st.just(scales),
    )


SPECIAL: dict[type, Callable[[], st.SearchStrategy[Any]]] = {
    ma.FunctionControl: _function_control,
    ma.WriteAcceleration: lambda: fixed_strategy(
        ma.WriteAcceleration, acceleration_dps_s=_ACCELERATION_WRITE
    ),
    ma.ActiveReply: _active_reply,
    ma.AccelerationReply: lambda: fixed_strategy(ma.AccelerationReply, acceleration_dps_s=_ACCELERATION),
    ma.CanIdReply: lambda: fixed_strategy(ma.CanIdReply, layout=st.sampled_from(list(ma.CanIdLayout))),
    ma.MotionCommand: lambda: scales_strategy.flatmap(_motion_command),
    ma.MotionReply: lambda: scales_strategy.flatmap(_motion_reply),
    ma.Rs485MotionCommand: lambda: fixed_strategy(
        ma.Rs485MotionCommand,
        motor_id=st.one_of(st.integers(1, 32), st.just(RS485_MOTION_BROADCAST_ID)),
    ),
    ma.Echo: lambda: (
        st.sampled_from(ECHO_COMMANDS).flatmap(message_strategy).map(lambda command: ma.Echo(command=command))
    ),
}


def message_strategy(cls: type) -> st.SearchStrategy[Any]:
    """Any valid instance of a MyActuator message class."""
    special = SPECIAL.get(cls)
    if special is not None:
        return special()
    return fixed_strategy(cls)


def message_classes() -> list[type[Message]]:
    """Every concrete message class the package exports (bases excluded)."""
    bases = {ma.MyActuatorCommand, ma.MyActuatorReply}
    found = []
    for name in ma.__all__:
        obj = getattr(ma, name)
        if isinstance(obj, type) and issubclass(obj, Message) and obj not in bases:
            found.append(obj)
    return found


def assert_field_quantised(spec: Any, decoded: Any, given: Any, *, field: str) -> None:
    """``decoded`` is ``given`` quantised to the field's resolution."""
    if isinstance(spec, SpecialZero):
        if given is None:
            assert decoded is None, f"{field}: None decoded as {decoded!r}"
            return
        spec = spec.inner
    if isinstance(spec, ScaledField | StepField):
        assert_quantised(decoded, given, spec.resolution, field=field)
    elif isinstance(spec, Float32Field):
        assert decoded == float32(given), f"{field}: {given!r} decoded as {decoded!r}"
    else:
        assert decoded == given, f"{field}: {given!r} decoded as {decoded!r}"
        assert type(decoded) is type(given) or not isinstance(given, IntEnum), field


def assert_round_trip(message: Any, decode: Callable[[bytes], Any]) -> None:
    """decode(encode(m)) is m quantised field by field, and re-encodes to the same bytes."""
    data = message.encode()
    decoded = decode(data)
    assert type(decoded) is type(message)
    assert decoded.encode() == data
    assert_quantised_message(decoded, message)


MOTION_FIELDS = (
    "position_rad",
    "velocity_rad_s",
    "kp",
    "kd",
    "torque_ff_nm",
    "position_rad",
    "velocity_rad_s",
    "torque_nm",
)


def assert_quantised_message(decoded: Any, given: Any) -> None:
    if isinstance(given, ma.Echo):
        assert_quantised_message(decoded.command, given.command)
        return
    if isinstance(given, ma.MotionCommand | ma.MotionReply):
        assert decoded.scales == given.scales
        for name in (
            "position_rad",
            "velocity_rad_s",
            "kp",
            "kd",
            "torque_ff_nm",
            "position_rad",
            "velocity_rad_s",
            "torque_nm",
        ):
            if hasattr(given, name):
                resolution = given.scales.resolution(name)
                assert_quantised(getattr(decoded, name), getattr(given, name), resolution, field=name)
        if isinstance(given, ma.MotionReply):
            assert decoded.motor_id == given.motor_id
        return
    if isinstance(given, ma.FunctionControl):
        assert (decoded.index, decoded.value) == (given.index, given.value)
        return
    if isinstance(given, ma.CanIdReply):
        assert (decoded.motor_id, decoded.layout) == (given.motor_id, given.layout)
        return
    for name, spec in type(given).field_specs().items():
        assert_field_quantised(spec, getattr(decoded, name), getattr(given, name), field=name)

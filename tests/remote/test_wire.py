"""servobus.remote.wire: every family's messages survive the trip; nothing else becomes a command."""

from __future__ import annotations

import contextlib
import enum
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import MotorBusy, MotorFault, MotorTimeout, ProtocolError
from servobus.protocols import get_family
from servobus.protocols import lk as lk_family
from servobus.protocols import myactuator as ma
from servobus.remote import wire

FAMILIES = ("myactuator", "lk", "hollow")
CLIENT = "0123456789abcdef0123456789abcdef"


def _built(family: str) -> list[object]:
    """One instance of every command of ``family`` that builds with its defaults."""
    out = []
    for cls in get_family(family).commands:
        try:
            out.append(cls())
        except (TypeError, ValueError):
            continue
    return out


def _round(schema: wire.Schema, value: object) -> object:
    out = bytearray()
    wire.encode_value(schema, value, out)
    reader = wire._Reader(bytes(out))
    back = wire.decode_value(schema, reader)
    reader.end()
    return back


@pytest.mark.parametrize("family", FAMILIES)
def test_commands_round_trip(family: str) -> None:
    schema = wire.Schema.of(family)
    built = _built(family)
    assert built
    for command in built:
        assert _round(schema, command) == command


def test_values_with_fields_round_trip() -> None:
    schema = wire.Schema.of("myactuator")
    for command in (
        ma.SpeedControl(speed_dps=-123.25),
        ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10),
        ma.ReadStatus2(),
    ):
        assert _round(schema, command) == command
    reply = ma.StatusReply(
        temperature_c=50,
        current_a=1.0,
        speed_dps=500.0,
        angle_deg=45.0,
        command=ma.StatusCommand.SPEED_CONTROL,
    )
    state = wire.State(3, time.time_ns(), True, reply, ma.ErrorFlags(0))
    assert wire.decode_state(schema, wire.encode_state(schema, state)) == state
    assert wire.peek_motor(wire.encode_state(schema, state)) == 3


def test_nested_values_of_lk() -> None:
    """A dataclass in a field (PID gains) and tuples (four motors' currents) survive the trip."""
    from servobus.protocols.lk.params import PidGains

    schema = wire.Schema.of("lk")
    for command in (
        lk_family.WriteParamRam(param=lk_family.ParamId.ANGLE_PID, value=PidGains(kp=100, ki=20, kd=3)),
        lk_family.MultiMotorTorque(motor_type=lk_family.MotorType.MF, currents_a=(0.5, -0.5, 0.0, 1.0)),
    ):
        assert _round(schema, command) == command


def test_setpoints_round_trip_and_bounds() -> None:
    schema = wire.Schema.of("myactuator")
    items = tuple((i, ma.SpeedControl(speed_dps=float(i))) for i in range(1, 33))
    message = wire.Setpoints(CLIENT, 7, 10, 20, items)
    data = wire.encode_setpoints(lambda mid: schema, message)
    assert wire.decode_setpoints(lambda mid: schema, data) == message
    with pytest.raises(wire.WireError, match="no motor 5"):
        wire.decode_setpoints(lambda mid: schema if mid != 5 else None, data)
    with pytest.raises(wire.WireError, match="at most"):
        wire.encode_setpoints(lambda mid: schema, wire.Setpoints(CLIENT, 1, 1, 2, items * 9))


def test_a_value_out_of_range_is_refused_by_its_constructor() -> None:
    """Bytes edited past a field's range decode to no command: the constructor's check runs."""
    schema = wire.Schema.of("myactuator")
    data = bytearray(wire.encode_request(schema, wire.Request(CLIENT, ma.SpeedControl(speed_dps=1.0))))
    at = data.index(wire._F64.pack(1.0)[0:8])
    data[at : at + 8] = wire._F64.pack(1e12)
    with pytest.raises(wire.WireError, match="speed_dps"):
        wire.decode_request(schema, bytes(data))


def test_a_reply_is_not_a_command() -> None:
    schema = wire.Schema.of("myactuator")
    reply = ma.StatusReply(
        temperature_c=50, current_a=1.0, speed_dps=5.0, angle_deg=45.0, command=ma.StatusCommand.SPEED_CONTROL
    )
    out = bytearray(wire._start(wire.REQUEST))
    out += bytes.fromhex(CLIENT) + wire._F64.pack(float("nan"))
    wire.encode_value(schema, reply, out)
    with pytest.raises(wire.WireError, match="not a command"):
        wire.decode_request(schema, bytes(out))


def test_types_outside_the_family_are_not_encoded() -> None:
    class Other(enum.Enum):
        A = 1

    schema = wire.Schema.of("myactuator")
    for value in (Other.A, object(), 2**70, get_family("lk").commands[0]):
        with pytest.raises(wire.WireError):
            wire.encode_value(schema, value, bytearray())


@pytest.mark.parametrize(
    "error",
    [
        MotorTimeout("motor 3: no reply"),
        MotorBusy("busy"),
        ProtocolError("bad", raw=b"\x01"),
        PermissionError("held"),
    ],
)
def test_errors_round_trip_by_kind(error: BaseException) -> None:
    schema = wire.Schema.of("myactuator")
    back = wire.decode_result(schema, wire.encode_result(schema, wire.Result(error=error))).error
    assert isinstance(back, type(error)) and str(error) in str(back)


def test_a_fault_keeps_its_flags() -> None:
    schema = wire.Schema.of("myactuator")
    fault = MotorFault("motor 2: over voltage", flags=ma.ErrorFlags(0x08), motor_id=2)
    back = wire.decode_result(schema, wire.encode_result(schema, wire.Result(error=fault))).error
    assert isinstance(back, MotorFault) and back.flags == fault.flags and back.motor_id == 2


def test_the_schema_digest_names_the_declarations() -> None:
    assert wire.Schema.of("myactuator").digest != wire.Schema.of("lk").digest
    assert wire.Schema(get_family("myactuator")).digest == wire.Schema.of("myactuator").digest


def test_wrong_version_and_kind() -> None:
    schema = wire.Schema.of("myactuator")
    data = wire.encode_request(schema, wire.Request(CLIENT, ma.ReadStatus2()))
    with pytest.raises(wire.WireError, match="version"):
        wire.decode_request(schema, b"\x09" + data[1:])
    with pytest.raises(wire.WireError, match="kind"):
        wire.decode_setpoints(lambda mid: schema, data)
    with pytest.raises(wire.WireError, match="left over"):
        wire.decode_request(schema, data + b"\x00")


_DECODERS = (
    lambda data: wire.decode_setpoints(lambda mid: wire.Schema.of("myactuator"), data),
    lambda data: wire.decode_request(wire.Schema.of("lk"), data),
    lambda data: wire.decode_result(wire.Schema.of("hollow"), data),
    lambda data: wire.decode_state(wire.Schema.of("myactuator"), data),
)


@given(st.binary(max_size=300), st.sampled_from(range(len(_DECODERS))))
def test_any_bytes_are_a_message_or_a_wire_error(data: bytes, which: int) -> None:
    with contextlib.suppress(wire.WireError):
        _DECODERS[which](data)


def _valid() -> list[bytes]:
    schema = wire.Schema.of("myactuator")
    items = (
        (1, ma.SpeedControl(speed_dps=3.0)),
        (2, ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10)),
    )
    return [
        b"\x01\x01" + wire.encode_setpoints(lambda mid: schema, wire.Setpoints(CLIENT, 1, 2, 3, items))[2:],
        wire.encode_request(schema, wire.Request(CLIENT, ma.ReadStatus2(), 0.5)),
    ]


@given(st.integers(0, 1), st.integers(0, 10_000), st.integers(0, 255))
def test_a_flipped_byte_is_a_message_or_a_wire_error(which: int, at: int, value: int) -> None:
    data = bytearray(_valid()[which])
    data[at % len(data)] = value
    with contextlib.suppress(wire.WireError):
        (_DECODERS[0] if which == 0 else lambda d: wire.decode_request(wire.Schema.of("myactuator"), d))(
            bytes(data)
        )


def test_a_motor_key_has_one_spelling() -> None:
    from servobus.remote.keys import Keys

    keys = Keys("n")
    assert keys.parse_motor("servobus/n/b/3/request") == ("b", 3, "request")
    for bad in (
        "servobus/n/b/03/request",
        "servobus/n/b/\u0663/request",
        "servobus/n/b/+3/read",
        "servobus/m/b/3/read",
    ):
        with pytest.raises(ValueError, match="not a motor key"):
            keys.parse_motor(bad)

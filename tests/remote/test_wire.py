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


# ---- what a bridge takes before decoding (remote/_limits.py), and the decode budget ----

_STR_BYTES = 64  # (a string field's longest legitimate value: a model's name)


def _most(schema: wire.Schema, hint: object, commands: tuple[type, ...]) -> tuple[int, int]:
    """(The most bytes, the most values) a value of type ``hint`` encodes to, from the declarations."""
    import dataclasses
    import types
    import typing

    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint in (type(None), bool):
        return 1, 1
    if hint in (int, float):
        return 9, 1
    if hint in (str, bytes):
        return 3 + _STR_BYTES, 1
    if origin in (typing.Union, types.UnionType):
        found = [_most(schema, a, commands) for a in args]
        return max(b for b, _ in found), max(v for _, v in found)
    if origin is tuple:
        found = [_most(schema, a, commands) for a in args]
        return 2 + sum(b for b, _ in found), 1 + sum(v for _, v in found)
    if isinstance(hint, typing.TypeVar):  # (an echo: any command of the family)
        found = [_most(schema, c, commands) for c in commands]
        return max(b for b, _ in found), max(v for _, v in found)
    assert isinstance(hint, type), hint
    if issubclass(hint, enum.Enum):
        return 3 + max(3 + len(m.value.encode()) if isinstance(m.value, str) else 9 for m in hint), 2
    assert dataclasses.is_dataclass(hint), hint
    most = (0, 0)
    for cls in [c for c in schema.types if issubclass(c, hint) and dataclasses.is_dataclass(c)] or [hint]:
        hints = typing.get_type_hints(cls)
        found = [_most(schema, hints[f.name], commands) for f in dataclasses.fields(cls) if f.init]
        most = max(most[0], 4 + sum(b for b, _ in found)), max(most[1], 1 + sum(v for _, v in found))
    return most


def _largest() -> dict[str, tuple[int, int]]:
    """Per family: (the most bytes, the most values) of any command and of any reply."""
    out = {}
    for name in FAMILIES:
        schema, family = wire.Schema.of(name), get_family(name)
        commands = tuple(family.commands)
        sent = [_most(schema, c, commands) for c in commands]
        replies = [_most(schema, r, commands) for c in commands for r in c.reply_types()]
        out[name] = (max(b for b, _ in sent), max(v for _, v in sent + replies))
    return out


def test_the_size_limits_hold_the_largest_legitimate_message_of_every_family() -> None:
    from servobus.remote import _limits

    for name in FAMILIES:  # (the estimate is no smaller than any command encoded)
        schema, family = wire.Schema.of(name), get_family(name)
        for command in _built(name):
            out = bytearray()
            wire.encode_value(schema, command, out)
            assert len(out) <= _most(schema, type(command), tuple(family.commands))[0], command
    command_bytes = max(b for b, _ in _largest().values())
    values = max(v for _, v in _largest().values())
    print(f"largest command {command_bytes} bytes; most values in a command or reply {values}")
    assert (command_bytes, values) == (183, 18)  # (what _limits' and wire's docstrings say)
    request = 2 + wire.CLIENT_ID_BYTES + 8 + command_bytes
    setpoints_head = 2 + wire.CLIENT_ID_BYTES + 4 + 8 + 8 + 2
    assert 4 * request <= _limits.REQUEST_BYTES
    assert 4 * (setpoints_head + 2 + command_bytes) <= _limits.SETPOINT_BYTES
    assert setpoints_head + wire._MAX_SETPOINTS * (2 + command_bytes) <= _limits.SETPOINTS_BYTES
    assert 3 * values <= wire.MAX_VALUES
    # each key's limit, exactly: the size itself passes, one byte more is counted and refused
    counts = {"oversized": 0}
    served = type("Served", (), {"counts": counts})()
    for leaf, limit in _limits.BYTES.items():
        assert not _limits.oversized(served, f"servobus/n/b/3/{leaf}", b"x" * limit)  # type: ignore[arg-type]
        assert _limits.oversized(served, f"servobus/n/b/3/{leaf}", b"x" * (limit + 1))  # type: ignore[arg-type]
    assert not _limits.oversized(served, "servobus/n/b/info", None)  # type: ignore[arg-type]
    assert counts["oversized"] == len(_limits.BYTES)


def _nested(counts: list[int]) -> bytes:
    body = b"\x00"
    for count in reversed(counts):
        body = b"\x07" + bytes([count]) + body * count
    return body


def test_a_value_holds_at_most_max_values_whatever_its_bytes() -> None:
    schema = wire.Schema.of("myactuator")
    fits = b"\x07" + bytes([wire.MAX_VALUES - 1]) + b"\x00" * (wire.MAX_VALUES - 1)
    assert wire.decode_value(schema, wire._Reader(fits)) == (None,) * (wire.MAX_VALUES - 1)
    for data in (fits[:1] + bytes([wire.MAX_VALUES]) + b"\x00" * wire.MAX_VALUES, _nested([2] * 8)):
        with pytest.raises(wire.WireError, match=f"more than {wire.MAX_VALUES} values"):
            wire.decode_value(schema, wire._Reader(data))
    # a 10 MB read (10.4 million values, within the depth limit) is refused at its 65th value
    head = wire.encode_request(schema, wire.Request(CLIENT, ma.ReadStatus2()))[: 2 + wire.CLIENT_ID_BYTES + 8]
    big = head + _nested([255, 255, 160])
    started = time.perf_counter()
    with pytest.raises(wire.WireError, match="values"):
        wire.decode_request(schema, big)
    took_s = time.perf_counter() - started
    print(f"a {len(big) / 1e6:.1f} MB read refused in {took_s * 1e3:.2f} ms")
    assert len(big) > 10_000_000 and took_s < 0.05
    # the budget is per top-level value: a batch of 256 set-points of 12 values each decodes
    batch = tuple(
        (mid, ma.MotionCommand(position_rad=1.0, velocity_rad_s=2.0, kp=3.0, kd=0.5, torque_ff_nm=0.1))
        for mid in range(256)
    )
    encoded = wire.encode_setpoints(lambda _: schema, wire.Setpoints(CLIENT, 1, 2, 3, batch))
    assert wire.decode_setpoints(lambda _: schema, encoded).items == batch

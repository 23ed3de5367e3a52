"""The binary encoding of what crosses the network: commands, replies, set-points, states, results.

Sans-IO and family-agnostic. A family's messages are frozen dataclasses whose constructors check
every field against the manual's range, so the encoding carries a message as its type and its field
values, and the receiving side builds it again with its constructor: a value out of range, a type
that is not the family's, or bytes that do not parse are a :class:`WireError`, never a command.

A value is one tag byte and its body (little-endian)::

    0 None   1 False   2 True   3 int (i64)   4 float (f64)   5 str (u16 length, UTF-8)
    6 bytes (u16 length)   7 tuple (u8 count, values)   8 enum (u16 type, value)
    9 dataclass (u16 type, u8 field count, the init fields' values in declaration order)

A decoded value nests at most 8 deep and holds at most :data:`MAX_VALUES` values (64; the largest
command or reply of any family holds 18), so its cost is bounded whatever bytes arrive.

Types are numbered by the family's :class:`Schema`: every command class, every reply type they
declare and every dataclass or enum their fields name, sorted by qualified name. Both sides derive it
from the same family, and :attr:`Schema.digest` (in the bridge's ``info``) tells a client whose
servobus differs before it sends anything.

A message is a version byte, a kind byte and its body (see the ``encode_*`` functions).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import math
import struct
import typing
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

from servobus.errors import (
    MotorBusy,
    MotorFault,
    MotorNotExecuted,
    MotorOffline,
    MotorStreaming,
    MotorTimeout,
    ProtocolError,
    ServobusError,
    TransportError,
)
from servobus.limits import LimitExceeded
from servobus.protocols import Command, Family, Reply, get_family

__all__ = [
    "VERSION",
    "Request",
    "Result",
    "Schema",
    "Setpoints",
    "State",
    "WireError",
    "decode_request",
    "decode_result",
    "decode_setpoints",
    "decode_state",
    "encode_request",
    "encode_result",
    "encode_setpoints",
    "encode_state",
    "peek_motor",
    "peek_setpoints",
    "public_id",
    "shown_id",
]

VERSION = 1
SETPOINTS, REQUEST, RESULT, STATE = 1, 2, 3, 4
CLIENT_ID_BYTES = 16
_MAX_DEPTH = 8
_MAX_SETPOINTS = 256
#: the most values (each tag counts one) one command, reply or error may hold when decoded: the
#: largest of any family holds 18 (hollow's ModbusWrite, ModbusReadReply); so the cost of decoding
#: a message is bounded by its count of such values, whatever its bytes
MAX_VALUES = 64

_NONE, _FALSE, _TRUE, _INT, _FLOAT, _STR, _BYTES, _TUPLE, _ENUM, _DATACLASS = range(10)
_U8, _U16, _I64, _F64, _U64, _U32 = (struct.Struct(f) for f in ("<B", "<H", "<q", "<d", "<Q", "<I"))


class WireError(ValueError):
    """Bytes that are not a valid message: counted and dropped by whoever received them."""


class Schema:
    """The numbered types of one family: what :func:`encode_value` may write and read back."""

    __slots__ = ("_fields", "digest", "family", "index", "types")

    def __init__(self, family: Family[Any]) -> None:
        found: dict[type, None] = {}
        stack: list[type] = []
        for command in family.commands:
            stack.append(command)
            stack.extend(command.reply_types())
        while stack:
            cls = stack.pop()
            if cls in found:
                continue
            found[cls] = None
            if dataclasses.is_dataclass(cls):
                stack.extend(_named_types(cls))
        self.family = family.name
        self.types: tuple[type, ...] = tuple(sorted(found, key=_qualified))
        self.index = {cls: i for i, cls in enumerate(self.types)}
        self._fields = {
            cls: tuple(f.name for f in dataclasses.fields(cls) if f.init)
            for cls in self.types
            if dataclasses.is_dataclass(cls)
        }
        text = ";".join(f"{_qualified(c)}({','.join(self._fields.get(c, ()))})" for c in self.types)
        self.digest = hashlib.sha256(text.encode()).hexdigest()[:16]

    @staticmethod
    @cache
    def of(family: str) -> Schema:
        """The schema of the family named ``family`` (built once)."""
        return Schema(get_family(family))

    def fields(self, cls: type) -> tuple[str, ...] | None:
        """The init fields of dataclass ``cls`` in order (None: not a dataclass of the schema)."""
        return self._fields.get(cls)


def _qualified(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _named_types(cls: type) -> list[type]:
    """The dataclasses and enums (with members) that ``cls``'s field annotations name."""
    out = []
    for hint in typing.get_type_hints(cls).values():
        stack = [hint]
        while stack:
            item = stack.pop()
            args = typing.get_args(item)
            if args:
                stack.extend(args)
            elif isinstance(item, type) and (
                dataclasses.is_dataclass(item) or (issubclass(item, enum.Enum) and len(item) > 0)
            ):
                out.append(item)
    return out


# ---- values ----


def encode_value(schema: Schema, value: object, out: bytearray, depth: int = 0) -> None:
    """Append ``value`` to ``out``.

    Raises:
        WireError: a type outside the schema, an int beyond 64 bits, a string or bytes too long.
    """
    if depth > _MAX_DEPTH:
        raise WireError("value nested too deep")
    if value is None:
        out.append(_NONE)
    elif value is True or value is False:
        out.append(_TRUE if value else _FALSE)
    elif isinstance(value, enum.Enum):
        out.append(_ENUM)
        out += _U16.pack(_type_index(schema, type(value)))
        encode_value(schema, value.value, out, depth + 1)
    elif isinstance(value, int):
        if not -(2**63) <= value < 2**63:
            raise WireError(f"int {value} does not fit 64 bits")
        out.append(_INT)
        out += _I64.pack(value)
    elif isinstance(value, float):
        out.append(_FLOAT)
        out += _F64.pack(value)
    elif isinstance(value, str):
        raw = value.encode()
        out.append(_STR)
        out += _U16.pack(_length(len(raw)))
        out += raw
    elif isinstance(value, bytes | bytearray):
        out.append(_BYTES)
        out += _U16.pack(_length(len(value)))
        out += value
    elif isinstance(value, tuple):
        out.append(_TUPLE)
        out += _U8.pack(_count(len(value)))
        for item in value:
            encode_value(schema, item, out, depth + 1)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        cls = type(value)
        names = schema.fields(cls) or ()
        out.append(_DATACLASS)
        out += _U16.pack(_type_index(schema, cls))
        out += _U8.pack(len(names))
        for name in names:
            encode_value(schema, getattr(value, name), out, depth + 1)
    else:
        raise WireError(f"cannot encode a {type(value).__name__}")


def _type_index(schema: Schema, cls: type) -> int:
    found = schema.index.get(cls)
    if found is None:
        raise WireError(f"{cls.__name__} is not a type of the {schema.family} family")
    return found


def _length(n: int) -> int:
    if n > 0xFFFF:
        raise WireError(f"{n} bytes is too long")
    return n


def _count(n: int) -> int:
    if n > 0xFF:
        raise WireError(f"a tuple of {n} items is too long")
    return n


class _Reader:
    """A cursor over received bytes; every read checks what is left."""

    __slots__ = ("at", "data")

    def __init__(self, data: bytes, at: int = 0) -> None:
        self.data = data
        self.at = at

    def take(self, fmt: struct.Struct) -> Any:
        end = self.at + fmt.size
        if end > len(self.data):
            raise WireError(f"truncated at byte {self.at} of {len(self.data)}")
        (value,) = fmt.unpack_from(self.data, self.at)
        self.at = end
        return value

    def raw(self, n: int) -> bytes:
        end = self.at + n
        if end > len(self.data):
            raise WireError(f"truncated at byte {self.at} of {len(self.data)}")
        out = self.data[self.at : end]
        self.at = end
        return bytes(out)

    def end(self) -> None:
        if self.at != len(self.data):
            raise WireError(f"{len(self.data) - self.at} bytes left over")


class _Budget:
    """How many more values one top-level value may hold (:data:`MAX_VALUES`)."""

    __slots__ = ("left",)

    def __init__(self, values: int = MAX_VALUES) -> None:
        self.left = values

    def spend(self) -> None:
        self.left -= 1
        if self.left < 0:
            raise WireError(f"more than {MAX_VALUES} values in one value")


def decode_value(schema: Schema, reader: _Reader, depth: int = 0, budget: _Budget | None = None) -> Any:
    """The value at ``reader``: built by its type's own constructor, which checks its ranges.

    ``budget``: what the enclosing value may still hold (None: a top-level value, with
    :data:`MAX_VALUES`); each value spends one, so its cost is bounded before its bytes are.

    Raises:
        WireError: anything that does not parse, more values than the budget or deeper than
            allowed, or a value the constructor refuses (its message kept).
    """
    if depth > _MAX_DEPTH:
        raise WireError("value nested too deep")
    if budget is None:
        budget = _Budget()
    budget.spend()
    tag = reader.take(_U8)
    if tag == _NONE:
        return None
    if tag == _FALSE:
        return False
    if tag == _TRUE:
        return True
    if tag == _INT:
        return reader.take(_I64)
    if tag == _FLOAT:
        return reader.take(_F64)
    if tag == _STR:
        try:
            return reader.raw(reader.take(_U16)).decode()
        except UnicodeDecodeError as exc:
            raise WireError(f"a string that is not UTF-8: {exc}") from None
    if tag == _BYTES:
        return reader.raw(reader.take(_U16))
    if tag == _TUPLE:
        return tuple(decode_value(schema, reader, depth + 1, budget) for _ in range(reader.take(_U8)))
    if tag in (_ENUM, _DATACLASS):
        index = reader.take(_U16)
        if index >= len(schema.types):
            raise WireError(f"type {index} is not in the {schema.family} schema")
        cls = schema.types[index]
        if tag == _ENUM:
            if not issubclass(cls, enum.Enum):
                raise WireError(f"{cls.__name__} is not an enum")
            return _build(cls, (decode_value(schema, reader, depth + 1, budget),), {})
        names = schema.fields(cls)
        if names is None:
            raise WireError(f"{cls.__name__} is not a dataclass")
        if reader.take(_U8) != len(names):
            raise WireError(f"{cls.__name__} has {len(names)} fields")
        values = {name: decode_value(schema, reader, depth + 1, budget) for name in names}
        return _build(cls, (), values)
    raise WireError(f"unknown tag {tag}")


def _build(cls: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    try:
        return cls(*args, **kwargs)
    except (ValueError, TypeError, OverflowError) as exc:
        raise WireError(f"{getattr(cls, '__name__', cls)}: {exc}") from None


def _start(kind: int) -> bytearray:
    out = bytearray()
    out.append(VERSION)
    out.append(kind)
    return out


def _open(data: bytes, kind: int) -> _Reader:
    reader = _Reader(data)
    version = reader.take(_U8)
    if version != VERSION:
        raise WireError(f"wire version {version} (this servobus speaks {VERSION})")
    found = reader.take(_U8)
    if found != kind:
        raise WireError(f"message kind {found}, expected {kind}")
    return reader


def _client_id(reader: _Reader) -> str:
    return reader.raw(CLIENT_ID_BYTES).hex()


def public_id(client_id: str) -> str:
    """The name of a client's liveliness token: a hash of the secret id its messages carry, so that
    knowing the token does not let another client speak in its name."""
    return hashlib.sha256(bytes.fromhex(client_id)).hexdigest()[:32]


def shown_id(public: str) -> str:
    """How a bridge's metrics name the client that holds a motor: a hash of its public id, so that
    reading them does not tell another client the key of that client's liveliness token (whoever
    declared a token with the same key would keep it alive when that client left)."""
    return hashlib.sha256(b"shown:" + bytes.fromhex(public)).hexdigest()[:16]


# ---- messages ----


@dataclass(frozen=True, slots=True)
class Setpoints:
    """Set-points from one client: each ``(motor_id, command)`` must not be applied after
    ``deadline_unix_ns`` (the client's wall clock), nor longer than it was meant to stay valid
    (``deadline_unix_ns - sent_unix_ns``) after it arrived."""

    client_id: str
    seq: int
    sent_unix_ns: int
    deadline_unix_ns: int
    items: tuple[tuple[int, Command], ...]


def encode_setpoints(schemas: Callable[[int], Schema], message: Setpoints) -> bytes:
    """``message`` as bytes; ``schemas(motor_id)`` gives each motor's family schema."""
    out = _start(SETPOINTS)
    out += bytes.fromhex(message.client_id)
    out += _U32.pack(message.seq & 0xFFFFFFFF)
    out += _U64.pack(message.sent_unix_ns)
    out += _U64.pack(message.deadline_unix_ns)
    if len(message.items) > _MAX_SETPOINTS:
        raise WireError(f"{len(message.items)} set-points in one message (at most {_MAX_SETPOINTS})")
    out += _U16.pack(len(message.items))
    for motor_id, command in message.items:
        out += _U16.pack(motor_id)
        encode_value(schemas(motor_id), command, out)
    return bytes(out)


def peek_setpoints(data: bytes) -> tuple[str, int]:
    """(The client id, how many set-points) of a set-point message, read from its header alone:
    what a receiver checks before it pays for decoding the commands.

    Raises:
        WireError: not a set-point message, or a header cut short.
    """
    reader = _open(data, SETPOINTS)
    client_id = _client_id(reader)
    reader.at += _U32.size + 2 * _U64.size  # (seq, sent, deadline)
    return client_id, int(reader.take(_U16))


def decode_setpoints(schemas: Callable[[int], Schema | None], data: bytes) -> Setpoints:
    """The set-points in ``data``.

    Raises:
        WireError: bytes that do not parse, a motor ``schemas`` does not know (returns None), a
            value that is not a command of the motor's family, or one its constructor refuses.
    """
    reader = _open(data, SETPOINTS)
    client_id = _client_id(reader)
    seq, sent, deadline = reader.take(_U32), reader.take(_U64), reader.take(_U64)
    count = reader.take(_U16)
    if count > _MAX_SETPOINTS:
        raise WireError(f"{count} set-points in one message (at most {_MAX_SETPOINTS})")
    items = []
    for _ in range(count):
        motor_id = reader.take(_U16)
        schema = schemas(motor_id)
        if schema is None:
            raise WireError(f"no motor {motor_id} on this bus")
        items.append((motor_id, _command(decode_value(schema, reader))))
    reader.end()
    return Setpoints(client_id, seq, sent, deadline, tuple(items))


def _command(value: object) -> Command:
    if not isinstance(value, Command):
        raise WireError(f"a {type(value).__name__} is not a command")
    return value


@dataclass(frozen=True, slots=True)
class Request:
    """One command to run through the Bus and answer: ``timeout_s`` None is the Bus's own."""

    client_id: str
    command: Command
    timeout_s: float | None = None


def encode_request(schema: Schema, message: Request) -> bytes:
    out = _start(REQUEST)
    out += bytes.fromhex(message.client_id)
    out += _F64.pack(math.nan if message.timeout_s is None else message.timeout_s)
    encode_value(schema, message.command, out)
    return bytes(out)


def decode_request(schema: Schema, data: bytes) -> Request:
    """The request in ``data``.

    Raises:
        WireError: as :func:`decode_setpoints`; also a timeout that is not a positive number.
    """
    reader = _open(data, REQUEST)
    client_id = _client_id(reader)
    timeout = reader.take(_F64)
    if not math.isnan(timeout) and not (0 < timeout <= 60):
        raise WireError(f"timeout_s={timeout} is outside (0, 60]")
    command = _command(decode_value(schema, reader))
    reader.end()
    return Request(client_id, command, None if math.isnan(timeout) else timeout)


# The errors a result may carry, by name; anything else arrives as a ServobusError with its text.
_ERRORS: dict[str, type[Exception]] = {
    cls.__name__: cls
    for cls in (
        MotorTimeout,
        MotorOffline,
        MotorBusy,
        MotorStreaming,
        MotorNotExecuted,
        ProtocolError,
        TransportError,
        ServobusError,
        LimitExceeded,
        ValueError,
        PermissionError,
    )
}


@dataclass(frozen=True, slots=True)
class Result:
    """A request's outcome: its reply (None for commands without one), or an error as a value."""

    reply: Reply | None = None
    error: BaseException | None = None


def encode_result(schema: Schema, result: Result) -> bytes:
    out = _start(RESULT)
    error = result.error
    if error is None:
        out.append(1)
        encode_value(schema, result.reply, out)
        return bytes(out)
    out.append(0)
    name = next((c.__name__ for c in type(error).__mro__ if c.__name__ in _ERRORS), "ServobusError")
    if isinstance(error, MotorFault):
        name = "MotorFault"
    encode_value(schema, name, out)
    encode_value(schema, str(error)[:2000], out)
    flags = getattr(error, "flags", None) if isinstance(error, MotorFault) else None
    encode_value(schema, flags if flags is None or type(flags) in schema.index else None, out)
    encode_value(schema, getattr(error, "motor_id", None), out)
    return bytes(out)


def decode_result(schema: Schema, data: bytes) -> Result:
    """The result in ``data``.

    Raises:
        WireError: bytes that do not parse, a reply that is not the family's.
    """
    reader = _open(data, RESULT)
    ok = reader.take(_U8)
    if ok == 1:
        reply = decode_value(schema, reader)
        reader.end()
        if reply is not None and not isinstance(reply, Reply):
            raise WireError(f"a {type(reply).__name__} is not a reply")
        return Result(reply=reply)
    if ok != 0:
        raise WireError(f"result flag {ok}")
    name, message, flags, motor_id = (decode_value(schema, reader) for _ in range(4))
    reader.end()
    if not isinstance(name, str) or not isinstance(message, str):
        raise WireError("an error without a name and a message")
    if name == "MotorFault" and isinstance(flags, enum.Flag) and isinstance(motor_id, int):
        return Result(error=MotorFault(message, flags=flags, motor_id=motor_id))
    if name == "MotorNotExecuted":
        if isinstance(motor_id, int):
            return Result(error=MotorNotExecuted(message, motor_id=motor_id))
        name = "ServobusError"  # (it cannot be made without its motor)
    cls = _ERRORS.get(name, ServobusError)
    return Result(error=cls(message))


@dataclass(frozen=True, slots=True)
class State:
    """What a bridge publishes of one motor: its latest reply or stream frame (None before any),
    whether the watchdog has it online, and its last reported fault: error flags, or the one code a
    family reports (``MotorFault.code``; None: none reported)."""

    motor_id: int
    stamp_unix_ns: int
    online: bool
    reply: Reply | None
    fault: enum.Flag | enum.IntEnum | None = None


def encode_state(schema: Schema, state: State) -> bytes:
    out = _start(STATE)
    out += _U16.pack(state.motor_id)
    out += _U64.pack(state.stamp_unix_ns)
    out.append(1 if state.online else 0)
    encode_value(schema, state.reply, out)
    encode_value(
        schema, state.fault if state.fault is None or type(state.fault) in schema.index else None, out
    )
    return bytes(out)


def peek_motor(data: bytes) -> int:
    """The motor id of a state message, read before its family's schema is chosen.

    Raises:
        WireError: not a state message.
    """
    reader = _open(data, STATE)
    return int(reader.take(_U16))


def decode_state(schema: Schema, data: bytes) -> State:
    """The state in ``data``.

    Raises:
        WireError: bytes that do not parse, values that are not the family's.
    """
    reader = _open(data, STATE)
    motor_id, stamp, online = reader.take(_U16), reader.take(_U64), reader.take(_U8)
    reply, fault = decode_value(schema, reader), decode_value(schema, reader)
    reader.end()
    if online > 1 or (reply is not None and not isinstance(reply, Reply)):
        raise WireError("a state that is not a motor's")
    if fault is not None and not isinstance(fault, enum.Flag | enum.IntEnum):
        raise WireError("a fault that is not error flags or a code")
    return State(motor_id, stamp, bool(online), reply, fault)

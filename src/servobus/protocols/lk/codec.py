"""LK codec entry points: per-revision decoder tables, availability checks, frame helpers.

Tables are built from the message classes themselves (``CODE``/``REVISIONS``), so which command
exists in which revision is stated once, on the class (spec §3, §9 D12):

* V2.36 only: 0x8C brake, 0x18 calibrate, 0xC0/0xC1 control parameters (and its 0x40/0x42/0x44
  setting scheme, 0xA2/0xA5/0xA6/0x9A/0x9D/0x94 layouts).
* V2.35 only: 0x91 encoder offset, 0x33/0x34 acceleration, the 0x280 multi-motor frame (and its
  ParamID scheme and layouts).

A reply decoder exists for a command byte in a revision only if the request exists there, so a
V2.36 decoder never accepts a 0x91 reply. Decoding with the wrong revision is a ProtocolError (the
bytes are not a message of that revision); encoding a command for a revision that lacks it is a
ValueError naming command and revision (the caller asked for something impossible, before any send).

Every entry point takes ``revision=`` and/or ``model=`` (:class:`~servobus.protocols.lk.model.LkModel`,
which also carries motor type and encoder width). Given both, they must agree; given neither,
V2.36 / MG / 14-bit.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import TypeVar

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.lk import commands_control as ctl
from servobus.protocols.lk._base import LkCommand, LkReply
from servobus.protocols.lk.classes import COMMAND_CLASSES, REQUESTS
from servobus.protocols.lk.ids import (
    MULTI_MOTOR_ID,
    motor_id_from_reply_id,
    motor_id_from_request_id,
    reply_id,
    request_id,
)
from servobus.protocols.lk.model import DEFAULT_MODEL, LkModel, MotorType, Revision, check_member

__all__ = [
    "COMMAND_CLASSES",
    "INFERRED_LAYOUTS",
    "REPLY_CLASSES",
    "REPLY_LAYOUTS",
    "REQUESTS",
    "check_available",
    "decode_reply",
    "decode_request",
    "encode_request",
    "reply_class",
    "reply_frame",
    "request_classes",
    "request_frame",
    "resolve_model",
]


def _reply_layouts() -> tuple[tuple[type[LkReply], frozenset[int]], ...]:
    replies = dict.fromkeys(reply for cls in COMMAND_CLASSES for reply in cls.reply_types())
    return tuple((reply, reply.answers()) for reply in replies if issubclass(reply, LkReply))


# Reply layouts and the command bytes each serves (from the commands that declare it their reply).
REPLY_LAYOUTS: tuple[tuple[type[LkReply], frozenset[int]], ...] = _reply_layouts()

# Layouts no manual prints; implemented from the spec's inference (listed in the package docstring).
INFERRED_LAYOUTS: Mapping[int, str] = MappingProxyType(
    {
        MULTI_MOTOR_ID if cls.CODE is None else cls.CODE: cls.INFERRED
        for cls in COMMAND_CLASSES
        if cls.INFERRED
    }
)


def _reply_table(revision: Revision) -> dict[int, type[LkReply]]:
    # The reply of each request of the revision: the one of its declared reply types the revision has.
    # 0x280's replies are 0xA1 replies (spec §5), and 0xA1 is a request of both revisions.
    table: dict[int, type[LkReply]] = {}
    for code, cls in REQUESTS[revision].items():
        replies = [r for r in cls.reply_types() if issubclass(r, LkReply) and revision in r.REVISIONS]
        if len(replies) != 1:  # pragma: no cover - a declaration error, caught at import
            raise AssertionError(f"{cls.__name__}: {len(replies)} reply layouts in {revision.name}")
        table[code] = replies[0]
    return table


REPLY_CLASSES: Mapping[Revision, Mapping[int, type[LkReply]]] = MappingProxyType(
    {revision: MappingProxyType(_reply_table(revision)) for revision in Revision}
)

_M = TypeVar("_M", LkCommand, LkReply)
_MODELS = {revision: LkModel(revision=revision) for revision in Revision}


def resolve_model(revision: Revision | None = None, model: LkModel | None = None) -> LkModel:
    """The model an entry point works with: ``model``, else the default model of ``revision``.

    Raises:
        ValueError: ``revision`` is not a Revision, or it contradicts ``model.revision``.
    """
    if revision is not None:
        check_member("revision", revision, Revision)
    if model is None:
        return DEFAULT_MODEL if revision is None else _MODELS[revision]
    if not isinstance(model, LkModel):
        raise ValueError(f"model={model!r} is not an LkModel")
    if revision is not None and revision is not model.revision:
        raise ValueError(f"revision={revision.name} contradicts model.revision={model.revision.name}")
    return model


def _other_revisions(code: int, tables: Mapping[Revision, Mapping[int, object]], revision: Revision) -> str:
    others = [r.name for r in Revision if r is not revision and code in tables[r]]
    return f" (exists in {', '.join(others)})" if others else ""


def decode_request(
    can_id: int, data: bytes, *, revision: Revision | None = None, model: LkModel | None = None
) -> LkCommand:
    """Decode a request frame's payload (the simulator's side).

    Args:
        can_id: 0x140+ID (ID 1..32), or 0x280 for the V2.35 multi-motor frame.
        data: the payload.
        revision: protocol revision (default: ``model``'s, else V2.36).
        model: revision, motor type and encoder width.

    Returns:
        The typed command.

    Raises:
        ProtocolError: ``can_id`` is not a request identifier of the revision, or the bytes are not a
            request of the revision (unknown or other-revision command byte, wrong length, values
            the layout does not allow).
        ValueError: ``revision`` and ``model`` disagree.
    """
    model = resolve_model(revision, model)
    data = bytes(data)
    if can_id == MULTI_MOTOR_ID:
        if model.revision not in ctl.MultiMotorTorque.REVISIONS:
            raise ProtocolError(
                f"identifier 0x280 (multi-motor) does not exist in {model.revision.name}", raw=data
            )
        return ctl.MultiMotorTorque.decode(data, model=model)
    motor_id = motor_id_from_request_id(can_id)
    if motor_id is None:
        raise ProtocolError(
            f"identifier 0x{can_id:03X} is not an LK request identifier (0x141..0x160)", raw=data
        )
    return _decode(REQUESTS, data, model, motor_id, "request")


def decode_reply(
    can_id: int, data: bytes, *, revision: Revision | None = None, model: LkModel | None = None
) -> LkReply:
    """Decode a reply frame's payload.

    On V2.35 the reply identifier is the request identifier: call this only for frames that
    :func:`servobus.protocols.lk.ids.reply_key` keys (received, not our own loop-back).

    Args:
        can_id: 0x180+ID on V2.36, 0x140+ID on V2.35.
        data: the payload.
        revision: protocol revision (default: ``model``'s, else V2.36).
        model: revision, motor type and encoder width.

    Returns:
        The typed reply.

    Raises:
        ProtocolError: ``can_id`` is not a reply identifier of the revision, or the bytes are not a
            reply of the revision.
        ValueError: ``revision`` and ``model`` disagree.
    """
    model = resolve_model(revision, model)
    data = bytes(data)
    motor_id = motor_id_from_reply_id(can_id, model.revision)
    if motor_id is None:
        base = 0x180 if model.revision is Revision.V2_36 else 0x140
        raise ProtocolError(
            f"identifier 0x{can_id:03X} is not a {model.revision.name} reply identifier "
            f"(0x{base + 1:03X}..0x{base + 32:03X})",
            raw=data,
        )
    return _decode(REPLY_CLASSES, data, model, motor_id, "reply")


def _decode(
    tables: Mapping[Revision, Mapping[int, type[_M]]], data: bytes, model: LkModel, motor_id: int, what: str
) -> _M:
    if not data:
        raise ProtocolError(f"empty {what}", motor_id=motor_id)
    cls = tables[model.revision].get(data[0])
    if cls is None:
        raise ProtocolError(
            f"no {model.revision.name} {what} has command byte 0x{data[0]:02X}"
            + _other_revisions(data[0], tables, model.revision),
            raw=data,
            motor_id=motor_id,
            command=data[0],
        )
    try:
        return cls.decode(data, model=model)
    except ProtocolError as exc:
        raise exc.with_context(motor_id=motor_id) from None


def reply_class(command: int, revision: Revision) -> type[LkReply]:
    """The reply class that answers request byte ``command`` in ``revision``.

    Raises:
        ValueError: ``command`` is not a request of ``revision``.
    """
    if command not in REQUESTS[revision]:
        raise ValueError(f"command 0x{command:02X} does not exist in {revision.name}")
    return REPLY_CLASSES[revision][command]


def _motor_type_of(message: object) -> MotorType | None:
    value = getattr(message, "motor_type", None)
    return value if isinstance(value, MotorType) else None


def check_available(
    command: LkCommand, *, revision: Revision | None = None, model: LkModel | None = None
) -> None:
    """Raise ValueError unless ``command`` can be sent to a motor of ``revision`` / ``model``.

    Checks the revision (spec §3, §9 D12), the motor types the manual allows ([001]: 0xA0 MS only,
    0xA1 MF/MH/MG only), and that a command's own ``motor_type`` agrees with an explicit ``model``.

    Raises:
        ValueError: naming the command and the revision (or motor type) it does not exist for.
    """
    model_given = model is not None
    model = resolve_model(revision, model)
    cls = type(command)
    name = f"{cls.__name__} (0x{cls.CODE:02X})" if cls.CODE is not None else f"{cls.__name__} (id 0x280)"
    if model.revision not in cls.REVISIONS:
        available = ", ".join(r.name for r in Revision if r in cls.REVISIONS)
        raise ValueError(f"{name} does not exist in {model.revision.name} (only in {available})")
    own = _motor_type_of(command)
    if own is not None and model_given and own is not model.motor_type:
        raise ValueError(f"{name}.motor_type={own.name} contradicts model.motor_type={model.motor_type.name}")
    motor_type = own if own is not None else (model.motor_type if model_given else None)
    allowed = cls.MOTOR_TYPES.get(model.revision)
    if motor_type is not None and allowed is not None and motor_type not in allowed:
        kinds = ", ".join(t.name for t in MotorType if t in allowed)
        raise ValueError(
            f"{name} is not implemented on {motor_type.name} motors in {model.revision.name} (only {kinds})"
        )


def encode_request(
    command: LkCommand, *, revision: Revision | None = None, model: LkModel | None = None
) -> bytes:
    """The payload of ``command`` after :func:`check_available`.

    Raises:
        ValueError: the command does not exist for this revision / motor type.
    """
    check_available(command, revision=revision, model=model)
    return command.encode()


def request_frame(
    command: LkCommand,
    *,
    motor_id: int | None,
    revision: Revision | None = None,
    model: LkModel | None = None,
) -> Frame:
    """The CAN frame of ``command`` to ``motor_id`` (None for the 0x280 multi-motor frame).

    Raises:
        ValueError: unavailable command, ``motor_id`` not 1..32, or a motor id given for 0x280.
    """
    data = encode_request(command, revision=revision, model=model)
    if isinstance(command, ctl.MultiMotorTorque):
        if motor_id is not None:
            raise ValueError(f"motor_id={motor_id!r}: the 0x280 frame addresses motors 1..4 by position")
        return Frame(arbitration_id=MULTI_MOTOR_ID, data=data)
    if motor_id is None:
        raise ValueError(f"motor_id is required for {type(command).__name__}")
    return Frame(arbitration_id=request_id(motor_id), data=data)


def reply_frame(
    reply: LkReply, *, motor_id: int, revision: Revision | None = None, model: LkModel | None = None
) -> Frame:
    """The CAN frame in which motor ``motor_id`` sends ``reply`` (the simulator's side).

    Raises:
        ValueError: the reply layout does not exist in the revision, or ``motor_id`` is not 1..32.
    """
    model = resolve_model(revision, model)
    if model.revision not in type(reply).REVISIONS:
        raise ValueError(f"{type(reply).__name__} does not exist in {model.revision.name}")
    return Frame(arbitration_id=reply_id(motor_id, model.revision), data=reply.encode())


def request_classes(revision: Revision) -> list[type[LkCommand]]:
    """The command classes available in ``revision`` (0x280 included)."""
    return [cls for cls in COMMAND_CLASSES if revision in cls.REVISIONS]

"""One LK motor's codec on Frames (protocols/_bound.py's contract): ``FAMILY.bind(3, revision="V2_35")``.

Link: ``"can"``. Requests go to 0x140 + ID; replies come on 0x180 + ID (V2.36) or on the request's own
identifier (V2.35), so on V2.35 our own frames looped back by an adapter (``is_rx`` False) are never
taken for replies. On V2.35 the reply to 0x9B (clear errors) may say 0x9A (spec A4): both bytes map to
one key, so a 0x9B request waits for either and FIFO order keeps pairs straight.

LK motors send nothing on their own (no streams, no error reports): every frame on a motor's reply
identifier is a REPLY.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Hashable, Sequence
from operator import attrgetter
from typing import Any

from servobus.errors import ProtocolError
from servobus.frame import Frame, classic_request
from servobus.protocols._bound import (
    KIND_NOT_OURS,
    KIND_REPLY,
    Broadcast,
    CodecBase,
    FrameKind,
    check_bus,
    echo_key,
    frame_key,
    motor_ids_of,
)
from servobus.protocols._family import find_revision
from servobus.protocols._fast import Slow, maker
from servobus.protocols._fields import IntField, ScaledField, round_half_away
from servobus.protocols._message import Command, Reply
from servobus.protocols._special import SpecialZero
from servobus.protocols.lk import commands as cmd
from servobus.protocols.lk._base import (
    CommandField,
    EncoderCountField,
    FlagByteField,
    IqField,
    LkCommand,
    LkMessage,
    LkReply,
    MemberField,
)
from servobus.protocols.lk.codec import (
    COMMAND_CLASSES,
    REPLY_CLASSES,
    check_available,
    decode_reply,
    resolve_model,
)
from servobus.protocols.lk.commands_control import MultiMotorTorque
from servobus.protocols.lk.ids import (
    MULTI_MOTOR_ID,
    MULTI_MOTOR_IDS,
    MULTI_MOTOR_REPLY_CODE,
    reply_id,
    request_id,
)
from servobus.protocols.lk.model import LkModel, Revision, encoder_max_count
from servobus.protocols.lk.params import ParamMessage
from servobus.protocols.lk.replies import (
    REPLY_SPEED,
    TEMPERATURE,
    Status2Reply,
    status2_slot,
    torque_range,
)
from servobus.protocols.lk.restart import RESTART
from servobus.protocols.lk.states import BrakeAction

__all__ = ["LINKS", "LkCodec", "bind", "broadcast"]

LINKS = ("can",)
#: the revisions, the default first (the Family\'s)
REVISIONS = (Revision.V2_36, Revision.V2_35)

DEFAULT_TIMEOUT_S = 0.02
#: ROM writes and the brake (a class declaring ``SLOW``) take longer; 0x18 declares its own TIMEOUT_S.
SLOW_TIMEOUT_S = 0.5
CALIBRATION_TIMEOUT_S = cmd.CALIBRATION_TIMEOUT_S
#: Echo replies that carry the value their request wrote (the classes declaring ``ECHO``: 0x34
#: acceleration, 0xC1 control parameter): keyed with it (``echo_key``), so a stray echo never answers
#: another write. Known from DATA[0] alone, as :meth:`LkCodec.classify` has nothing else.
_VALUE_ECHO_CODES = frozenset(cls.CODE for cls in COMMAND_CLASSES if cls.ECHO and cls.CODE is not None)
#: Per command class: (timeout_s, retry_safe), from its declarations (SLOW, TIMEOUT_S, READ).
_RULES: dict[type, tuple[float, bool]] = {}


def _rules(cls: type) -> tuple[float, bool]:
    timeout = getattr(cls, "TIMEOUT_S", None)
    if timeout is None:
        timeout = SLOW_TIMEOUT_S if getattr(cls, "SLOW", False) else DEFAULT_TIMEOUT_S
    rules = _RULES[cls] = (timeout, bool(getattr(cls, "READ", False)))
    return rules


def _status2_decoders(model: LkModel) -> dict[int, Callable[[bytes], Status2Reply]]:
    """The fast status-2 decoder of each command byte (0x9C, 0xA0..0xA8).

    What DATA[2..3] is (iq in A, raw iq, power) depends on the motor type and the command (0xA0's is
    power on every type), its decode-time limits on the revision too (``torque_range``): codes that
    agree on both share one decoder.
    """
    groups: dict[tuple[int, tuple[int, int] | None], set[int]] = {}
    for code in sorted(Status2Reply.answers()):
        key = (id(status2_slot(code)), torque_range(model.revision, model.motor_type, code))
        groups.setdefault(key, set()).add(code)
    decoders: dict[int, Callable[[bytes], Status2Reply]] = {}
    for codes in groups.values():
        decoder = _status2_decoder(model, frozenset(codes))
        decoders.update(dict.fromkeys(codes, decoder))
    return decoders


def _status2_decoder(model: LkModel, codes: frozenset[int]) -> Callable[[bytes], Status2Reply]:
    """Status 2 (``<BbhhH``) for command bytes ``codes`` that agree on what DATA[2..3] is and its
    limits, without re-validation; :class:`Slow` when in doubt."""
    unpack = struct.Struct("<BbhhH").unpack
    code = min(codes)
    slot = status2_slot(code)
    iq = slot.field(model.motor_type)
    counts_name = slot.counts_names.get(model.motor_type)
    iq_name = slot.amps_name if iq is not None else counts_name
    if iq_name is None:
        raise ValueError(f"no status-2 layout for {model.motor_type.name}")
    iq_lo, iq_hi = torque_range(model.revision, model.motor_type, code) or slot.limits
    cpu = iq.counts_per_unit if iq is not None else None
    t_lo, t_hi = TEMPERATURE.limits
    s_lo, s_hi = REPLY_SPEED.limits
    e_hi = encoder_max_count(model.encoder_bits)
    make = maker(
        Status2Reply,
        ("command", "motor_type", "encoder_bits", "temperature_c", "speed_dps", "encoder_counts", iq_name),
    )
    motor_type, bits = model.motor_type, model.encoder_bits

    def decode(data: bytes) -> Status2Reply:
        if len(data) != 8:
            raise Slow
        command, temperature, current, speed, encoder = unpack(data)
        if (
            command not in codes
            or not t_lo <= temperature <= t_hi
            or not iq_lo <= current <= iq_hi
            or not s_lo <= speed <= s_hi
            or encoder > e_hi
        ):
            raise Slow
        value = current / cpu if cpu is not None else current
        return make(command, motor_type, bits, temperature, float(speed), encoder, value)  # type: ignore[no-any-return]

    return decode


def _layout_decoders(model: LkModel) -> dict[int, Callable[[bytes], Reply]]:
    """A fast decoder, derived from the declared layout, for each reply of the revision whose fields
    are plain integers, scaled values, enum or flag bytes, encoder counts or the command byte (every
    reply but status 2, which has its own, status 3 and the parameter replies)."""
    decoders: dict[int, Callable[[bytes], Reply]] = {}
    for code, cls in REPLY_CLASSES[model.revision].items():
        decoder = _layout_decoder(cls, model, code)
        if decoder is not None:
            decoders[code] = decoder
    return decoders


def _layout_decoder(cls: type[LkReply], model: LkModel, code: int) -> Callable[[bytes], Reply] | None:
    """The reply ``cls`` from bytes whose DATA[0] is ``code`` (checked: a shared layout's other
    bytes have their own decoder), values checked against the field limits only; None for a layout
    with a field kind it does not know. :class:`Slow` for anything the full decoder must judge."""
    if cls.CONSTANTS or not cls.HAS_CODE or issubclass(cls, ParamMessage):
        return None
    names = list(cls.MODEL)
    model_values = [getattr(model, name) for name in cls.MODEL]
    readers: list[tuple[int, int, bool, Callable[[int], Any] | None, float, float]] = []
    for offset, spec in cls.all_fields():
        if isinstance(spec, CommandField):
            names.append("command")
            readers.append((0, 1, False, None, code, code))
            continue
        if isinstance(spec, EncoderCountField):
            readers.append((offset, 2, False, None, 0, encoder_max_count(model.encoder_bits)))
        elif isinstance(spec, IntField):
            readers.append((offset, spec.size, spec.signed, None, *spec.limits))
        elif isinstance(spec, ScaledField):
            readers.append((offset, spec.size, spec.signed, spec.from_code, *spec.limits))
        elif isinstance(spec, MemberField):
            readers.append((offset, 1, False, spec.members, 0, 0xFF))
        elif isinstance(spec, FlagByteField):
            readers.append((offset, 1, False, spec.flags, 0, 0xFF))
        else:
            return None
        names.append(spec.name)
    make = maker(cls, tuple(names))

    def decode(data: bytes) -> Reply:
        if len(data) != 8 or data[0] != code:
            raise Slow
        values = list(model_values)
        for offset, size, signed, convert, lo, hi in readers:
            value = int.from_bytes(data[offset : offset + size], "little", signed=signed)
            if convert is not None:
                try:
                    value = convert(value)
                except ValueError:  # an enum byte the manual does not list
                    raise Slow from None
            if not lo <= value <= hi:
                raise Slow
            values.append(value)
        return make(*values)  # type: ignore[no-any-return]

    return decode


def _iq_code(slot: Any, motor_type: Any) -> Callable[[Any], int]:
    """The int16 count of an already validated message's torque field (amperes or raw counts)."""
    field = slot.field(motor_type)
    if field is not None:
        get_amps, cpu = attrgetter(slot.amps_name), field.counts_per_unit
        return lambda m: round_half_away(get_amps(m) * cpu)
    return attrgetter(slot.counts_names[motor_type]) if motor_type in slot.counts_names else _no_iq


def _no_iq(message: Any) -> int:
    raise ValueError(f"{type(message).__name__} has no torque field for its motor type")


def _fast_encoders(model: LkModel) -> dict[type, Callable[[Any], bytes]]:
    """``command.encode()`` by one ``struct.pack``, generated from each command's declared layout
    (its values were validated when it was built); commands with another layout keep ``encode()``."""
    encoders: dict[type, Callable[[Any], bytes]] = {}
    for cls in COMMAND_CLASSES:
        encoder = _fast_encoder(cls, model)
        if encoder is not None:
            encoders[cls] = encoder
    return encoders


_STRUCT_CODES = {
    (1, False): "B",
    (1, True): "b",
    (2, False): "H",
    (2, True): "h",
    (4, False): "I",
    (4, True): "i",
}


def _fast_encoder(cls: type[LkCommand], model: LkModel) -> Callable[[Any], bytes] | None:
    if cls.CODE is None or cls.CONSTANTS or cls.encode is not LkMessage.encode:
        return None  # 0x280, fixed constants, or a layout chosen by a value (the parameter frames)
    fmt, position, args = "<B", 1, []
    namespace: dict[str, Any] = {"rha": round_half_away}
    for i, (offset, spec) in enumerate(cls.all_fields()):
        if isinstance(spec, IqField) and not spec.labels:
            namespace[f"f{i}"] = _iq_code(spec.slot, model.motor_type)
            arg, signed = f"f{i}(m)", True
        elif isinstance(spec, ScaledField):
            arg, signed = f"rha(m.{spec.name} * {spec.counts_per_unit!r})", spec.signed
        elif isinstance(spec, SpecialZero):
            namespace[f"f{i}"] = spec.to_code
            arg, signed = f"f{i}(m.{spec.name})", spec.signed
        elif isinstance(spec, IntField | MemberField):
            arg, signed = f"m.{spec.name}", isinstance(spec, IntField) and spec.signed
        else:
            return None
        code = _STRUCT_CODES.get((spec.size, signed))
        if code is None or offset < position:
            return None
        fmt += "x" * (offset - position) + code
        position = offset + spec.size
        args.append(arg)
    namespace["pack"] = struct.Struct(fmt + "x" * (8 - position)).pack
    exec(f"def encode(m):\n    return pack({cls.CODE}, {', '.join(args)})\n", namespace)
    encode: Callable[[Any], bytes] = namespace["encode"]
    return encode


class LkCodec(CodecBase):
    """One LK motor on CAN. Build it with :func:`bind` (or ``FAMILY.bind``)."""

    family = "lk"
    RESTART = RESTART  # what proves a restart (servobus.bus.restarts)
    SAFE_COMMANDS = {  # noqa: RUF012 - a class table, not per instance
        "stop": lambda codec: cmd.MotorStop(),
        "shutdown": lambda codec: cmd.MotorOff(),
        "brake": lambda codec: cmd.BrakeControl(action=BrakeAction.ENGAGE),
    }
    revision: Revision
    model: LkModel

    __slots__ = (
        "_aliases",
        "_available",
        "_encoders",
        "_fast",
        "_reply_base",
        "_reply_id",
        "_request_id",
    )

    def __init__(self, motor_id: int, model: LkModel) -> None:
        self._request_id = request_id(motor_id)
        self._available: set[tuple[type, Any]] = set()
        self.motor_id = motor_id
        self.model = model
        self.link = "can"
        self.framing = None
        self.revision = model.revision
        self._reply_id = reply_id(motor_id, model.revision)
        self._reply_base = frame_key(self._reply_id, 0)
        # A reply byte another command's reply may carry (V2.35 0x9B -> 0x9A, A4) keys as that one.
        self._aliases = {
            cls.CODE: alias
            for cls in COMMAND_CLASSES
            if cls.CODE is not None and (alias := cls.REPLY_ALIASES.get(model.revision)) is not None
        }
        self.request_ids = frozenset({self._request_id})
        self.reply_ids = frozenset({self._reply_id})
        self.shared_ids = frozenset({MULTI_MOTOR_ID}) if model.revision is Revision.V2_35 else frozenset()
        self._fast: dict[int, Callable[[bytes], Any]] = _layout_decoders(model) | _status2_decoders(model)
        self._encoders = _fast_encoders(model)

    def _check(self, command: Command) -> LkCommand:
        if not isinstance(command, LkCommand):
            raise ValueError(f"{command!r} is not an LK command")
        if isinstance(command, MultiMotorTorque):
            raise ValueError("the 0x280 multi-motor torque frame goes to four motors: use FAMILY.broadcast")
        # A command that carries an encoder width must carry the motor's: its counts were checked
        # against that width, and a wider one would put counts on the wire the motor cannot hold.
        bits = getattr(command, "encoder_bits", None)
        if bits is not None and bits != self.model.encoder_bits:
            raise ValueError(
                f"{type(command).__name__}.encoder_bits={bits} contradicts the motor's "
                f"{self.model.encoder_bits}-bit encoder"
            )
        # Availability depends on the class and the command's own motor type only: check once each.
        key = (type(command), getattr(command, "motor_type", None))
        if key not in self._available:
            check_available(command, model=self.model)
            self._available.add(key)
        return command

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor.

        Raises:
            ValueError: not an LK command, the 0x280 frame, or a command this revision or motor type lacks.
        """
        message = self._check(command)
        fast = self._encoders.get(type(message))
        data = fast(message) if fast is not None else message.encode()  # (8 bytes: LK's payload())
        return classic_request(self._request_id, data)

    def reply_code_key(self, code: int) -> int:
        """The key of this motor's reply whose DATA[0] is ``code`` (a broadcast's replies)."""
        return self._reply_base | code

    def reply_key(self, command: Command) -> Hashable | None:
        """The key of the reply to ``command`` (every single-motor LK command is answered).

        Raises:
            ValueError: as :meth:`encode`.
        """
        message = self._check(command)
        code = message.CODE
        assert code is not None
        if code in _VALUE_ECHO_CODES:  # by code, as classify() must: the two keys always agree
            return echo_key(self._reply_base | code, message.encode())
        return self._reply_base | self._aliases.get(code, code)

    def timeout_s(self, command: Command) -> float:
        """How long to wait for the reply to ``command`` (longer for a class declaring ``SLOW``)."""
        rules = _RULES.get(type(command)) or _rules(type(command))
        return rules[0]

    def retry_safe(self, command: Command) -> bool:
        """True for reads (``READ``): resending them changes nothing on the motor."""
        rules = _RULES.get(type(command)) or _rules(type(command))
        return rules[1]

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """REPLY for a received frame on this motor's reply identifier, else NOT_OURS."""
        if frame.arbitration_id != self._reply_id or not frame.is_rx or frame.is_extended_id or frame.is_fd:
            return KIND_NOT_OURS, None
        data = frame.data
        if not data:
            return KIND_REPLY, None
        code = data[0]
        if code in _VALUE_ECHO_CODES:
            return KIND_REPLY, echo_key(self._reply_base | code, data)
        return KIND_REPLY, self._reply_base | self._aliases.get(code, code)

    def request_key(self, frame: Frame) -> Hashable | None:
        """The key of the reply to ``frame`` if it is another host's request to this motor (0x140+ID,
        received). None on V2.35, whose replies come on the request's own identifier: a request
        there cannot be told from a reply by its identifier."""
        if (
            frame.arbitration_id != self._request_id
            or self._request_id == self._reply_id
            or not frame.is_rx
            or frame.is_extended_id
            or frame.is_fd
            or not frame.data
        ):
            return None
        data = frame.data
        code = data[0]
        if code in _VALUE_ECHO_CODES:
            return echo_key(self._reply_base | code, data)
        return self._reply_base | self._aliases.get(code, code)

    def decode(self, frame: Frame) -> Reply:
        """The typed reply in ``frame``.

        Raises:
            ProtocolError: bytes that are not a reply of this revision and model, or another motor's frame.
        """
        data = frame.data
        if frame.arbitration_id != self._reply_id:
            raise ProtocolError(f"{frame!r} is not a frame of this motor", raw=data, motor_id=self.motor_id)
        if data:
            fast = self._fast.get(data[0])
            if fast is not None:
                try:
                    return fast(data)  # type: ignore[no-any-return]
                except Slow:
                    pass
        return decode_reply(frame.arbitration_id, data, model=self.model)


def bind(
    motor_id: int, *, revision: Revision | str | None = None, model: LkModel | None = None, link: str = "can"
) -> LkCodec:
    """The codec of LK motor ``motor_id``.

    Args:
        motor_id: 1..32.
        revision: V2_36 (default) or V2_35, as a Revision or its name; must agree with ``model``.
        model: revision, motor type (MS/MF/MH/MG) and encoder width (default: MG, 14 bits).
        link: ``"can"``.

    Raises:
        ValueError: an id outside 1..32, an unknown revision or link, or ``revision`` contradicting ``model``.
    """
    if link not in LINKS:
        raise ValueError(f"lk has no link {link!r} (links: {', '.join(LINKS)})")
    rev = find_revision("lk", REVISIONS, revision) if revision is not None else None
    return LkCodec(motor_id, resolve_model(rev, model))


def broadcast(command: Command, motors: Sequence[LkCodec]) -> Broadcast:
    """The V2.35 multi-motor torque frame (0x280) to motors 1..4; each replies with 0xA1 status 2.

    Args:
        command: a :class:`MultiMotorTorque` (the only multi-motor LK frame).
        motors: the bound codecs of the motors (ids 1..4, V2.35) whose replies to gather.

    Raises:
        ValueError: another command, a motor that is not V2.35 or not 1..4, or motor types that differ
            from the command's.
    """
    if not isinstance(command, MultiMotorTorque):
        raise ValueError(f"{type(command).__name__} has no LK broadcast form (only MultiMotorTorque)")
    motor_ids_of(motors)
    check_bus(motors)
    for motor in motors:
        if not isinstance(motor, LkCodec) or motor.revision is not Revision.V2_35:
            raise ValueError(f"{motor!r}: the 0x280 frame exists only for LK V2.35 motors")
        if motor.motor_id not in MULTI_MOTOR_IDS:
            raise ValueError(f"{motor!r}: the 0x280 frame addresses motors 1..4 only")
        if motor.model.motor_type is not command.motor_type:
            raise ValueError(
                f"{motor!r} is {motor.model.motor_type.name}, the command {command.motor_type.name}"
            )
        check_available(command, model=motor.model)
    replies: dict[int, Hashable] = {m.motor_id: m.reply_code_key(MULTI_MOTOR_REPLY_CODE) for m in motors}
    return Broadcast(Frame(arbitration_id=MULTI_MOTOR_ID, data=command.encode(), is_rx=False), replies)

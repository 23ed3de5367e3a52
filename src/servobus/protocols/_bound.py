"""The one contract between the orchestrator and every family: ``Family.bind()`` -> :class:`BoundCodec`.

A bound codec is one motor's codec (family, id, revision, model, link fixed at bind time), working on
:class:`~servobus.Frame` only. The Bus, the scheduler and the CLI use nothing else, so none of them ever
writes ``if family == ...``; :class:`BoundCodec` lists its members and what each gives.

A key is an opaque hashable (an ``int`` in the built-in families, cheap to hash): equal keys mean "this
frame can answer that request". The key of a reply that echoes the value its request wrote holds the
echoed bytes (:func:`echo_key`): without sequence numbers, that is what keeps a stray echo (a request
the motor received twice, a late reply) from answering the next write with another value.

On serial links a Frame stands for one serial message: the address byte as ``arbitration_id`` and the
message body as ``data`` (the framing adds headers and the CRC).

Sans-IO like everything below the Bus: nothing here reads a clock, awaits or does I/O.
"""

from __future__ import annotations

import enum
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

from servobus.frame import Frame
from servobus.protocols._message import Command, Reply
from servobus.protocols._restart import RestartEvidence

__all__ = [
    "EXTENDED",
    "KIND_NOT_OURS",
    "KIND_REPLY",
    "KIND_REPORT",
    "KIND_STREAM",
    "BoundCodec",
    "Broadcast",
    "FrameKind",
    "Framing",
    "StreamDeframer",
    "check_bus",
    "describe_id",
    "echo_key",
    "frame_key",
    "id_key",
]

EXTENDED = 1 << 29
"""Or-ed into an identifier in ``request_ids``/``reply_ids`` for a 29-bit (extended) identifier,
which is a different identifier space on the wire from the 11-bit ones."""


class FrameKind(enum.Enum):
    """What a received frame is to one motor's codec."""

    REPLY = "reply"  # answers a request of ours (if one with its key is pending)
    STREAM = "stream"  # an active-reply (0xB6) frame of a command the motor streams
    REPORT = "report"  # an automatic error report (MyActuator 0x9A with 0x20 index 3 on)
    NOT_OURS = "not ours"  # another motor's, another host's, our own loop-back, or no family frame


# The members as module globals for the per-frame paths (every codec's classify, the scheduler's
# intake): in CPython 3.11 ``FrameKind.REPLY`` is a metaclass attribute lookup (~55 ns), a global is
# one dict read.
KIND_REPLY = FrameKind.REPLY
"""``FrameKind.REPLY`` as a module global (a codec's ``classify`` runs per frame)."""
KIND_STREAM = FrameKind.STREAM
"""``FrameKind.STREAM`` as a module global."""
KIND_REPORT = FrameKind.REPORT
"""``FrameKind.REPORT`` as a module global."""
KIND_NOT_OURS = FrameKind.NOT_OURS
"""``FrameKind.NOT_OURS`` as a module global."""


def id_key(arbitration_id: int, is_extended_id: bool = False) -> int:
    """An identifier as listed in ``request_ids``/``reply_ids`` (extended ones carry :data:`EXTENDED`)."""
    return arbitration_id | EXTENDED if is_extended_id else arbitration_id


def frame_key(arbitration_id: int, byte: int | None = None) -> int:
    """The built-in families' match key: the identifier, and DATA[0] (or another keying byte) if any.

    ``(id << 9) | 0x100 | byte`` keeps "keyed by id and byte" apart from "keyed by id alone".
    """
    return arbitration_id << 9 if byte is None else (arbitration_id << 9) | 0x100 | byte


def echo_key(key: int, data: bytes) -> int:
    """``key`` (a :func:`frame_key`, below 2**40) narrowed by the bytes after DATA[0] of an echo reply."""
    return key | int.from_bytes(data[1:], "little") << 40


def describe_id(ident: int) -> str:
    """``0x141`` or ``0x00000064 (extended)`` for an entry of ``request_ids``/``reply_ids``."""
    if ident & EXTENDED:
        return f"0x{ident & ~EXTENDED:08X} (extended)"
    return f"0x{ident:03X}"


class StreamDeframer(Protocol):
    """Bytes in (any chunking), whole Frames out; noise is dropped and counted, never raised."""

    def feed(self, data: bytes) -> list[Frame]: ...

    def idle(self) -> list[Frame]:
        """The line went quiet: frames a timing-delimited framing (Modbus RTU) was holding back."""
        ...


@runtime_checkable
class Framing(Protocol):
    """How a serial link carries Frames: chosen by the family, used by the serial transport."""

    name: str

    def encode(self, frame: Frame) -> bytes:
        """The bytes on the wire for ``frame`` (header, address, body, CRC)."""
        ...

    def deframer(self) -> StreamDeframer:
        """A fresh de-framer for one received byte stream."""
        ...


@dataclass(frozen=True, slots=True)
class Broadcast:
    """A frame addressed to several motors, and the replies it collects.

    Attributes:
        frame: what to send once.
        replies: motor id -> the key its reply carries (empty when no motor answers).
    """

    frame: Frame
    replies: dict[int, Hashable]


class BoundCodec(Protocol):
    """One motor's codec (family, id, revision, model, link fixed at bind time), working on Frames:
    all the Bus, the scheduler and the CLI ask of a family.

    * ``encode(command)``: the Frame to send (values already checked by the command class)
    * ``reply_key(command)``: the key the reply will carry, or None when no reply comes
    * ``classify(frame)``: ``(FrameKind, key)`` from ids and DATA[0] (and the echoed bytes of a reply that
      echoes a written value), no payload decode
    * ``decode(frame)``: the typed reply (``ProtocolError`` for bytes that do not decode)
    * ``timeout_s(command)``: how long a reply may take (brake release, ROM writes: longer)
    * ``retry_safe(command)``: True only for commands that change nothing (reads)
    * ``note_sent(command)``: tell the codec a command left (0xB6 streams, 0x9A reports change what the
      motor's frames mean)
    * ``may_echo(command)``: True when a reply that is ``command``'s own bytes would be the motor echoing it
      unexecuted: ``Command.NEVER_ECHOED``, or ``echoing`` (the family saw its motor say it will echo the
      next command: MyActuator's 0xF1)
    * ``safe_command(kind)``: the command that stops the motor: ``"stop"``, ``"shutdown"`` or ``"brake"``
      (ValueError where the motor has no such command)
    * ``request_key(frame)``: the key of the reply this motor will give to ``frame``, a request of ANOTHER
      host to it (None: not one, or can't be told from a reply)
    * ``request_ids`` / ``reply_ids``: this motor's own identifiers (filters, the collision check)
    * ``shared_ids``: identifiers every motor of the family uses (broadcasts, a host id)
    * ``framing``: serial links: Frame <-> bytes on the wire; None on CAN

    A key is an opaque hashable: equal keys mean "this frame can answer that request"
    (:func:`id_key`, :func:`frame_key`, :func:`echo_key`).
    """

    @property
    def family(self) -> str: ...

    @property
    def motor_id(self) -> int: ...

    @property
    def revision(self) -> enum.Enum: ...

    @property
    def model(self) -> Any: ...

    @property
    def link(self) -> str: ...

    @property
    def request_ids(self) -> frozenset[int]: ...

    @property
    def reply_ids(self) -> frozenset[int]: ...

    @property
    def shared_ids(self) -> frozenset[int]: ...

    @property
    def framing(self) -> Framing | None: ...

    @property
    def echoing(self) -> bool: ...

    def encode(self, command: Command) -> Frame: ...

    def reply_key(self, command: Command) -> Hashable | None: ...

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]: ...

    def decode(self, frame: Frame) -> Reply: ...

    def timeout_s(self, command: Command) -> float: ...

    def retry_safe(self, command: Command) -> bool: ...

    def note_sent(self, command: Command) -> None: ...

    def may_echo(self, command: Command) -> bool: ...

    def safe_command(self, kind: str = "stop") -> Command: ...

    @property
    def streams(self) -> frozenset[int]: ...


class CodecBase:
    """What the built-in bound codecs share: the contract's public attributes, and the defaults of a
    family whose motors never stream or report (``streams`` empty, ``note_sent`` a no-op)."""

    __slots__ = (
        "framing",
        "link",
        "model",
        "motor_id",
        "reply_ids",
        "request_ids",
        "revision",
        "shared_ids",
    )
    family: str
    framing: Framing | None
    link: str
    model: Any
    motor_id: int
    reply_ids: frozenset[int]
    request_ids: frozenset[int]
    revision: enum.Enum
    shared_ids: frozenset[int]

    def __repr__(self) -> str:
        return f"<{self.family} motor {self.motor_id} {self.revision.name} {self.link}>"

    @property
    def streams(self) -> frozenset[int]:
        """The command bytes the motor streams (none, unless the family overrides this)."""
        return frozenset()

    def note_sent(self, command: Command) -> None:
        """Nothing the family's commands change alters how its frames are classified."""

    #: The motor said it will echo its next command unexecuted (MyActuator: an 0xF1 frame; the
    #: family's ``classify`` sets it, and clears it at the motor's next reply). False in families
    #: whose motors never say so.
    echoing: bool = False

    def may_echo(self, command: Command) -> bool:
        """Whether a reply equal to ``command``'s bytes means it was not executed: its class says
        so (``NEVER_ECHOED``), or the motor said it will echo its next command (``echoing``)."""
        return command.NEVER_ECHOED or self.echoing

    def request_key(self, frame: Frame) -> Hashable | None:
        """The key of the reply this motor will give to ``frame``, a request another host sent it
        (CAN is broadcast: the adapter receives other nodes' requests), or None: not a request to
        this motor, one it will not answer, or one this family cannot tell from a reply (a family
        without the method: the scheduler counts such frames ``foreign``, as before)."""
        return None

    def encode(self, command: Command) -> Frame:
        raise NotImplementedError

    def decode(self, frame: Frame) -> Reply:
        raise NotImplementedError

    #: what proves that the motor restarted, per family (servobus.bus.restarts; None: nothing does)
    RESTART: ClassVar[RestartEvidence | None] = None

    #: kind -> a function building the command, per family (see :meth:`safe_command`)
    SAFE_COMMANDS: ClassVar[dict[str, Any]] = {}

    def safe_command(self, kind: str = "stop") -> Command:
        """The command that makes this motor safe: ``"stop"`` (hold, output off), ``"shutdown"``
        (motor off) or ``"brake"`` (lock the brake).

        Raises:
            ValueError: an unknown kind, or one this motor's family or revision has no command for.
        """
        build = self.SAFE_COMMANDS.get(kind)
        if build is None:
            known = ", ".join(sorted(self.SAFE_COMMANDS))
            raise ValueError(f"{self.family} motors have no {kind!r} safe command (known: {known})")
        command: Command = build(self)
        self.encode(command)  # refused now (revision, link), not when the motors must stop
        return command

    def decode_many(self, frames: Sequence[Frame]) -> list[Reply]:
        """:meth:`decode` of each frame."""
        return [self.decode(f) for f in frames]


def _medium(codec: BoundCodec) -> str:
    """What a motor's frames travel on: ``"CAN"``, or the serial framing's name."""
    framing = codec.framing
    return "CAN" if framing is None else f"the {framing.name} serial line"


def _name(codec: BoundCodec) -> str:
    return f"{codec.family} motor {codec.motor_id} ({codec.revision.name}, {codec.link})"


def check_bus(codecs: Iterable[BoundCodec]) -> None:
    """Refuse motors that cannot share one bus: some frame would belong to two of them.

    Motors on different media (CAN, or a serial line's framing) never share a bus. Two motors collide
    when an identifier one of them sends or takes (its own requests and replies)
    is also one of the other's, or is an identifier the other's family uses for every motor (0x280,
    0x300, a hollow host id); and two families collide when they use the same shared identifier for
    different things (MyActuator's 0x280 broadcast is LK V2.35's multi-motor torque frame). Motors of
    one family share their family's shared identifiers by design.

    Raises:
        ValueError: naming both motors and the identifier.
    """
    seen: list[BoundCodec] = []
    for codec in codecs:
        own = codec.request_ids | codec.reply_ids
        for other in seen:
            if _medium(codec) != _medium(other):  # CAN ids and serial addresses are different spaces
                raise ValueError(
                    f"{_name(other)} and {_name(codec)} cannot share a bus: one is on "
                    f"{_medium(other)}, the other on {_medium(codec)}"
                )
            other_own = other.request_ids | other.reply_ids
            clash = own & other_own
            why = "both use"
            if not clash:
                clash = own & other.shared_ids or other_own & codec.shared_ids
                why = "one's own identifier is shared by the other's family:"
            if not clash and codec.family != other.family:
                clash = codec.shared_ids & other.shared_ids
                why = "the two families give different meanings to"
            if clash:
                ids = ", ".join(describe_id(i) for i in sorted(clash))
                raise ValueError(f"{_name(other)} and {_name(codec)} cannot share a bus: {why} {ids}")
        seen.append(codec)


def motor_ids_of(codecs: Sequence[BoundCodec]) -> list[int]:
    """The motor ids of ``codecs``, refusing a repeated one (helper of the families' ``broadcast``).

    Raises:
        ValueError: a motor id appears twice.
    """
    ids = [c.motor_id for c in codecs]
    if len(set(ids)) != len(ids):
        raise ValueError(f"motor ids {ids} repeat")
    return ids

"""The DM-J codec: requests and feedback told apart by identifier and payload, and one motor's bound
codec.

Identifiers (11-bit, classic CAN):

==========  ===========  =================================================================
identifier  direction    carries
==========  ===========  =================================================================
ID          host->motor  a special command (FF x 7 + code) or else a MIT set-point (1..15)
0x7FF       host->all    a state refresh; DATA[0] names the motor that answers
ID + 0x10   motor->host  motor ID's feedback (DATA[0]'s low nibble is ID again)
==========  ===========  =================================================================

Motor ids are 1..15: the feedback names only the id's low nibble, and ID + 0x10 must not be another
motor's command id. The scaling of every MIT frame is the bound motor's model's
(:mod:`servobus_dm.models`); a command made for another model is re-scaled to the motor's (and
checked against its ranges) as it is encoded.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Sequence
from typing import Any

from servobus.authoring import (
    Broadcast,
    CodecBase,
    Command,
    Frame,
    FrameKind,
    ProtocolError,
    Reply,
    claimant,
    classic_request,
    command_classes,
    frame_key,
)
from servobus_dm import messages
from servobus_dm.messages import (
    Disable,
    DmCommand,
    Feedback,
    MitControl,
    RefreshState,
    Revision,
    SpecialCommand,
)
from servobus_dm.models import DmModel, find_model

__all__ = [
    "COMMANDS",
    "FEEDBACK_OFFSET",
    "LINKS",
    "MOTOR_IDS",
    "REFRESH_ID",
    "DmCodec",
    "bind",
    "broadcast",
    "decode_reply",
    "decode_request",
    "feedback_id",
    "request_id",
]

LINKS = ("can",)
MOTOR_IDS = range(1, 16)
#: The identifier of the state refresh, shared by every motor.
REFRESH_ID = 0x7FF
#: The feedback comes on the motor's id plus this (the drive's MST_ID, as the public driver sets it).
FEEDBACK_OFFSET = 0x10
#: How long a feedback may take: the drive answers within a millisecond; a zero written to flash
#: (``SLOW``) gets longer, with room for a loaded bus.
TIMEOUT_S = 0.02
SLOW_TIMEOUT_S = 0.2

#: Every command class, in declaration order.
COMMANDS: tuple[type[DmCommand[Any]], ...] = command_classes(vars(messages).values())  # type: ignore[assignment]
#: the commands told by their whole payload (FF x 7 + code), which the motor reads before a set-point
_SPECIALS: tuple[type[SpecialCommand[Any]], ...] = tuple(c for c in COMMANDS if issubclass(c, SpecialCommand))


def request_id(motor_id: int) -> int:
    """Motor ``motor_id``'s command identifier (its id).

    Raises:
        ValueError: ``motor_id`` outside 1..15.
    """
    if isinstance(motor_id, bool) or not isinstance(motor_id, int) or motor_id not in MOTOR_IDS:
        raise ValueError(f"dm motor_id={motor_id!r} is outside 1..15")
    return motor_id


def feedback_id(motor_id: int) -> int:
    """Motor ``motor_id``'s feedback identifier, id + 0x10 (ValueError outside 1..15)."""
    return request_id(motor_id) + FEEDBACK_OFFSET


def _revision(revision: Revision | str | None) -> Revision:
    if isinstance(revision, Revision):
        return revision
    if revision is None:
        return Revision.V1
    from servobus_dm import FAMILY  # (the package imports this module first)

    found: Revision = FAMILY.revision(revision)
    return found


def decode_request(
    can_id: int, data: bytes, *, revision: Revision | str | None = None, model: DmModel | str | None = None
) -> DmCommand[Any]:
    """The command in a request frame: a refresh on 0x7FF; on a motor id a special command if the
    payload is one (as the motor reads it), else a MIT set-point scaled by ``model``.

    Raises:
        ProtocolError: not a DM-J request identifier, or bytes that do not decode.
        ValueError: an unknown revision or model.
    """
    _revision(revision)
    if can_id == REFRESH_ID:
        return RefreshState.decode(data)
    if can_id not in MOTOR_IDS:
        raise ProtocolError(f"0x{can_id:03X} is no dm request identifier", raw=data)
    special = claimant(_SPECIALS, data)
    if special is not None:
        return special.decode(data)  # type: ignore[return-value]
    return MitControl.decode(data, model=find_model(model))


def decode_reply(
    can_id: int, data: bytes, *, revision: Revision | str | None = None, model: DmModel | str | None = None
) -> Feedback:
    """The feedback in a frame on a feedback identifier (0x11..0x1F), scaled by ``model``. The
    identifier says whose it is (motor id + 0x10); D0's low nibble, which tells motors apart where
    several share one master id, is given as it came (``Feedback.motor_id``).

    Raises:
        ProtocolError: not a feedback identifier, or bytes that do not decode.
        ValueError: an unknown revision or model.
    """
    _revision(revision)
    if can_id - FEEDBACK_OFFSET not in MOTOR_IDS:
        raise ProtocolError(f"0x{can_id:03X} is no dm feedback identifier", raw=data)
    return Feedback.decode(data, model=find_model(model))


class DmCodec(CodecBase):
    """One DM-J motor on CAN (the :class:`~servobus.protocols.BoundCodec` contract), of one model."""

    family = "dm"
    SAFE_COMMANDS = {"stop": lambda codec: Disable(), "shutdown": lambda codec: Disable()}  # noqa: RUF012
    __slots__ = ("_key", "_reply_id")
    model: DmModel

    def __init__(self, motor_id: int, revision: Revision, model: DmModel) -> None:
        self._reply_id = feedback_id(motor_id)
        self._key = frame_key(self._reply_id)
        self.motor_id = motor_id
        self.revision = revision
        self.model = model
        self.link = "can"
        self.framing = None
        self.request_ids = frozenset({motor_id})
        self.reply_ids = frozenset({self._reply_id})
        self.shared_ids = frozenset({REFRESH_ID})

    def __repr__(self) -> str:
        return f"<dm motor {self.motor_id} {self.model.name}>"

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor, scaled by its model.

        Raises:
            ValueError: not a DM-J command, a value outside this motor's model's range (naming
                the field, its limits and the model), or a set-point whose payload is a special
                command's (FF x 7 + code: the motor would read it as that command).
        """
        if isinstance(command, RefreshState):
            return classic_request(REFRESH_ID, dataclasses.replace(command, motor_id=self.motor_id).encode())
        if isinstance(command, MitControl) and command.model is not self.model:
            command = dataclasses.replace(command, model=self.model)
        if not isinstance(command, DmCommand):
            raise ValueError(f"{command!r} is not a dm command")
        data = command.encode()
        special = claimant(_SPECIALS, data)
        if special is not None and not isinstance(command, special):
            # the motor reads the payload as the special command: never send it as a set-point
            raise ValueError(
                f"{command!r} encodes to {data.hex(' ').upper()}, the {special.__name__} command's payload: "
                "the motor would read it so (lower a value by one step)"
            )
        return classic_request(self.motor_id, data)

    def reply_key(self, command: Command) -> Hashable | None:
        """The feedback's key (every feedback of the motor is alike); None for a command without one.

        Raises:
            ValueError: not a DM-J command.
        """
        if not isinstance(command, DmCommand):
            raise ValueError(f"{command!r} is not a dm command")
        return None if command.REPLY is None else self._key

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """REPLY for a classic frame received on this motor's feedback identifier, NOT_OURS otherwise."""
        if (
            frame.arbitration_id != self._reply_id
            or not frame.is_rx
            or frame.is_extended_id
            or frame.is_fd
            or frame.is_serial
        ):
            return FrameKind.NOT_OURS, None
        return FrameKind.REPLY, self._key

    def decode(self, frame: Frame) -> Reply:
        """The feedback in ``frame``, scaled by this motor's model.

        Raises:
            ProtocolError: bytes that do not decode, or a frame that is not this motor's.
        """
        if frame.arbitration_id != self._reply_id:
            raise ProtocolError(
                f"{frame!r} is not a frame of this motor", raw=frame.data, motor_id=self.motor_id
            )
        return decode_reply(frame.arbitration_id, frame.data, model=self.model)

    def timeout_s(self, command: Command) -> float:
        """How long the feedback to ``command`` may take."""
        return SLOW_TIMEOUT_S if command.SLOW else TIMEOUT_S

    def retry_safe(self, command: Command) -> bool:
        """True for the refresh only: every other command drives the motor."""
        return command.READ


def bind(
    motor_id: int,
    *,
    revision: Revision | str | None = None,
    model: DmModel | str | None = None,
    link: str = "can",
) -> DmCodec:
    """DM-J motor ``motor_id``'s codec, of ``model`` (a :class:`DmModel` or its name; default DM4310).

    Raises:
        ValueError: an id outside 1..15, an unknown revision or model, or a link other than ``"can"``.
    """
    if link not in LINKS:
        raise ValueError(f"dm has no link {link!r} (links: {', '.join(LINKS)})")
    return DmCodec(request_id(motor_id), _revision(revision), find_model(model))


def broadcast(command: Command, motors: Sequence[DmCodec]) -> Broadcast:
    """Refused: a DM-J motor takes commands on its own id only (the refresh names one motor).

    Raises:
        ValueError: always.
    """
    raise ValueError("dm motors have no broadcast frame: each takes commands on its own id")

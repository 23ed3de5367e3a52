"""Decoding CAN and CAN FD payloads of the hollow family, and building their frames.

The hollow family is not DATA[0]-keyed like the other families: its frames are told apart by
payload length, identifier kind (standard/extended), the FD flag and the special-command pattern
(hollow.md §3-§7). So the decoders take those flags as keywords::

    decode_request(can_id, data, *, is_extended_id=False, is_fd=False,
                   revision=Revision.HO_SERIES, model=DEFAULT_MODEL, can_mode=CanMode.NORMAL)
    decode_reply(can_id, data, *, is_extended_id=False, is_fd=False,
                 revision=Revision.HO_SERIES, model=DEFAULT_MODEL)

and :func:`decode_request_frame` / :func:`decode_reply_frame` take a :class:`servobus.Frame`.

Requests (arbitration id = motor id, 0..100):

==========  ========  =======  =================================================================
id kind     FD        length   request
==========  ========  =======  =================================================================
standard    no        8        ``FF x7 F9..FE`` special command, else a setpoint: absolute
                               (:class:`Setpoint`) in normal ``can_mode``, an increment
                               (:class:`IncrementalSetpoint`) in extended mode
extended    either    6..8     D0 = 0, D1 = 1..4: :class:`PiMultiplier`; 8 bytes otherwise:
                               :class:`CanModeSwitch` (§5.1, A17)
standard    yes       16       :class:`FdCommand`
==========  ========  =======  =================================================================

Replies (on the host id, standard identifier): 6 bytes :class:`NormalReply`, 8 bytes
:class:`ExtendedReply`, 16 FD bytes :class:`FdReply`.

The RS-485 converter's framings live in :mod:`servobus.protocols.hollow.rs485`.
"""

from __future__ import annotations

from enum import Enum
from functools import cache

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.hollow.commands import CanMode, HollowCommand, claimant
from servobus.protocols.hollow.commands_fd import FD_PAYLOAD_SIZE
from servobus.protocols.hollow.ids import MOTOR_IDS, check_host_id, request_id
from servobus.protocols.hollow.model import DEFAULT_MODEL, HollowModel
from servobus.protocols.hollow.replies import HollowReply, reply_classes

__all__ = [
    "DEFAULT_REVISION",
    "Revision",
    "decode_reply",
    "decode_reply_frame",
    "decode_request",
    "decode_request_frame",
    "reply_frame",
    "request_frame",
]


class Revision(Enum):
    """Protocol revisions of the hollow family.

    There is one manual, "Instructions for use of hollow series motor control" (seed 004), and it
    carries no version number or date: it identifies only the product line, the hollow ("HO") series
    (its model names are HO4307, HO5515, HO2212, HO6213). The one revision is named after that, so
    ``FAMILY`` has the same shape as the versioned families and a later manual can add a member.
    """

    HO_SERIES = "hollow series manual"


DEFAULT_REVISION = Revision.HO_SERIES
_SETPOINT_SIZE = 8


def _check_revision(revision: object) -> None:
    if not isinstance(revision, Revision):
        raise ValueError(f"revision={revision!r} is not one of {', '.join(r.name for r in Revision)}")


def decode_request(
    can_id: int,
    data: bytes,
    *,
    is_extended_id: bool = False,
    is_fd: bool = False,
    revision: Revision = DEFAULT_REVISION,
    model: HollowModel = DEFAULT_MODEL,
    can_mode: CanMode = CanMode.NORMAL,
) -> HollowCommand:
    """Decode a request payload as the motor does (the simulator's side).

    Args:
        can_id: the arbitration id: the motor id, 0..100, for every request (§3).
        data: the payload.
        is_extended_id: the frame has a 29-bit identifier (mode switch, PI frames).
        is_fd: the frame is CAN FD.
        revision: the protocol revision (one so far).
        model: the motor model whose scales apply.
        can_mode: the receiving motor's classic-CAN mode; it decides whether a setpoint's P is a
            position or an increment (§5.2). Power-up default: normal.

    Returns:
        The typed request.

    Raises:
        ProtocolError: an id outside 0..100, a length or frame kind that no request has, or a
            payload its decoder refuses.
        ValueError: ``revision`` is not a :class:`Revision`.
    """
    _check_revision(revision)
    data = bytes(data)
    if can_id not in MOTOR_IDS:
        raise ProtocolError(f"request id {can_id} is not a motor id (0..100)", raw=data)
    can_mode = to_can_mode(can_mode)
    # A17: PI frames may come as classic or FD extended frames; their classes check the length.
    if not is_extended_id and is_fd and len(data) != FD_PAYLOAD_SIZE:
        raise ProtocolError(f"CAN FD request: expected 16 data bytes, got {len(data)}", raw=data)
    if not is_extended_id and not is_fd and len(data) != _SETPOINT_SIZE:
        # §3: standard-id requests have DLC 8; the motor ignores others.
        raise ProtocolError(f"standard-id request: expected 8 data bytes, got {len(data)}", raw=data)
    cls = claimant(data, extended_id=is_extended_id, fd=is_fd, can_mode=can_mode)
    return cls.decode(data, model=model)


def to_can_mode(can_mode: object) -> CanMode:
    """``can_mode`` as a CanMode.

    Raises:
        ValueError: not a CanMode.
    """
    if not isinstance(can_mode, CanMode):
        raise ValueError(f"can_mode={can_mode!r} is not a CanMode")
    return can_mode


def decode_reply(
    can_id: int,
    data: bytes,
    *,
    is_extended_id: bool = False,
    is_fd: bool = False,
    revision: Revision = DEFAULT_REVISION,
    model: HollowModel = DEFAULT_MODEL,
) -> HollowReply:
    """Decode a reply payload (the host's side).

    Args:
        can_id: the arbitration id the reply came on (the host id); any standard id is accepted,
            matching it is :func:`~servobus.protocols.hollow.ids.reply_key`'s job.
        data: the payload.
        is_extended_id: the frame has a 29-bit identifier (no reply has: §3 `[I][C]`).
        is_fd: the frame is CAN FD.
        revision: the protocol revision (one so far).
        model: the motor model whose scales apply.

    Returns:
        :class:`NormalReply` (6 bytes), :class:`ExtendedReply` (8 bytes) or :class:`FdReply`
        (16 FD bytes).

    Raises:
        ProtocolError: an extended or out-of-range id, a length no reply has, or a payload its
            decoder refuses.
        ValueError: ``revision`` is not a :class:`Revision`.
    """
    _check_revision(revision)
    data = bytes(data)
    if is_extended_id or not 0 <= can_id <= 0x7FF:
        raise ProtocolError(f"reply id {can_id:#x} is not a standard identifier", raw=data)
    layouts = _reply_layouts(bool(is_fd))
    layout = layouts.get(len(data))
    if layout is None:
        sizes = " or ".join(str(size) for size in sorted(layouts))
        kind = "CAN FD" if is_fd else "classic"
        raise ProtocolError(f"{kind} reply: expected {sizes} data bytes, got {len(data)}", raw=data)
    return layout.decode(data, model=model)


@cache
def _reply_layouts(fd: bool) -> dict[int, type[HollowReply]]:
    """The reply classes of CAN FD or classic frames by payload size (§3: the size tells them apart)."""
    return {cls.SIZE: cls for cls in reply_classes() if fd == cls.FD}


def decode_request_frame(
    frame: Frame,
    *,
    revision: Revision = DEFAULT_REVISION,
    model: HollowModel = DEFAULT_MODEL,
    can_mode: CanMode = CanMode.NORMAL,
) -> HollowCommand:
    """:func:`decode_request` of a :class:`~servobus.Frame`, with its id and flags.

    Raises:
        ProtocolError: as :func:`decode_request`.
    """
    return decode_request(
        frame.arbitration_id,
        frame.data,
        is_extended_id=frame.is_extended_id,
        is_fd=frame.is_fd,
        revision=revision,
        model=model,
        can_mode=can_mode,
    )


def decode_reply_frame(
    frame: Frame, *, revision: Revision = DEFAULT_REVISION, model: HollowModel = DEFAULT_MODEL
) -> HollowReply:
    """:func:`decode_reply` of a :class:`~servobus.Frame`, with its id and flags.

    Raises:
        ProtocolError: as :func:`decode_reply`.
    """
    return decode_reply(
        frame.arbitration_id,
        frame.data,
        is_extended_id=frame.is_extended_id,
        is_fd=frame.is_fd,
        revision=revision,
        model=model,
    )


def request_frame(motor_id: int, command: HollowCommand) -> Frame:
    """The CAN frame that carries ``command`` to ``motor_id``: id kind and FD flag from the class.

    CAN FD frames switch bit rate (A28: 1 Mbit/s nominal, 5 Mbit/s data).

    Raises:
        ValueError: ``motor_id`` outside 0..100.
    """
    return Frame(
        arbitration_id=request_id(motor_id),
        data=command.encode(),
        is_extended_id=command.EXTENDED_ID,
        is_fd=command.FD,
        bitrate_switch=command.FD,
    )


def reply_frame(host_id: int, reply: HollowReply) -> Frame:
    """The CAN frame a motor sends ``reply`` in: standard id = ``host_id`` (the simulator's side).

    Raises:
        ValueError: ``host_id`` outside 0..0x7FF.
    """
    return Frame(
        arbitration_id=check_host_id(host_id),
        data=reply.encode(),
        is_fd=reply.FD,
        bitrate_switch=reply.FD,
    )

"""MyActuator arbitration identifiers and the match keys of design.md's "Matching" table.

CAN identifiers (myactuator-v4.md §1.1); motor ids are 1..32, so the ranges never overlap:

==================  ===========  ===================================================================
identifier          direction    meaning
==================  ===========  ===================================================================
0x140 + ID          host->motor  single-motor command
0x240 + ID          motor->host  reply (also to 0x280 broadcasts, 0xB6 active frames, 0x9A reports)
0x280               host->all    multi-motor command: same data, every motor replies on 0x240 + ID
0x300               host->all    0x79 CAN-ID set/read (V4.3); the manual prints the reply on 0x300 too
0x400 + ID          host->motor  motion (MIT) mode command
0x500 + ID          motor->host  motion (MIT) mode reply
==================  ===========  ===================================================================

Match keys (the scheduler pairs a reply with the outstanding request of the same key):

* CAN: ``(0x240 + ID, DATA[0])``; a 0x280 broadcast expects one such key per motor in its window.
* motion mode: ``0x500 + ID`` (one outstanding per motor; the reply has no command byte).
* 0x300 (0x79): ``(0x300, 0x79)``. The reply uses the request's own identifier, so a frame we sent
  ourselves (``Frame.is_rx`` False, looped back by the adapter) is never taken for the reply.
* RS485: ``(ID byte, DATA[0])``. A 0xCD broadcast is answered by each motor with its own ID byte.

Pure functions only: no frame is built here.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable
from enum import Enum

from servobus.frame import Frame

__all__ = [
    "BROADCAST_ID",
    "ID_SETTING_ID",
    "MOTOR_IDS",
    "RS485_BROADCAST_ID",
    "IdKind",
    "broadcast_reply_keys",
    "check_motor_id",
    "classify_id",
    "motion_reply_id",
    "motion_request_id",
    "motor_id_from_reply_id",
    "reply_id",
    "reply_key",
    "request_id",
    "request_key",
    "rs485_reply_key",
    "rs485_request_key",
]

MOTOR_IDS = range(1, 33)
REQUEST_BASE = 0x140
REPLY_BASE = 0x240
BROADCAST_ID = 0x280
ID_SETTING_ID = 0x300
MOTION_REQUEST_BASE = 0x400
MOTION_REPLY_BASE = 0x500
RS485_BROADCAST_ID = 0xCD
ID_SETTING_CODE = 0x79


class IdKind(Enum):
    """What a MyActuator CAN identifier carries."""

    REQUEST = "request"
    REPLY = "reply"
    BROADCAST = "broadcast"
    ID_SETTING = "id_setting"
    MOTION_REQUEST = "motion_request"
    MOTION_REPLY = "motion_reply"


def check_motor_id(motor_id: int) -> int:
    """Return ``motor_id`` if it is a valid motor id (1..32).

    Raises:
        ValueError: not an integer in 1..32.
    """
    if isinstance(motor_id, bool) or not isinstance(motor_id, int) or motor_id not in MOTOR_IDS:
        raise ValueError(f"motor_id={motor_id!r} is outside [1, 32]")
    return motor_id


def request_id(motor_id: int) -> int:
    """0x140 + ID: where a single-motor command goes.

    Raises:
        ValueError: motor id outside 1..32.
    """
    return REQUEST_BASE + check_motor_id(motor_id)


def reply_id(motor_id: int) -> int:
    """0x240 + ID: where a motor replies (and sends active / error frames).

    Raises:
        ValueError: motor id outside 1..32.
    """
    return REPLY_BASE + check_motor_id(motor_id)


def motion_request_id(motor_id: int) -> int:
    """0x400 + ID: motion (MIT) mode command.

    Raises:
        ValueError: motor id outside 1..32.
    """
    return MOTION_REQUEST_BASE + check_motor_id(motor_id)


def motion_reply_id(motor_id: int) -> int:
    """0x500 + ID: motion (MIT) mode reply.

    Raises:
        ValueError: motor id outside 1..32.
    """
    return MOTION_REPLY_BASE + check_motor_id(motor_id)


_BASES = (
    (REQUEST_BASE, IdKind.REQUEST),
    (REPLY_BASE, IdKind.REPLY),
    (MOTION_REQUEST_BASE, IdKind.MOTION_REQUEST),
    (MOTION_REPLY_BASE, IdKind.MOTION_REPLY),
)


def classify_id(can_id: int) -> tuple[IdKind, int | None] | None:
    """What ``can_id`` is and which motor it names.

    Returns:
        ``(kind, motor_id)``; motor_id is None for 0x280 and 0x300. None if the identifier is not one
        of this family's.
    """
    if can_id == BROADCAST_ID:
        return IdKind.BROADCAST, None
    if can_id == ID_SETTING_ID:
        return IdKind.ID_SETTING, None
    for base, kind in _BASES:
        if can_id - base in MOTOR_IDS:
            return kind, can_id - base
    return None


def motor_id_from_reply_id(can_id: int) -> int:
    """The motor id of a reply identifier 0x241..0x260 or a motion reply identifier 0x501..0x520.

    Raises:
        ValueError: ``can_id`` is neither.
    """
    found = classify_id(can_id)
    if found is None or found[0] not in (IdKind.REPLY, IdKind.MOTION_REPLY) or found[1] is None:
        raise ValueError(
            f"can_id=0x{can_id:X} is not a MyActuator reply identifier (0x241..0x260, 0x501..0x520)"
        )
    return found[1]


def request_key(can_id: int, data: bytes) -> Hashable | None:
    """The key the reply to this request will carry, or None if no single reply is expected.

    0x280 broadcasts return None: use :func:`broadcast_reply_keys`. Requests without a reply (0x76
    reset, 0xB4 baud rate, 0xB6 active reply) still get a key; whether to wait is the codec's
    ``expects_reply`` decision, not an id question.
    """
    found = classify_id(can_id)
    if found is None:
        return None
    kind, motor_id = found
    if kind is IdKind.REQUEST and data and motor_id is not None:
        return (REPLY_BASE + motor_id, data[0])
    if kind is IdKind.MOTION_REQUEST and motor_id is not None:
        return MOTION_REPLY_BASE + motor_id
    if kind is IdKind.ID_SETTING and data:
        return (ID_SETTING_ID, data[0])
    return None


def broadcast_reply_keys(data: bytes, motor_ids: Iterable[int]) -> dict[int, Hashable]:
    """The keys of the replies a 0x280 broadcast of ``data`` collects, one per motor id.

    Raises:
        ValueError: empty data, or a motor id outside 1..32.
    """
    if not data:
        raise ValueError("a broadcast needs DATA[0]")
    return {m: (reply_id(m), data[0]) for m in motor_ids}


def reply_key(frame: Frame) -> Hashable | None:
    """The key of a received frame, or None if it is not a reply of this family.

    Our own transmitted frames (``is_rx`` False) are never replies; this matters on 0x300, where the
    0x79 reply uses the request's identifier.
    """
    if frame.is_extended_id or frame.is_fd or not frame.is_rx:
        return None
    found = classify_id(frame.arbitration_id)
    if found is None:
        return None
    kind = found[0]
    if kind is IdKind.REPLY and frame.data:
        return (frame.arbitration_id, frame.data[0])
    if kind is IdKind.MOTION_REPLY:
        return frame.arbitration_id
    if kind is IdKind.ID_SETTING and frame.data and frame.data[0] == ID_SETTING_CODE:
        return (ID_SETTING_ID, ID_SETTING_CODE)
    return None


def rs485_request_key(motor_id: int, data: bytes) -> Hashable | None:
    """The key of the reply to an RS485 request sent with ID byte ``motor_id``.

    0xCD broadcasts return None (each motor answers with its own ID byte), except 0x79, whose reply
    keeps the 0xCD ID byte (myactuator-v4.md §4.38).
    """
    if not data:
        return None
    if motor_id == RS485_BROADCAST_ID:
        return (RS485_BROADCAST_ID, data[0]) if data[0] == ID_SETTING_CODE else None
    return (motor_id, data[0]) if motor_id in MOTOR_IDS else None


def rs485_reply_key(motor_id: int, data: bytes) -> Hashable | None:
    """The key of a received RS485 frame's (ID byte, DATA), or None if it cannot be a reply."""
    if not data:
        return None
    if motor_id in MOTOR_IDS or (motor_id == RS485_BROADCAST_ID and data[0] == ID_SETTING_CODE):
        return (motor_id, data[0])
    return None

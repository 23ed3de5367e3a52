"""LK arbitration identifiers and the match keys of design.md's "Matching" table.

Requests go to 0x140+ID (ID 1..32) in both revisions. Replies come from 0x180+ID on V2.36 and from
the request's own identifier 0x140+ID on V2.35 (spec §1.1, D1). The 0x280 multi-motor frame
(V2.35 only) is answered by motors 1..4, each on 0x140+ID with DATA[0] = 0xA1, in ascending order
(spec §5). A reply is keyed by ``(reply identifier, DATA[0])``.

The V2.35 echo problem: reply and request share the identifier, and for many commands (0x80, 0x81,
0x88, 0x95, 0x34, 0x91 ...) the reply's bytes equal the request's. Bytes cannot tell them apart;
direction can. :func:`reply_key` keys only received frames (``Frame.is_rx``, python-can's flag:
False marks our own transmission looped back by the adapter), so our own request is never taken
for its reply.

Residual risk (V2.35): another host on the same bus sending a request to 0x140+ID produces a
received frame (``is_rx=True``) that is indistinguishable from the motor's reply, bytes and
identifier alike. It will be keyed as a reply (and, if its command byte matches one we wait for,
resolve our request with the other host's set-point). Nothing in the frame can prevent this; run
V2.35 motors with a single host per bus, or use V2.36 firmware, whose replies have their own
identifiers.
"""

from __future__ import annotations

from servobus.frame import Frame
from servobus.protocols._fields import check_choice
from servobus.protocols.lk.classes import REQUESTS
from servobus.protocols.lk.model import Revision

__all__ = [
    "MOTOR_IDS",
    "MULTI_MOTOR_ID",
    "MULTI_MOTOR_IDS",
    "MULTI_MOTOR_REPLY_CODE",
    "REQUEST_BASE",
    "is_reply_id",
    "is_request_id",
    "match_key",
    "motor_id_from_reply_id",
    "motor_id_from_request_id",
    "multi_motor_reply_keys",
    "reply_id",
    "reply_key",
    "request_id",
    "request_keys",
]

REQUEST_BASE = 0x140
_REPLY_BASE = {Revision.V2_36: 0x180, Revision.V2_35: 0x140}
MOTOR_IDS = range(1, 33)
MULTI_MOTOR_ID = 0x280
MULTI_MOTOR_IDS = range(1, 5)
MULTI_MOTOR_REPLY_CODE = 0xA1  # spec §5: "same as the single motor torque closed-loop reply"


def _check_motor_id(motor_id: int) -> None:
    if isinstance(motor_id, bool) or not isinstance(motor_id, int):
        raise ValueError(f"motor_id={motor_id!r} is not an integer")
    check_choice("motor_id", motor_id, MOTOR_IDS)


def request_id(motor_id: int) -> int:
    """The request identifier 0x140+ID.

    Raises:
        ValueError: ``motor_id`` is not 1..32.
    """
    _check_motor_id(motor_id)
    return REQUEST_BASE + motor_id


def reply_id(motor_id: int, revision: Revision) -> int:
    """The reply identifier: 0x180+ID on V2.36, 0x140+ID on V2.35.

    Raises:
        ValueError: ``motor_id`` is not 1..32.
    """
    _check_motor_id(motor_id)
    return _REPLY_BASE[revision] + motor_id


def is_request_id(can_id: int) -> bool:
    """True for 0x141..0x160."""
    return REQUEST_BASE + 1 <= can_id <= REQUEST_BASE + 32


def is_reply_id(can_id: int, revision: Revision) -> bool:
    """True for 0x181..0x1A0 on V2.36 and 0x141..0x160 on V2.35."""
    base = _REPLY_BASE[revision]
    return base + 1 <= can_id <= base + 32


def motor_id_from_request_id(can_id: int) -> int | None:
    """The motor id addressed by a request identifier, or None if ``can_id`` is not one."""
    return can_id - REQUEST_BASE if is_request_id(can_id) else None


def motor_id_from_reply_id(can_id: int, revision: Revision) -> int | None:
    """The motor id that sent a reply on ``can_id``, or None if it is not a reply id of ``revision``."""
    return can_id - _REPLY_BASE[revision] if is_reply_id(can_id, revision) else None


def match_key(motor_id: int, command: int, revision: Revision) -> tuple[int, int]:
    """The key a reply of ``motor_id`` with DATA[0] = ``command`` has: ``(reply id, DATA[0])``.

    Raises:
        ValueError: ``motor_id`` is not 1..32.
    """
    return (reply_id(motor_id, revision), command)


def request_keys(motor_id: int, command: int, revision: Revision) -> tuple[tuple[int, int], ...]:
    """Every key the reply to request ``command`` sent to ``motor_id`` may carry.

    Normally one key, ``(reply id, command)``; a command class declaring ``REPLY_ALIASES`` for the
    revision adds the other byte (V2.35: the reply to 0x9B may say 0x9A, spec A4), so that request
    waits for either. The caller registers these keys before the frame is written.

    Raises:
        ValueError: ``motor_id`` is not 1..32.
    """
    cls = REQUESTS[revision].get(command)
    alias = cls.REPLY_ALIASES.get(revision) if cls is not None else None
    codes = (command,) if alias is None else (command, alias)
    return tuple(match_key(motor_id, code, revision) for code in codes)


def multi_motor_reply_keys(
    revision: Revision, motor_ids: range = MULTI_MOTOR_IDS
) -> tuple[tuple[int, int], ...]:
    """The keys of the replies to one 0x280 frame: ``(0x140+ID, 0xA1)`` for ID 1..4, in reply order.

    Raises:
        ValueError: ``revision`` is V2.36 (0x280 is documented only in V2.35), or an id is not 1..4.
    """
    if revision is not Revision.V2_35:
        raise ValueError(f"the 0x280 multi-motor frame is not available in {revision.name}")
    for motor_id in motor_ids:
        check_choice("motor_id", motor_id, MULTI_MOTOR_IDS)
    return tuple(match_key(motor_id, MULTI_MOTOR_REPLY_CODE, revision) for motor_id in motor_ids)


def reply_key(frame: Frame, *, revision: Revision) -> tuple[int, int] | None:
    """The match key ``(reply id, DATA[0])`` of a received frame, or None if it is not a motor reply.

    None for: our own transmitted frames looped back (``is_rx=False``; on V2.35 these carry the
    reply identifier), extended or CAN FD frames, identifiers that are not reply ids of
    ``revision`` (on V2.36 nothing on 0x140+ID is a reply), and frames without data. A keyed
    frame may still fail to decode (wrong length, unknown byte); that is the decoder's verdict.
    See the module docstring for the residual risk on V2.35.
    """
    if not frame.is_rx or frame.is_extended_id or frame.is_fd or not frame.data:
        return None
    if not is_reply_id(frame.arbitration_id, revision):
        return None
    return (frame.arbitration_id, frame.data[0])

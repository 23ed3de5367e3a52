"""Which frames the simulated LK motor takes: pure functions of the frame and the motor's settings.

:func:`ignore_reason` says why a frame is not for the motor (the counter it goes to), and
:func:`undecodable_reason` what a frame of its own that does not decode is (the counter, and the
code a status reply answers with, where the motor answers at all).
"""

from __future__ import annotations

from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import Revision
from servobus.protocols.lk.codec import REQUESTS
from servobus.protocols.lk.ids import MULTI_MOTOR_ID, MULTI_MOTOR_IDS, request_id
from servobus.protocols.lk.model import MotorType

__all__ = ["ignore_reason", "undecodable_reason"]


def ignore_reason(frame: Frame, revision: Revision, motor_id: int, *, busy: bool) -> str | None:
    """The counter a frame the motor does not take goes to (None: it takes it)."""
    if frame.is_extended_id or frame.is_fd:
        return "ignored_kind"
    if frame.arbitration_id == MULTI_MOTOR_ID:
        if revision not in lk.MultiMotorTorque.REVISIONS:
            return "other_revision"
        if motor_id not in MULTI_MOTOR_IDS:
            return "ignored_id"
    elif frame.arbitration_id != request_id(motor_id):
        return "ignored_id"
    if busy:
        return "busy"
    return None


def undecodable_reason(frame: Frame, revision: Revision, motor_type: MotorType) -> tuple[str, int | None]:
    """(the counter, the code a status-2 reply answers with or None) for a frame of the motor's own
    that did not decode."""
    data = frame.data
    code = data[0] if data and frame.arbitration_id != MULTI_MOTOR_ID else None
    ours = REQUESTS[revision]
    if code is not None and code not in ours and any(code in REQUESTS[r] for r in Revision):
        return "other_revision", None
    if code is not None and code in ours and len(data) == 8:
        # 0xA1 is "only implemented on MF, MH, MG" ([001] §10; the codec has no iq for MS on
        # either revision). The motor still answers (one reply per request, spec §1.1), idle.
        allowed = ours[code].MOTOR_TYPES.get(revision)
        if allowed is not None and motor_type not in allowed:
            return "not_implemented", code
    return "undecodable", None

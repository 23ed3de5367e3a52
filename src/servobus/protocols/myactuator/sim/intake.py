"""Which frames the simulated MyActuator motor takes, and the requests they carry.

Identifiers (§1.1): 0x140+ID requests and 0x400+ID motion commands of this motor are taken; 0x280
and 0x300 (0x79, V4.3) only while the CAN-ID filter is off, otherwise they are ``filtered``. Other
identifiers are ``ignored_id``, extended or FD frames ``ignored_kind``. A request is decoded once per
distinct frame (for the motor's revision and motion scales); one that does not decode counts as
``other_revision`` if the other revision has it, else ``undecodable``.
"""

from __future__ import annotations

import functools

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command
from servobus.protocols.myactuator import IdKind, Revision
from servobus.protocols.myactuator.codec import decode_standard_request
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_ID,
    classify_id,
    motion_reply_id,
    motion_request_id,
    reply_id,
    request_id,
)
from servobus.protocols.myactuator.sim.base import MotorBase

__all__ = ["CACHE_SIZE", "Intake", "reply_can_id"]

#: distinct requests a motor keeps decoded (and replies encoded, device.py): both are pure
CACHE_SIZE = 4096
_OTHER_REVISION = {Revision.V4_3: Revision.V4_4, Revision.V4_4: Revision.V4_3}
_classify_id = functools.lru_cache(maxsize=None)(classify_id)  # at most 0x800 standard identifiers


_reply_id = functools.lru_cache(maxsize=None)(reply_id)  # a bad id still raises (errors are not cached)


def reply_can_id(kind: IdKind, motor_id: int) -> int:
    """Where the reply to a request that came on a ``kind`` identifier goes (§1.1)."""
    if kind is IdKind.MOTION_REQUEST:
        return motion_reply_id(motor_id)
    if kind is IdKind.ID_SETTING:
        return ID_SETTING_ID  # the 0x79 examples print the reply on 0x300 (§4.38)
    return _reply_id(motor_id)


@functools.cache
def _listen_ids(motor_id: int) -> frozenset[int]:
    return frozenset((request_id(motor_id), motion_request_id(motor_id), BROADCAST_ID, ID_SETTING_ID))


class Intake(MotorBase):
    """The receiving part of :class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor`."""

    def listen_ids(self) -> frozenset[int]:
        """0x140+ID, 0x400+ID, 0x280 and 0x300 (filtered or not, it counts them): any other
        identifier is ``ignored_id`` (``ignored_kind`` if extended or FD) whatever it carries."""
        return _listen_ids(self.motor_id)

    def count_refused_bytes(self, data: bytes, *, can_id: int | None = None, rs485: bool = False) -> None:
        """Count a request this revision refused: ``other_revision`` if the other revision has it."""
        other = _OTHER_REVISION[self.revision]
        try:
            if rs485:
                decode_standard_request(data, other, id_setting_allowed=True)
            else:
                assert can_id is not None
                ma.decode_request(can_id, data, revision=other)
        except ProtocolError:
            self._counters["undecodable"] += 1
        else:
            self._counters["other_revision"] += 1

    def _route(self, frame: Frame) -> IdKind | None:
        if frame.is_extended_id or frame.is_fd:
            self._counters["ignored_kind"] += 1
            return None
        found = _classify_id(frame.arbitration_id)
        kind, motor_id = found if found else (None, None)
        if kind in (IdKind.REQUEST, IdKind.MOTION_REQUEST) and motor_id == self.motor_id:
            return kind
        if kind in (IdKind.BROADCAST, IdKind.ID_SETTING):
            if self.ram.can_id_filter:  # §1.1: with the filter on, 0x280 (and 0x300) are not received
                self._counters["filtered"] += 1
                return None
            return kind
        self._counters["ignored_id"] += 1
        return None

    def _decode(self, can_id: int, data: bytes) -> Command:
        """The request in a frame: decoded once per distinct frame (a pure function of the bytes, the
        revision and the motion scales; commands are frozen, so one object serves every time)."""
        decoded = self._decoded
        if decoded.get(None) != (self.revision, self.motion_scales):  # changed since: start over
            decoded.clear()
            decoded[None] = (self.revision, self.motion_scales)
        key = (can_id, data)
        command = decoded.get(key)
        if command is None:
            if len(decoded) > CACHE_SIZE:
                decoded.clear()
                decoded[None] = (self.revision, self.motion_scales)
            command = decoded[key] = ma.decode_request(
                can_id, data, revision=self.revision, motion_scales=self.motion_scales
            )
        assert isinstance(command, Command)
        return command

"""Restart detection of a Bus (:class:`Restarts`): a motor that comes back online is checked for a
restart, with the evidence its family declares (``codec.RESTART``, servobus.protocols._restart).

A motor whose supply sagged is silent, then answers again in its power-on state: the set-points it
held are lost (issue [field] case 2). To the watchdog it was offline and is online again, exactly like
a motor whose cable was pulled and put back, which keeps running. So when the watchdog reports a
motor online again (after it was offline), the family's probes are read in a task of the Bus, and
the family judges what was remembered before the silence against what came since. A restart is
reported once: a :class:`~servobus.bus.watchdog.MotorStatus` with reason ``"restarted"`` to
``bus.subscribe_status`` callbacks, the motor's ``restarts`` counter, ``motor.restarted_at`` and one
warning. What to send the motor again is the user's decision (docs/restarts.md has the recipe).

Nothing here runs per reply: what is judged is the motor's last reply before its silence, the reply
that brought it back, the probes' replies, and the last reply of each type the family names for the
intake to remember (``MotorRecord.remembered``: LK's 0x92, which its probes cannot give before the
silence); the rest runs on the watchdog's transitions.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from servobus.bus.watchdog import MotorStatus
from servobus.errors import ServobusError
from servobus.protocols._restart import RestartEvidence, Seen

if TYPE_CHECKING:
    from servobus.bus.engine import Engine
    from servobus.bus.motor import Motor, MotorRecord

__all__ = ["Restarts"]

logger = logging.getLogger("servobus.bus")


def evidence_of(motor: Motor) -> RestartEvidence | None:
    """The family's restart evidence for ``motor`` (None: its family declares none)."""
    return getattr(motor.codec, "RESTART", None)


class Restarts:
    """The restart checks of one Bus: a watchdog listener that checks each motor that came back.

    Args:
        engine: the Bus's engine (its clock, counters, whether the block is being left).
        spawn: ``spawn(fn, *args)`` runs ``fn(*args)`` in a task of the Bus's task group; False when
            the Bus has none (it is not open).
    """

    def __init__(self, engine: Engine, spawn: Callable[..., bool]) -> None:
        self.engine = engine
        self.name = engine.name
        self._records = engine.registry.records
        self._spawn = spawn

    def on_status(self, status: MotorStatus) -> None:
        """The watchdog's verdict on a motor: remember it at its first sighting and when it falls
        silent; check it when it comes back."""
        motor = status.motor
        if status.reason == "restarted" or evidence_of(motor) is None:
            return
        record = self._records[id(motor.codec)]
        if not status.online:
            said = {**record.readings, **record.remembered}
            if motor.state is not None:  # its last word (dated late, which only weakens a proof)
                said[type(motor.state)] = Seen(motor.state, status.at)
            record.before = said
            return
        if record.known_since is None:  # first seen: its run time (if any) starts before now
            record.known_since = status.at
            record.before = None
            return
        before, record.before = record.before, None
        if before is None or self.engine.closing or motor.state is None:
            return
        back = Seen(motor.state, status.at)  # the reply that brought it back
        self._spawn(self._check, record, before, back)

    async def _check(self, record: MotorRecord, before: dict[type, Seen], back: Seen) -> None:
        """Read the family's probes of ``record``'s motor (back online with ``back``) and judge."""
        motor = record.motor
        evidence = evidence_of(motor)
        assert evidence is not None and record.known_since is not None
        after = {kind: seen for kind, seen in record.remembered.items() if seen.at >= back.at}
        after[type(back.reply)] = back
        for probe in evidence.probes:
            try:
                reply = await motor.request(probe(), retries=1)
            except ServobusError as exc:  # offline again, streaming, the Bus closing: no verdict
                logger.debug("%s: %r: restart check not done (%s)", self.name, motor, exc)
                return
            if reply is not None:  # (kept: the next silence's "before")
                after[type(reply)] = record.readings[type(reply)] = Seen(reply, self.engine.time())
        try:
            why = evidence.judge(before, after, record.known_since)
        except Exception:  # a family's bug: no verdict, and never the end of the Bus's task group
            logger.exception("%s: %r: the restart evidence of its family failed", self.name, motor)
            return
        if why is None or self.engine.closing:
            return
        record.known_since = back.at
        motor.restarted_at = back.at
        self.engine.count(record.codec, "restarts")
        self.engine.watchdog.restarted(motor, self.engine.time(), why)

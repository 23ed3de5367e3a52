"""Restart detection of a Bus (:class:`Restarts`): a motor that comes back online is checked for a
restart, with the evidence its family declares (``codec.RESTART``, servobus.protocols._restart).

A motor whose supply sagged is silent, then answers again in its power-on state: the set-points it
held are lost (issue [field] case 2). To the watchdog it was offline and is online again, exactly like
a motor whose cable was pulled and put back, which keeps running. So when the watchdog reports a
motor online again (after it was offline), the family's probes are read in a task of the Bus, and
the family judges what was remembered before the silence against what came since. A restart is
reported once: a :class:`~servobus.watchdog.MotorStatus` with reason ``"restarted"`` to
``bus.subscribe_status`` callbacks, the motor's ``restarts`` counter, ``motor.restarted_at`` and one
warning. What to send the motor again is the user's decision (docs/restarts.md has the recipe).

Nothing here runs per reply: what is judged is the motor's last reply before its silence, the reply
that brought it back, the probes' replies, and the last reply of each type the family names for the
intake to remember (``Motor._remembered``: LK's 0x92, which its probes cannot give before the
silence); the rest runs on the watchdog's transitions.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from servobus.errors import ServobusError
from servobus.protocols._restart import RestartEvidence, Seen
from servobus.watchdog import MotorStatus

if TYPE_CHECKING:
    from servobus.bus import Bus
    from servobus.motor import Motor

__all__ = ["Restarts"]

logger = logging.getLogger("servobus.bus")


def evidence_of(motor: Motor) -> RestartEvidence | None:
    """The family's restart evidence for ``motor`` (None: its family declares none)."""
    return getattr(motor.codec, "RESTART", None)


class Restarts:
    """The restart checks of one Bus: a watchdog listener that checks each motor that came back.

    Args:
        bus: the Bus (its task group runs the checks, its watchdog reports them).
    """

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self._known_since: dict[int, float] = {}  # by codec id: running without a restart since
        self._readings: dict[int, dict[type, Seen]] = {}  # by codec id: its probes' last replies
        self._before: dict[int, dict[type, Seen]] = {}  # by codec id: what it said before its silence

    def on_status(self, status: MotorStatus) -> None:
        """The watchdog's verdict on a motor: remember it at its first sighting and when it falls
        silent; check it when it comes back."""
        motor = status.motor
        if status.reason == "restarted" or evidence_of(motor) is None:
            return
        key = id(motor.codec)
        if not status.online:
            said = {**self._readings.get(key, {}), **motor._remembered}
            if motor.state is not None:  # its last word (dated late, which only weakens a proof)
                said[type(motor.state)] = Seen(motor.state, status.at)
            self._before[key] = said
            return
        if key not in self._known_since:  # first seen: its run time (if any) starts before now
            self._known_since[key] = status.at
            self._before.pop(key, None)
            return
        before = self._before.pop(key, None)
        group = self.bus._group
        if before is None or group is None or self.bus._closing or motor.state is None:
            return
        back = Seen(motor.state, status.at)  # the reply that brought it back
        group.start_soon(self._check, motor, before, back)

    async def _check(self, motor: Motor, before: dict[type, Seen], back: Seen) -> None:
        """Read the family's probes of ``motor`` (back online with ``back``) and judge."""
        evidence = evidence_of(motor)
        assert evidence is not None
        key = id(motor.codec)
        after = {kind: seen for kind, seen in motor._remembered.items() if seen.at >= back.at}
        after[type(back.reply)] = back
        for probe in evidence.probes:
            try:
                reply = await motor.request(probe(), retries=1)
            except ServobusError as exc:  # offline again, streaming, the Bus closing: no verdict
                logger.debug("%s: %r: restart check not done (%s)", self.bus.name, motor, exc)
                return
            if reply is not None:  # (kept: the next silence's "before")
                seen = after[type(reply)] = Seen(reply, self.bus._now())
                self._readings.setdefault(key, {})[type(reply)] = seen
        try:
            why = evidence.judge(before, after, self._known_since[key])
        except Exception:  # a family's bug: no verdict, and never the end of the Bus's task group
            logger.exception("%s: %r: the restart evidence of its family failed", self.bus.name, motor)
            return
        if why is None or self.bus._closing:
            return
        self._known_since[key] = back.at
        motor.restarted_at = back.at
        self.bus.scheduler.motor_counts[key]["restarts"] += 1
        self.bus._watchdog.restarted(motor, self.bus._now(), why)

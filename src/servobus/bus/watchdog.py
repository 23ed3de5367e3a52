"""The host-side watchdog of a Bus: a motor that misses replies, or is silent too long, is marked
offline; one that answers is online again (:class:`Watchdog`).

It keeps no timer of its own: :attr:`Watchdog.silence_at` says when the silence check is next due,
and the Bus's one timer task (servobus.bus.engine) calls :meth:`Watchdog.check_silence` then.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from servobus.timing import format_duration

if TYPE_CHECKING:
    from servobus.bus.motor import Motor, MotorRecord

__all__ = ["MotorStatus", "Watchdog"]

logger = logging.getLogger("servobus.bus")


@dataclass(frozen=True, slots=True)
class MotorStatus:
    """A motor went offline (missed replies, or silent too long), came back (it answered), or is
    found to have restarted.

    Attributes:
        motor: the motor.
        online: its new state.
        at: when (the loop's clock).
        reason: why, in words (``"3 replies missed"``, ``"silent for 500 ms"``, ``"answered"``), or
            ``"restarted"``: the motor, back online, had restarted (servobus.bus.restarts; it follows
            its ``"answered"``), so the set-points it held are lost; or
            what the motor said of itself while it stays online or offline (``"communication
            watchdog tripped (0xF1)"``: its output is off until it executes a command again).
    """

    motor: Motor
    online: bool
    at: float
    reason: str


class Watchdog:
    """Misses and silence of the motors of one bus.

    Args:
        name: the bus's label, for the log.
        motors: the motors to watch (read when the silence check runs).
        offline_after_misses: replies missed in a row after which a motor is offline.
        offline_after_s: silence after which a motor that answered before is offline (None: never).
        rearm: called when :attr:`silence_at` was set (the timer that honours it re-arms).
    """

    def __init__(
        self,
        name: str,
        motors: Callable[[], Iterable[Motor]],
        *,
        offline_after_misses: int,
        offline_after_s: float | None,
        rearm: Callable[[], object] = lambda: None,
    ) -> None:
        if offline_after_misses < 1:
            raise ValueError(f"offline_after_misses={offline_after_misses} must be at least 1")
        if offline_after_s is not None and offline_after_s <= 0:
            raise ValueError(f"offline_after_s={offline_after_s} must be positive (or None)")
        self.name = name
        self.offline_after_misses = offline_after_misses
        self.offline_after_s = offline_after_s
        self.listeners: list[Callable[[MotorStatus], object]] = []
        #: when the silence check is next due: the online motor heard from longest ago turns silent
        #: then (None: no check armed)
        self.silence_at: float | None = None
        self._motors = motors
        self.rearm = rearm

    def missed(self, record: MotorRecord, now: float) -> None:
        """``record``'s motor missed a reply (its request timed out)."""
        record.misses += 1
        motor = record.motor
        if record.misses >= self.offline_after_misses and motor.online is not False:
            self.set_status(motor, False, now, f"{record.misses} replies missed")

    def answered(self, record: MotorRecord, now: float) -> None:
        """A frame of ``record``'s motor came (its ``last_seen`` is set)."""
        record.misses = 0
        motor = record.motor
        if motor.online is not True:
            self.set_status(motor, True, now, "answered")

    def set_status(self, motor: Motor, online: bool, at: float, reason: str) -> None:
        motor.online = online
        status = MotorStatus(motor, online, at, reason)
        (logger.info if online else logger.warning)(
            "%s: %r %s (%s)", self.name, motor, "online" if online else "offline", reason
        )
        self._tell(status)
        if online:
            self.arm_silence()

    def restarted(self, motor: Motor, at: float, evidence: str) -> None:
        """``motor``, back online, had restarted (servobus.bus.restarts found ``evidence``): told once."""
        logger.warning("%s: %r restarted (%s): what it was told before is lost", self.name, motor, evidence)
        self._tell(MotorStatus(motor, True, at, "restarted"))

    def event(self, motor: Motor, at: float, reason: str) -> None:
        """Tell the listeners what happened to ``motor`` that leaves it online as it is (``reason``:
        ``"communication watchdog tripped (0xF1)"``; the caller logs it)."""
        self._tell(MotorStatus(motor, motor.online is not False, at, reason))

    def _tell(self, status: MotorStatus) -> None:
        for callback in self.listeners:
            try:
                callback(status)
            except Exception:  # a listener's bug must not stop the reader
                logger.exception("%s: status listener %r failed", self.name, callback)

    def arm_silence(self) -> None:
        """Time the silence check for the online motor heard from longest ago (if none is armed)."""
        if self.offline_after_s is None or self.silence_at is not None:
            return
        heard = [m.last_seen for m in self._motors() if m.online and m.last_seen is not None]
        if heard:
            self.silence_at = min(heard) + self.offline_after_s
            self.rearm()

    def check_silence(self, now: float) -> None:
        """The silence check is due (``now >= silence_at``): every online motor silent since then
        is offline; the check is armed again for the others."""
        at, self.silence_at = self.silence_at, None
        if at is None or self.offline_after_s is None:
            return
        silent = self.offline_after_s
        for motor in self._motors():
            if motor.online and motor.last_seen is not None and motor.last_seen + silent <= at:
                self.set_status(motor, False, now, f"silent for {format_duration(silent)}")
        self.arm_silence()

    def stop(self) -> None:
        """The Bus closed: no check is due."""
        self.silence_at = None

"""A CAN link's bus-off state: a condition of the open link, not a lost device (private).

A controller that saw too many errors goes bus-off and sends nothing until it is restarted (by
itself, SocketCAN's ``restart-ms``, or by its driver). The transport hears of it from a BUS_OFF
error frame or from a send the adapter refused with ENETDOWN, and of the restart from a RESTARTED
error frame or from a send that went through. Meanwhile the link stays OPEN (no close, no reopen,
no frame lost on the receive side) and sends fail at once with :class:`BusOffError`, counted
``bus_off_dropped`` and reported ``"bus_off"``, except one frame every ``bus_off_probe_s`` that goes
to the adapter: the restart of an adapter that reports no error frames is found by it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from servobus.timing import format_duration
from servobus.transports._sending import BusOffError
from servobus.transports.events import BusOff, BusRestarted, CanErrorClass, ErrorFrame, TransportEvent
from servobus.transports.stats import TransportStats

__all__ = ["BusOffState"]

logger = logging.getLogger("servobus.transports")


class BusOffState:
    """One CAN link's bus-off state (sans-IO: times are given).

    Args:
        name: the link's, for errors and logs.
        stats: the link's counters (``bus_off``, ``restarted``, ``error_frames``, ``bus_off_dropped``).
        emit: the link's events (``BusOff``, ``BusRestarted``, ``ErrorFrame``).
        probe_s: while bus-off, one frame this often still goes to the adapter.
    """

    __slots__ = ("_back_at", "_emit", "_name", "_probe_at", "_stats", "probe_s", "since")

    def __init__(
        self, name: str, stats: TransportStats, emit: Callable[[TransportEvent], None], probe_s: float
    ) -> None:
        self._name = name
        self._stats = stats
        self._emit = emit
        self.probe_s = probe_s
        #: when the controller went bus-off (loop clock), None while it is not (read on every send)
        self.since: float | None = None
        self._probe_at = 0.0
        #: when it last came back: a refusal from before then (a worker thread's report that crossed
        #: the RESTARTED error frame on its way to the loop) is old news
        self._back_at = -math.inf

    def gate(self, now: float) -> None:
        """A send while bus-off: refused at once, but for one probe every ``probe_s``.

        Raises:
            BusOffError: the frame is not sent (counted ``bus_off_dropped``).
        """
        if now >= self._probe_at:
            self._probe_at = now + self.probe_s
            return
        self._stats.bus_off_dropped += 1
        raise BusOffError(f"{self._name}: the CAN controller is bus-off (since {self.since:.3f})")

    def error_frame(self, classes: CanErrorClass, data: bytes, at: float) -> None:
        """An error frame from the adapter: counted, an event, and the bus-off state it reports."""
        self._stats.error_frames += 1
        self._emit(ErrorFrame(at, classes, data))
        if CanErrorClass.BUS_OFF in classes:
            self.went_off(at)
        elif CanErrorClass.RESTARTED in classes:
            self.came_back(at)

    def went_off(self, at: float, cause: BaseException | None = None) -> None:
        """The controller is bus-off since ``at`` (an error frame, or a send refused with ENETDOWN)."""
        if self.since is not None or at < self._back_at:
            return
        self.since = at
        self._probe_at = at + self.probe_s
        self._stats.bus_off += 1
        logger.warning("%s: the CAN controller is bus-off%s", self._name, f" ({cause})" if cause else "")
        self._emit(BusOff(at))

    def came_back(self, at: float) -> None:
        """The controller restarted at ``at`` (a RESTARTED error frame, or a send that went through)."""
        since = self.since
        if since is None:
            return
        self.since = None
        self._back_at = at
        self._stats.restarted += 1
        took = format_duration(at - since)
        logger.info("%s: the CAN controller restarted after %s bus-off", self._name, took)
        self._emit(BusRestarted(at))

    def forget(self) -> None:
        """A new connection: a reopened controller starts error-active."""
        self.since = None

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
from typing import TYPE_CHECKING, ClassVar

from servobus.transports._sending import BusOffError
from servobus.transports.events import BusOff, BusRestarted, CanErrorClass, ErrorFrame, TransportEvent
from servobus.transports.stats import TransportStats

__all__ = ["BusOffState"]

logger = logging.getLogger("servobus.transports")


class BusOffState:
    """Bus-off bookkeeping of a transport (a base class of Transport; sans-IO: times are given)."""

    name: str
    _stats: TransportStats

    #: while bus-off, one frame this often still goes to the adapter (the others fail at once)
    bus_off_probe_s: ClassVar[float] = 0.02

    #: when the controller went bus-off (loop clock), None while it is not
    _off_since: float | None = None
    _probe_at = 0.0
    #: when it last came back: a refusal from before then (a worker thread's report that crossed the
    #: RESTARTED error frame on its way to the loop) is old news
    _back_at = -math.inf

    if TYPE_CHECKING:  # (the transport's; declared here for the type checker only)

        def _emit(self, event: TransportEvent) -> None: ...

    @property
    def bus_off(self) -> bool:
        """True while the CAN controller is bus-off (sends fail fast with BusOffError)."""
        return self._off_since is not None

    def _bus_off_gate(self, now: float) -> None:
        """A send while bus-off: refused at once, but for one probe every ``bus_off_probe_s``.

        Raises:
            BusOffError: the frame is not sent (counted ``bus_off_dropped``).
        """
        if now >= self._probe_at:
            self._probe_at = now + self.bus_off_probe_s
            return
        self._stats.bus_off_dropped += 1
        raise BusOffError(f"{self.name}: the CAN controller is bus-off (since {self._off_since:.3f})")

    def _note_error_frame(self, classes: CanErrorClass, data: bytes, at: float) -> None:
        """An error frame from the adapter: counted, an event, and the bus-off state it reports."""
        self._stats.error_frames += 1
        self._emit(ErrorFrame(at, classes, data))
        if CanErrorClass.BUS_OFF in classes:
            self._went_bus_off(at)
        elif CanErrorClass.RESTARTED in classes:
            self._came_back(at)

    def _went_bus_off(self, at: float, cause: BaseException | None = None) -> None:
        if self._off_since is not None or at < self._back_at:
            return
        self._off_since = at
        self._probe_at = at + self.bus_off_probe_s
        self._stats.bus_off += 1
        logger.warning("%s: the CAN controller is bus-off%s", self.name, f" ({cause})" if cause else "")
        self._emit(BusOff(at))

    def _came_back(self, at: float) -> None:
        since = self._off_since
        if since is None:
            return
        self._off_since = None
        self._back_at = at
        self._stats.restarted += 1
        logger.info("%s: the CAN controller restarted after %.3f s bus-off", self.name, at - since)
        self._emit(BusRestarted(at))

    def _forget_bus_off(self) -> None:
        """A new connection: a reopened controller starts error-active."""
        self._off_since = None

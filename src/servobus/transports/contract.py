"""What a link must be for a Bus to drive it: :class:`FrameLink`, and the line's rules it declares.

Every servobus transport is a FrameLink, and so is any object with these members (a test double, a
bench reflector, a user's own adapter). The Bus reads nothing else of it.

* **The line's rules** (:class:`LineRules`, ``link.rules``): how frames share the line. The Bus
  paces, times and judges replies by them (one frame at a time on a half-duplex line, the rest
  between frames, the shortest possible round trip, how long a command may wait for its turn).
* **Sends are handles**: ``send(frame, handle)`` hands a frame over, and the send reporter is later
  called with that same ``handle`` object: ``reporter(handle, sent_at, None)`` when the frame left
  (``sent_at`` on the loop's clock), ``reporter(handle, None, reason)`` when it never will
  (``"stale"``, ``"purged"``, ...). The handle is opaque to the link: a link may copy, re-encode or
  split the frame; it echoes the handle. With no handle given, the frame itself is the handle.
* **A link that reports** (``rules.reports_sends``) reports every frame it accepted, exactly once. One
  that does not is still timed: a request's deadline then starts when it is handed over.
* **Life cycle**: ``open()`` and ``close()`` are called by the same task (a link's background tasks
  live in a task group it enters in ``open`` and leaves in ``close``); ``async with link:`` does both.
* **Delivery**: received frames go to the consumer in batches, on the loop, in arrival order.
* ``stats()``: the link's counters (:class:`~servobus.transports.stats.TransportStats`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from servobus.frame import Frame
from servobus.transports.events import TransportEvent
from servobus.transports.stats import TransportStats

__all__ = ["Consumer", "FrameLink", "LineRules", "SendReporter"]

#: ``consumer(frames)``: the frames received since the last call, oldest first.
Consumer = Callable[[list[Frame]], object]
#: ``reporter(handle, sent_at, reason)``: ``sent_at`` when the frame left, else ``reason`` it never will.
SendReporter = Callable[[object, float | None, str | None], object]


@dataclass(frozen=True, slots=True)
class LineRules:
    """How frames share a line, as the Bus needs to know it.

    Attributes:
        half_duplex: one frame on the line at a time, replies included (RS485): the Bus has one
            request in flight.
        bitrate: the line's (nominal) bits per second, when known: it sets the shortest possible
            round trip (a frame with a reply's key that comes sooner is not that reply).
        gap_s: on a half-duplex line, the rest between the end of one exchange and the next frame.
        turnaround_s: on a half-duplex line, the rest after the far end's last byte before sending.
        stale_after_s: a command (not a read) queued longer than this is not sent (None: no limit).
        reports_sends: the link calls the send reporter for every frame it accepted.
        exact_times: a send report's time is when the frame was queued on the wire itself, and a
            received frame's stamp is when it ended there, on one clock (the in-process simulator):
            our frame and another host's are ordered by their times. Through an adapter (a reader
            thread, USB, a serial line) both are off by its latency, which is not known: False.
    """

    half_duplex: bool = False
    bitrate: int | None = None
    gap_s: float = 0.0
    turnaround_s: float = 0.0
    stale_after_s: float | None = None
    reports_sends: bool = True
    exact_times: bool = False

    def __post_init__(self) -> None:
        for name in ("gap_s", "turnaround_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 0")
        if self.bitrate is not None and self.bitrate <= 0:
            raise ValueError(f"bitrate={self.bitrate} must be positive (or None)")
        if self.stale_after_s is not None and self.stale_after_s <= 0:
            raise ValueError(f"stale_after_s={self.stale_after_s} must be positive (or None)")


@runtime_checkable
class FrameLink(Protocol):
    """What the Bus needs of a transport (see the module's docstring for the rules)."""

    name: str

    @property
    def rules(self) -> LineRules: ...

    @property
    def is_open(self) -> bool: ...

    async def open(self) -> None: ...

    async def close(self) -> None: ...

    def send(self, frame: Frame, handle: object = None) -> None: ...

    def set_consumer(self, consumer: Consumer | None) -> None: ...

    def set_send_reporter(self, reporter: SendReporter | None) -> None: ...

    def add_listener(self, listener: Callable[[TransportEvent], object]) -> None: ...

    def remove_listener(self, listener: Callable[[TransportEvent], object]) -> None: ...

    def stats(self) -> TransportStats: ...

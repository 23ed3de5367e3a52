"""What a transport reports besides frames: its state, and what the bus itself says.

Events go to listeners (:meth:`~servobus.transports.base.Transport.add_listener`) or an async
stream (:meth:`~servobus.transports.base.Transport.events`). Frames never travel as events;
error frames do, decoded from the SocketCAN error-frame layout that python-can passes through.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = [
    "BusOff",
    "BusRestarted",
    "CanErrorClass",
    "ErrorFrame",
    "FramesDropped",
    "StateChanged",
    "TransportEvent",
    "TransportState",
]


class TransportState(enum.Enum):
    """Where a transport is in its life.

    ``LOST`` is the only state the transport enters by itself: the device went away. If the
    transport reopens automatically it returns to ``OPEN``; ``close()`` always ends in ``CLOSED``.
    """

    CLOSED = "closed"
    OPENING = "opening"
    OPEN = "open"
    LOST = "lost"


class CanErrorClass(enum.IntFlag):
    """Error classes of a SocketCAN error frame (``linux/can/error.h``), carried in its identifier."""

    TX_TIMEOUT = 0x001
    LOST_ARBITRATION = 0x002
    CONTROLLER = 0x004
    PROTOCOL = 0x008
    TRANSCEIVER = 0x010
    NO_ACK = 0x020
    BUS_OFF = 0x040
    BUS_ERROR = 0x080
    RESTARTED = 0x100
    COUNTERS = 0x200


@dataclass(frozen=True, slots=True)
class StateChanged:
    """The transport moved to ``state``; ``cause`` is the failure behind a move to LOST."""

    state: TransportState
    timestamp: float
    cause: BaseException | None = None


@dataclass(frozen=True, slots=True)
class ErrorFrame:
    """An error frame from the adapter (``data`` holds the SocketCAN detail bytes)."""

    timestamp: float
    classes: CanErrorClass
    data: bytes


@dataclass(frozen=True, slots=True)
class BusOff:
    """The CAN controller went bus-off (an error frame said so, or a send was refused with
    ENETDOWN): it sends nothing until it recovers or is restarted. The transport stays OPEN; sends
    fail fast meanwhile (:class:`~servobus.transports.base.BusOffError`, reason ``"bus_off"``)."""

    timestamp: float


@dataclass(frozen=True, slots=True)
class BusRestarted:
    """The CAN controller is back from bus-off (a RESTARTED error frame, or a send went through)."""

    timestamp: float


@dataclass(frozen=True, slots=True)
class FramesDropped:
    """Frames the transport dropped on purpose, by ``reason``.

    Reasons, named as their :class:`~servobus.transports.stats.TransportStats` counters:
    ``"enobufs_dropped"`` (the adapter's send buffer was full: reported ``"queue_full"``),
    ``"bus_off_dropped"`` (the controller was bus-off: reported ``"bus_off"``), ``"stale"``
    (queued longer than ``stale_after_s``), ``"purged"`` (queued when the device was lost or the
    transport closed), ``"rx_overflow"`` (received while nobody read the receive buffer, oldest first).
    """

    reason: str
    count: int
    timestamp: float


TransportEvent = StateChanged | ErrorFrame | BusOff | BusRestarted | FramesDropped

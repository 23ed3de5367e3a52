"""Transport counters and the bus-load estimate."""

from __future__ import annotations

import collections
from dataclasses import dataclass

from servobus.transports.events import TransportState

__all__ = ["LoadMeter", "TransportStats"]


@dataclass(slots=True)
class TransportStats:
    """Counters of one transport since it was created (reopens do not reset them).

    :meth:`~servobus.transports.base.Transport.stats` returns a snapshot; the transport keeps
    counting into its own copy.

    Attributes:
        state: the transport's state when the snapshot was taken.
        frames_in, frames_out: whole frames received / handed to the device.
        bytes_in, bytes_out: CAN data bytes, or every byte on a serial line.
        discarded_bytes: serial bytes that could not start a frame that checks.
        crc_errors: serial frames that failed their CRC.
        queue_depth: frames waiting in the send queue.
        bus_load_pct: share of the line's capacity used in the last second, in and out, from
            nominal frame lengths (stuff bits not counted; None when the bit rate is unknown).
        queue_full: frames refused because the send queue was full.
        stale: queued frames dropped because they waited longer than ``stale_after_s``.
        purged: queued frames dropped when the device was lost or the transport closed.
        enobufs_waits, enobufs_dropped: sends the adapter refused for a full buffer, then retried
            or not sent by the ENOBUFS policy (reported ``"queue_full"``).
        bus_off_dropped: frames not sent because the controller was bus-off (reported ``"bus_off"``).
        rx_overflow: received frames dropped because nobody read the receive buffer.
        error_frames: every error frame the adapter reported.
        bus_off, restarted: times the controller went bus-off (a BUS_OFF error frame, or a send
            refused with ENETDOWN) and came back (a RESTARTED error frame, or a send went through).
        ignored: received frames a transport does not carry (CAN remote frames).
        bad_frames: received frames or lines that do not parse (a malformed SLCAN line, a DLC that
            disagrees with the data): counted and dropped, never a lost device.
        losses, reopens: times the device was lost, and reopened.
    """

    state: TransportState = TransportState.CLOSED
    frames_in: int = 0
    frames_out: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    discarded_bytes: int = 0
    crc_errors: int = 0
    queue_depth: int = 0
    bus_load_pct: float | None = None
    queue_full: int = 0
    stale: int = 0
    purged: int = 0
    enobufs_waits: int = 0
    enobufs_dropped: int = 0
    bus_off_dropped: int = 0
    rx_overflow: int = 0
    error_frames: int = 0
    bus_off: int = 0
    restarted: int = 0
    ignored: int = 0
    bad_frames: int = 0
    losses: int = 0
    reopens: int = 0


class LoadMeter:
    """Seconds of line time used, summed over a sliding window of ``window_s``.

    Time is split into ten slots per window, so the estimate moves in tenths of a window and
    costs one comparison per frame. Timestamps come from the caller (sans-IO).
    """

    __slots__ = ("_slot_s", "_slots", "window_s")

    def __init__(self, window_s: float = 1.0) -> None:
        if window_s <= 0:
            raise ValueError(f"window_s={window_s} must be positive")
        self.window_s = window_s
        self._slot_s = window_s / 10
        self._slots: collections.deque[list[float]] = collections.deque()  # [slot index, busy seconds]

    def add(self, now_s: float, busy_s: float) -> None:
        index = now_s // self._slot_s
        if self._slots and self._slots[-1][0] == index:
            self._slots[-1][1] += busy_s
        else:
            self._slots.append([index, busy_s])
            self._expire(index)

    def percent(self, now_s: float) -> float:
        """Share of the last window the line was busy, in percent."""
        self._expire(now_s // self._slot_s)
        return 100.0 * sum(busy for _, busy in self._slots) / self.window_s

    def _expire(self, index: float) -> None:
        while self._slots and self._slots[0][0] <= index - 10:
            self._slots.popleft()

"""A CAN bus in simulated time: frames contend by identifier and occupy the wire for their bit time.

Sans-IO discrete-event model. Nodes (the host, each simulated motor) :meth:`~CanBusModel.submit`
frames with the time they are ready; :meth:`~CanBusModel.advance` returns the transmissions that
have completed by a given time. The rules a real bus follows and this model keeps:

* one frame on the wire at a time, for ``frame_time_s`` (stuff bits included, see ``timing``);
* when the bus goes idle, every node with a frame ready contends and the lowest identifier wins
  (standard before extended at the same base id, as the IDE bit decides);
* a node sends its own frames in the order it queued them (a transmit FIFO): only the head of
  each node's queue contends, so a host's burst of requests leaves in submission order;
* a transmission that has started is decided: frames submitted later cannot pre-empt it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable
from dataclasses import dataclass

from servobus.frame import Frame
from servobus.timing import frame_time_s

__all__ = ["CanBusModel", "Transmission", "arbitration_priority"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Transmission:
    """One frame's time on the wire: it started at ``start_s`` and was received by all at ``end_s``."""

    frame: Frame
    source: Hashable
    start_s: float
    end_s: float


def arbitration_priority(frame: Frame) -> tuple[int, int, int]:
    """Sort key that orders frames the way bitwise arbitration does (smaller wins).

    The 11-bit base identifier decides first; at an equal base a standard frame wins, because its
    IDE bit is dominant where an extended frame's SRR/IDE are recessive; then the 18-bit extension.
    """
    if frame.is_extended_id:
        return frame.arbitration_id >> 18, 1, frame.arbitration_id & 0x3FFFF
    return frame.arbitration_id, 0, 0


@dataclass(slots=True)
class _Queued:
    frame: Frame
    ready_s: float


class CanBusModel:
    """Arbitration and wire time of one CAN (FD) bus.

    Args:
        bitrate: nominal bit rate, bit/s (1 Mbit/s for every family's default). ``math.inf`` gives
            a zero-latency bus: frames take no wire time but still leave one at a time by priority.
        data_bitrate: CAN FD data-phase bit rate for frames with bit-rate switching.
    """

    def __init__(self, *, bitrate: float = 1_000_000, data_bitrate: float | None = None) -> None:
        if bitrate <= 0 or (data_bitrate is not None and data_bitrate <= 0):
            raise ValueError(f"bit rates must be positive (bitrate={bitrate}, data_bitrate={data_bitrate})")
        self.bitrate = bitrate
        self.data_bitrate = data_bitrate
        self.busy_s = 0.0  # total time the wire carried frames
        self.frames = 0
        self._queues: dict[Hashable, deque[_Queued]] = {}
        self._free_at = 0.0
        self._now = 0.0  # the time advance() has run to: submissions cannot be older
        self._in_flight: Transmission | None = None

    def frame_time_s(self, frame: Frame) -> float:
        return frame_time_s(frame, self.bitrate, self.data_bitrate)

    def submit(self, frame: Frame, ready_s: float, source: Hashable = "host") -> None:
        """Queue ``frame`` at node ``source``; it may start at ``ready_s`` or when the bus is free.

        Raises:
            ValueError: ``ready_s`` is earlier than the time the bus has already run to.
        """
        if ready_s < self._now:
            raise ValueError(f"ready_s={ready_s} is before the bus time {self._now} (time runs forward)")
        self._queues.setdefault(source, deque()).append(_Queued(frame, ready_s))

    @property
    def pending(self) -> int:
        """Frames queued and not yet on the wire."""
        return sum(len(q) for q in self._queues.values())

    def next_event_s(self) -> float | None:
        """When the next transmission will complete, as far as the bus knows now (None: idle).

        Tentative while that transmission has not started: a frame submitted meanwhile may win.
        """
        if self._in_flight is not None:
            return self._in_flight.end_s
        chosen = self._arbitrate()
        if chosen is None:
            return None
        _, item, start = chosen
        return start + self.frame_time_s(item.frame)

    def advance(self, until_s: float) -> list[Transmission]:
        """Run the bus up to ``until_s``; return the transmissions completed by then, in order."""
        self._now = max(self._now, until_s)
        done: list[Transmission] = []
        while True:
            if self._in_flight is None:
                chosen = self._arbitrate()
                if chosen is None or chosen[2] > until_s:
                    return done  # idle, or the next start is still open to later submissions
                self._start(*chosen)
            assert self._in_flight is not None
            if self._in_flight.end_s > until_s:
                return done
            done.append(self._in_flight)
            self._in_flight = None

    def _arbitrate(self) -> tuple[Hashable, _Queued, float] | None:
        """The next winner among the queue heads and when it starts, without committing to it."""
        heads = [(source, q[0]) for source, q in self._queues.items() if q]
        if not heads:
            return None
        start = max(self._free_at, min(item.ready_s for _, item in heads))
        contenders = [(source, item) for source, item in heads if item.ready_s <= start]
        source, winner = min(contenders, key=lambda c: arbitration_priority(c[1].frame))
        return source, winner, start

    def _start(self, source: Hashable, item: _Queued, start: float) -> None:
        self._queues[source].popleft()
        duration = self.frame_time_s(item.frame)
        self._in_flight = Transmission(frame=item.frame, source=source, start_s=start, end_s=start + duration)
        self._free_at = start + duration
        self.busy_s += duration
        self.frames += 1

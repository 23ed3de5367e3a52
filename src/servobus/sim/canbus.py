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

A frame joins its node's queue when it is submitted, or, :meth:`~CanBusModel.schedule`\\ d, at the
time it becomes ready: a node that hands a frame to its controller later (a device's turnaround)
can be told about it at once, with no event of its own at the ready time.

Cost: a frame's bit-exact wire time is computed once per distinct frame (cached), and the next
arbitration is computed once per change of the queues, however often it is asked for.
"""

from __future__ import annotations

import bisect
import heapq
import itertools
from collections.abc import Hashable
from dataclasses import dataclass

from servobus.frame import Frame
from servobus.timing import frame_time_s

__all__ = ["CanBusModel", "Transmission", "arbitration_priority"]


@dataclass(frozen=True, slots=True, kw_only=True, init=False)
class Transmission:
    """One frame's time on the wire: it started at ``start_s`` and was received by all at ``end_s``."""

    frame: Frame
    source: Hashable
    start_s: float
    end_s: float

    # One per frame on the wire: set through the slot descriptors (a frozen dataclass's generated
    # __init__ goes through object.__setattr__ per field, several times slower).
    def __init__(self, *, frame: Frame, source: Hashable, start_s: float, end_s: float) -> None:
        _SET_FRAME(self, frame)
        _SET_SOURCE(self, source)
        _SET_START(self, start_s)
        _SET_END(self, end_s)


_SET_FRAME = Transmission.frame.__set__  # type: ignore[attr-defined,misc]
_SET_SOURCE = Transmission.source.__set__  # type: ignore[attr-defined,misc]
_SET_START = Transmission.start_s.__set__  # type: ignore[attr-defined,misc]
_SET_END = Transmission.end_s.__set__  # type: ignore[attr-defined,misc]


def arbitration_priority(frame: Frame) -> tuple[int, int, int]:
    """Sort key that orders frames the way bitwise arbitration does (smaller wins).

    The 11-bit base identifier decides first; at an equal base a standard frame wins, because its
    IDE bit is dominant where an extended frame's SRR/IDE are recessive; then the 18-bit extension.
    """
    if frame.is_extended_id:
        return frame.arbitration_id >> 18, 1, frame.arbitration_id & 0x3FFFF
    return frame.arbitration_id, 0, 0


# A node's queue is a heap of (joined_s, seq, ready_s, frame): in the order the frames joined it
# (submission order for submit(), the ready time for schedule()), ties in the order they were given.
_Queued = tuple[float, int, float, Frame]
_Choice = tuple[Hashable, float, float, Frame]  # (source, start_s, duration_s, frame): the next winner
# A queue head as arbitration sees it: ((priority, the node's first (joined_s, seq)), ready_s, node).
_Rank = tuple[tuple[int, int, int], tuple[float, int]]
_Head = tuple[_Rank, float, Hashable]

#: distinct frames whose wire time is kept (the cache starts over when it is full)
FRAME_TIME_CACHE = 4096


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
        self._times: dict[tuple[int, bytes, bool, bool, bool], float] = {}  # frame time by content
        self._chosen = False
        self._bitrate = bitrate
        self._data_bitrate = data_bitrate
        self.busy_s = 0.0  # total time the wire carried frames
        self.frames = 0
        self._queues: dict[Hashable, list[_Queued]] = {}  # only nodes with frames queued
        self._heads: list[_Head] = []  # every queue's head, best arbitration rank first
        self._head_of: dict[Hashable, _Head] = {}
        # Each node's first (joined_s, seq): equal identifiers from two nodes (a collision on a real
        # bus) go to the node that queued first, whatever order the simulator learnt of them in.
        self._first: dict[Hashable, tuple[float, int]] = {}
        self._seq = itertools.count()
        self._free_at = 0.0
        self._now = 0.0  # the time advance() has run to: submissions cannot be older
        self._in_flight: Transmission | None = None
        self._choice: _Choice | None = None  # the next winner, while _chosen

    @property
    def bitrate(self) -> float:
        """Nominal bit rate, bit/s. Settable (an adapter's bit-rate command): later frames use it."""
        return self._bitrate

    @bitrate.setter
    def bitrate(self, value: float) -> None:
        self._bitrate = value
        self._rates_changed()

    @property
    def data_bitrate(self) -> float | None:
        """CAN FD data-phase bit rate (None: the nominal rate). Settable, as :attr:`bitrate`."""
        return self._data_bitrate

    @data_bitrate.setter
    def data_bitrate(self, value: float | None) -> None:
        self._data_bitrate = value
        self._rates_changed()

    def _rates_changed(self) -> None:
        self._times.clear()
        self._chosen = False  # a tentative next transmission's length changes with the rate

    def frame_time_s(self, frame: Frame) -> float:
        """Seconds ``frame`` occupies this bus (:func:`servobus.timing.frame_time_s`, cached per frame)."""
        # Keyed by a plain tuple: hashed and compared in C, unlike the dataclass's own __hash__/__eq__.
        key = (frame.arbitration_id, frame.data, frame.is_extended_id, frame.is_fd, frame.bitrate_switch)
        duration = self._times.get(key)
        if duration is None:
            if len(self._times) >= FRAME_TIME_CACHE:
                self._times.clear()
            duration = self._times[key] = frame_time_s(frame, self.bitrate, self.data_bitrate)
        return duration

    def submit(self, frame: Frame, ready_s: float, source: Hashable = "host") -> None:
        """Queue ``frame`` at node ``source`` now; it may start at ``ready_s`` or when the bus is free.

        Raises:
            ValueError: ``ready_s`` is earlier than the time the bus has already run to.
        """
        self._join(frame, ready_s, source, self._now)

    def schedule(self, frame: Frame, ready_s: float, source: Hashable = "host") -> None:
        """Queue ``frame`` at node ``source`` as of ``ready_s``: the same as :meth:`submit` called at
        ``ready_s``, behind what the node queued before then and ahead of what it queues later.

        Raises:
            ValueError: ``ready_s`` is earlier than the time the bus has already run to.
        """
        self._join(frame, ready_s, source, ready_s)

    def _join(self, frame: Frame, ready_s: float, source: Hashable, joined_s: float) -> None:
        if ready_s < self._now:
            raise ValueError(f"ready_s={ready_s} is before the bus time {self._now} (time runs forward)")
        seq = next(self._seq)
        first = self._first.get(source)
        if first is None or (joined_s, seq) < first:
            self._first[source] = (joined_s, seq)
        item = (joined_s, seq, ready_s, frame)
        queue = self._queues.get(source)
        if queue is None:
            self._queues[source] = [item]
        else:
            heapq.heappush(queue, item)
            if queue[0] is not item:
                return  # behind the head: arbitration does not see it yet
            self._heads.remove(self._head_of[source])
        self._set_head(source, item)

    def _set_head(self, source: Hashable, item: _Queued) -> None:
        frame = item[3]
        priority = arbitration_priority(frame) if frame.is_extended_id else (frame.arbitration_id, 0, 0)
        head = ((priority, self._first[source]), item[2], source)
        self._head_of[source] = head
        bisect.insort(self._heads, head)
        self._chosen = False

    @property
    def pending(self) -> int:
        """Frames queued and not yet on the wire."""
        return sum(len(q) for q in self._queues.values())

    def queued(self, source: Hashable) -> int:
        """Frames node ``source`` has queued (scheduled ones included) and not yet on the wire."""
        queue = self._queues.get(source)
        return len(queue) if queue else 0

    def head(self, source: Hashable) -> tuple[float, float] | None:
        """(joined_s, ready_s) of the frame node ``source`` sends next, or None if it has none queued."""
        queue = self._queues.get(source)
        return (queue[0][0], queue[0][2]) if queue else None

    def next_completion(self) -> tuple[float, Hashable] | None:
        """(end_s, node) of the transmission that completes next (on the wire, or tentatively next:
        see :meth:`next_event_s`), or None if the bus is idle."""
        in_flight = self._in_flight
        if in_flight is not None:
            return in_flight.end_s, in_flight.source
        chosen = self._arbitrate()
        return None if chosen is None else (chosen[1] + chosen[2], chosen[0])

    def next_event_s(self) -> float | None:
        """When the next transmission will complete, as far as the bus knows now (None: idle).

        Tentative while that transmission has not started: a frame submitted meanwhile may win.
        """
        if self._in_flight is not None:
            return self._in_flight.end_s
        chosen = self._arbitrate()
        return None if chosen is None else chosen[1] + chosen[2]

    def advance(self, until_s: float) -> list[Transmission]:
        """Run the bus up to ``until_s``; return the transmissions completed by then, in order."""
        if until_s > self._now:
            self._now = until_s
        done: list[Transmission] = []
        while True:
            if self._in_flight is None:
                chosen = self._arbitrate()
                if chosen is None or chosen[1] > until_s:
                    return done  # idle, or the next start is still open to later submissions
                self._start(chosen)
            in_flight = self._in_flight
            assert in_flight is not None
            if in_flight.end_s > until_s:
                return done
            done.append(in_flight)
            self._in_flight = None

    def _arbitrate(self) -> _Choice | None:
        """The next winner among the queue heads, when it starts and ends, without committing to it."""
        if self._chosen:
            return self._choice
        choice: _Choice | None = None
        heads = self._heads
        if heads:
            # start = max(free_at, earliest ready); the winner is the best rank ready by then.
            start = self._free_at
            for head in heads:  # best rank first: the first one ready wins
                if head[1] <= start:
                    break
            else:  # none ready while the wire is busy: the bus idles until the first is ready
                start = min(head[1] for head in heads)
                head = next(head for head in heads if head[1] <= start)
            source = head[2]
            frame = self._queues[source][0][3]
            choice = (source, start, self.frame_time_s(frame), frame)
        self._choice = choice
        self._chosen = True
        return choice

    def _start(self, chosen: _Choice) -> None:
        source, start, duration, frame = chosen
        queue = self._queues[source]
        heapq.heappop(queue)
        heads, head = self._heads, self._head_of.pop(source)
        if heads[0] is head:  # the usual winner: the best rank
            del heads[0]
        else:
            heads.remove(head)
        if queue:
            self._set_head(source, queue[0])
        else:
            del self._queues[source]
        self._chosen = False
        self._in_flight = Transmission(frame=frame, source=source, start_s=start, end_s=start + duration)
        self._free_at = start + duration
        self.busy_s += duration
        self.frames += 1

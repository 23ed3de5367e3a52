"""What a :class:`~servobus.transports.can.CanTransport` makes of the messages its reader hands over
(private): the receive side of a python-can bus, apart from the bus and the sending.

:class:`CanIntake` is the sink every reader of :mod:`servobus.transports._can_readers` hands its
``(message, time)`` batches to. It owns the identifiers wanted on an application's bus (filtered
here, not in the bus's own filters), turns messages into :class:`~servobus.frame.Frame`, counts them
into the transport's counters and bus load, and passes error frames to the transport's bus-off state.
The transport hands it what it needs at construction: its counters, its load meter, the current
connection's generation (a reader of a lost connection is ignored), and where frames, error frames
and a lost device go.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import can

from servobus.frame import Frame
from servobus.timing import nominal_frame_time_s
from servobus.transports._can_readers import Batch
from servobus.transports.events import CanErrorClass
from servobus.transports.stats import LoadMeter, TransportStats

__all__ = ["CanIntake", "exact_filters", "wanted_ids"]

#: ``error_frame(classes, data, at)``: the transport's bus-off bookkeeping of an error frame
ErrorFrameSink = Callable[[CanErrorClass, bytes, float], None]


class CanIntake:
    """Received messages to frames, for one CAN transport (the readers' sink).

    Args:
        name: the transport's, for logs and reader threads.
        stats, load: the transport's counters and bus-load meter (counted into here).
        generation: the transport's current connection (batches of an older one are ignored).
        deliver: hands a batch of frames to the transport's consumer or readers.
        error_frame: the transport's bus-off bookkeeping of an error frame.
        lose: the transport's loss (a reader's device failed): ``lose(cause, generation)``.
    """

    __slots__ = (
        "_deliver",
        "_error_frame",
        "_generation",
        "_load",
        "_stats",
        "bitrate",
        "data_bitrate",
        "lose",
        "name",
        "wanted",
    )

    def __init__(
        self,
        name: str,
        stats: TransportStats,
        load: LoadMeter,
        *,
        generation: Callable[[], int],
        deliver: Callable[[list[Frame]], object],
        error_frame: ErrorFrameSink,
        lose: Callable[[BaseException, int], None],
    ) -> None:
        self.name = name
        self._stats = stats
        self._load = load
        self._generation = generation
        self._deliver = deliver
        self._error_frame = error_frame
        self.lose = lose
        #: the bus's nominal and data bit rates, for the bus load (None: the load is not measured)
        self.bitrate: int | None = None
        self.data_bitrate: int | None = None
        #: (identifier, extended) pairs taken from an application's bus; None: every identifier
        self.wanted: frozenset[tuple[int, bool]] | None = None

    def frame_time_s(self, frame: Frame) -> float:
        """How long ``frame`` occupies the bus (the bit rate is known)."""
        assert self.bitrate is not None
        return nominal_frame_time_s(frame, self.bitrate, self.data_bitrate)

    def count_bad(self, count: int, generation: int, discarded_bytes: int = 0) -> None:
        """Frames python-can could not parse (and bytes of a runaway line it held, thrown away)."""
        if generation == self._generation():
            self._stats.bad_frames += count
            self._stats.discarded_bytes += discarded_bytes

    def take(self, batch: Batch, generation: int, shift: float = 0.0) -> None:
        """Received messages, stamped ``shift`` off the loop's clock, as frames to the transport."""
        if generation != self._generation():
            return
        frames: list[Frame] = []
        stats = self._stats
        wanted = self.wanted
        timed = self.bitrate is not None
        for message, stamp in batch:
            timestamp = stamp + shift
            if message.is_error_frame:
                classes = CanErrorClass(message.arbitration_id & 0x3FF)
                self._error_frame(classes, bytes(message.data), timestamp)
                continue
            if message.is_remote_frame:
                stats.ignored += 1
                continue
            if wanted is not None and (message.arbitration_id, message.is_extended_id) not in wanted:
                continue  # another identifier on the application's bus
            try:
                frame = Frame.from_message(message, timestamp)
            except ValueError:
                stats.bad_frames += 1
                continue
            frames.append(frame)
            stats.bytes_in += len(frame.data)
            if timed:
                self._load.add(timestamp, self.frame_time_s(frame))
        if frames:
            stats.frames_in += len(frames)
            self._deliver(frames)


def wanted_ids(filters: list[can.typechecking.CanFilter] | None) -> frozenset[tuple[int, bool]] | None:
    """The (identifier, extended) pairs exact-match ``filters`` let through (None: all)."""
    if filters is None:
        return None
    return frozenset((f["can_id"], bool(f.get("extended"))) for f in filters)


def exact_filters(ids: Iterable[int], *, extended: bool) -> list[can.typechecking.CanFilter]:
    """python-can filters that let exactly ``ids`` through.

    Raises:
        ValueError: an identifier out of range.
    """
    mask = 0x1FFFFFFF if extended else 0x7FF
    filters: list[can.typechecking.CanFilter] = []
    for can_id in sorted(set(ids)):
        if not 0 <= can_id <= mask:
            raise ValueError(f"receive id 0x{can_id:X} is outside 0..0x{mask:X}")
        filters.append({"can_id": can_id, "can_mask": mask, "extended": extended})
    return filters

"""What a simulated device is to the rest of the simulator: frames in, timed frames out.

Sans-IO, like the codecs the devices are built on: a device never reads a clock or sleeps. The
network (virtual clock) or an attachment (real clock) passes ``now_s`` in and schedules what comes
back. A device answers a request with frames stamped with the time they are ready to leave (its
turnaround), and may also produce frames on its own (active reply streams, automatic error
reports, protection trips), which the caller collects with :meth:`Device.poll` at or after
:meth:`Device.next_deadline_s`.

**Listening devices.** On a wire every node sees every frame, but a device model only acts on a few
identifiers; handing each one every frame makes a 32-motor bus cost 32 calls a frame. A device may
therefore also have ``listen_ids()`` (the identifiers it acts on, or None for every frame: sniffers,
fault injectors), ``attach(link)`` and ``settle()`` (a :class:`Listener`). A
:class:`~servobus.sim.network.SimCanNetwork` then hands it (``receive``) only the frames on those
identifiers and keeps a :class:`BusLink` for the rest: how many there were, of which kind, and when
each ended. The device settles up through the link whenever it is used (:class:`ListeningDevice`
does it whenever its counters or plant are read), so what it reports is the same as if it had
received every frame: the same counters, and its plant integrated over the same steps. It tells the
network through the link when its identifiers or its :meth:`~Device.next_deadline_s` change outside
a ``receive``/``poll`` (a reboot, an injected error); after those the network asks again itself. A
device without these methods gets every frame and is asked for its deadline at every event.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Protocol

from servobus.frame import Frame
from servobus.sim.plant import Plant

__all__ = [
    "BusLink",
    "Device",
    "Emission",
    "FrameLog",
    "Listener",
    "ListeningDevice",
    "SerialDevice",
    "SerialEmission",
]


@dataclass(frozen=True, slots=True, init=False)
class Emission:
    """A frame a device wants to send, and when it is ready to leave."""

    ready_s: float
    frame: Frame

    # One per reply: set through the slot descriptors (a frozen dataclass's generated __init__ goes
    # through object.__setattr__ per field, several times slower).
    def __init__(self, ready_s: float, frame: Frame) -> None:
        _SET_READY(self, ready_s)
        _SET_FRAME(self, frame)


_SET_READY = Emission.ready_s.__set__  # type: ignore[attr-defined,misc]
_SET_FRAME = Emission.frame.__set__  # type: ignore[attr-defined,misc]


class Device(Protocol):
    """A simulated device on a CAN bus (RS485 devices use the same shape with serial frames)."""

    @property
    def name(self) -> str:
        """A label for logs and arbitration sources (unique on its bus)."""
        ...

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s`` (every frame, or those on its ``listen_ids()``)."""
        ...

    def poll(self, now_s: float) -> list[Emission]:
        """Spontaneous frames due by ``now_s`` (streams, error reports, timeouts)."""
        ...

    def next_deadline_s(self) -> float | None:
        """When :meth:`poll` next has something to do (None: nothing scheduled)."""
        ...


class Listener(Device, Protocol):
    """A device that is handed only the frames on its identifiers (see the module docstring)."""

    def listen_ids(self) -> Collection[int] | None:
        """The identifiers this device acts on (None: every frame)."""
        ...

    def attach(self, link: BusLink | None) -> None:
        """Join a network through ``link``, or leave it (None)."""
        ...

    def settle(self) -> None:
        """Take account of every frame ``link`` has logged for this device, now."""
        ...


class FrameLog:
    """The frames one network has carried, as its listening devices need them: one per network.

    ``ends`` and ``sources`` hold the end time and sender of frames ``base`` .. ``count - 1`` (the
    network drops the older ones once every device has settled up); ``odd`` counts the frames with
    an extended identifier or in CAN FD format, which device models ignore by kind rather than by id.
    """

    __slots__ = ("base", "count", "ends", "odd", "sources")

    def __init__(self) -> None:
        self.ends: list[float] = []
        self.sources: list[str] = []
        self.base = 0
        self.count = 0
        self.odd = 0

    def add(self, end_s: float, source: str, odd: bool) -> None:
        self.ends.append(end_s)
        self.sources.append(source)
        self.count += 1
        if odd:
            self.odd += 1

    def drop(self) -> None:
        """Forget the logged times (every link has settled up to :attr:`count`)."""
        self.ends.clear()
        self.sources.clear()
        self.base = self.count


class BusLink:
    """One device's account with a network: the frames on the bus it was not handed.

    The network counts, per device, the frames it sent (``own``) and the frames it handed it
    (``taken``); every other frame on the bus was "missed" and the device settles up for those with
    :meth:`catch_up`. ``log`` is the network's :class:`FrameLog`, which the device only reads.
    """

    __slots__ = ("_marks", "_notify", "cursor", "log", "name", "own", "own_odd", "taken", "taken_odd")

    def __init__(self, log: FrameLog, name: str, notify: Callable[[str], None]) -> None:
        self.log = log
        self._notify = notify
        self.name = name
        self.own = self.own_odd = self.taken = self.taken_odd = 0
        self.cursor = log.count  # frames before this link was made are not the device's concern
        self._marks = (log.odd, 0, 0, 0, 0)  # (log.odd, own, own_odd, taken, taken_odd) at cursor

    @property
    def behind(self) -> bool:
        """Frames have gone by since the last :meth:`catch_up`."""
        return self.cursor != self.log.count

    def catch_up(self, *, every_end: bool) -> tuple[int, int, list[float]]:
        """Settle up: (frames missed, of which odd, end times) since the last call.

        The end times are those of every frame the device did not send itself (taken ones too: the
        device has already advanced to those, so they cost it nothing); with ``every_end`` False only
        the last of them (enough for a device whose state does not depend on the steps).
        """
        log = self.log
        start, self.cursor = self.cursor, log.count
        odd, own, own_odd, taken, taken_odd = self._marks
        self._marks = (log.odd, self.own, self.own_odd, self.taken, self.taken_odd)
        missed = (log.count - start) - (self.own - own) - (self.taken - taken)
        missed_odd = (log.odd - odd) - (self.own_odd - own_odd) - (self.taken_odd - taken_odd)
        first = start - log.base
        assert first >= 0, "the network dropped frames a device had not settled up for"
        name, ends, sources = self.name, log.ends, log.sources
        if every_end:
            return missed, missed_odd, [ends[i] for i in range(first, len(ends)) if sources[i] != name]
        for i in range(len(ends) - 1, first - 1, -1):
            if sources[i] != name:
                return missed, missed_odd, [ends[i]]
        return missed, missed_odd, []

    def changed(self) -> None:
        """The device's identifiers or deadline changed outside the network's calls: ask again."""
        self._notify(self.name)


class ListeningDevice:
    """The listening half of a device model on a :class:`Plant`, with a :class:`~collections.Counter`.

    A subclass sets ``_plant`` and ``_counters`` and defines :meth:`listen_ids`; :attr:`plant` and
    :attr:`counters` settle up with the network before they are read, so they read as if the device
    had received every frame on the bus. Frames it was not handed count as ``received`` and as
    ``ignored_kind`` (extended or FD) or ``ignored_id``, which is what the models' own filters say of
    a frame on another identifier (:attr:`MISSED_ODD` names what a model calls an odd one).
    """

    #: the counter a missed extended or CAN FD frame goes to
    MISSED_ODD = "ignored_kind"
    _link: BusLink | None = None
    _plant: Plant
    _counters: Counter[str]

    def listen_ids(self) -> Collection[int] | None:
        """The identifiers this device acts on (None: every frame)."""
        raise NotImplementedError

    def attach(self, link: BusLink | None) -> None:
        """Join a network (``link``) or leave it (None); the network calls this.

        Raises:
            ValueError: the device is already on another network.
        """
        if link is not None and self._link is not None:
            raise ValueError(f"{self!r} is already on a network: remove it from that one first")
        self.settle()
        self._link = link

    @property
    def plant(self) -> Plant:
        """The mechanics, integrated up to the last frame on the bus."""
        self.settle()
        return self._plant

    @property
    def counters(self) -> Counter[str]:
        """Frames and events by kind (see the model's docstring), every frame on the bus counted."""
        self.settle()
        return self._counters

    def settle(self) -> None:
        """Settle up with the network for the frames it did not hand this device (cheap if none)."""
        link = self._link
        if link is None or link.cursor == link.log.count:
            return
        # The plant's state at a time does not depend on the times it was advanced to (its grid
        # starts at its last change), so the last frame end is enough.
        missed, odd, ends = link.catch_up(every_end=False)
        if missed:
            counters = self._counters
            counters["received"] += missed
            if odd:
                counters[self.MISSED_ODD] += odd
            if missed != odd:
                counters["ignored_id"] += missed - odd
        for end in ends:
            self._overhear(end)

    def tally(self, kind: str, n: int = 1) -> None:
        """Count ``n`` frames or events of ``kind`` (a key of :attr:`counters`) without settling up:
        for the model's own parts (its handlers, its C twin) while it acts on a frame."""
        self._counters[kind] += n

    def _overhear(self, now_s: float) -> None:
        """What receiving a frame on another identifier at ``now_s`` does (advance the plant)."""
        self._plant.advance(now_s)

    def _changed(self) -> None:
        if self._link is not None:
            self._link.changed()


@dataclass(frozen=True, slots=True)
class SerialEmission:
    """Bytes a serial device wants to write, and when it starts writing them."""

    ready_s: float
    data: bytes


class SerialDevice(Protocol):
    """A simulated device on an RS485 line: bytes in (any chunking), timed bytes out.

    The device de-frames its input itself (with the C core's de-framers), as a real one does, so
    corrupt, split and concatenated input behave as on a wire.
    """

    @property
    def name(self) -> str: ...

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        """Bytes that arrived on the line by ``now_s``."""
        ...

    def poll(self, now_s: float) -> list[SerialEmission]:
        """Spontaneous output due by ``now_s``."""
        ...

    def next_deadline_s(self) -> float | None:
        """When :meth:`poll` next has something to do (None: nothing scheduled)."""
        ...

"""Simulated devices on one simulated CAN bus, in virtual time.

Sans-IO discrete-event loop joining the pieces: the host :meth:`~SimCanNetwork.send`\\ s frames,
the :class:`~servobus.sim.canbus.CanBusModel` decides who gets the wire and for how long, every
device sees every completed frame (except its own) and answers after its turnaround, and
:meth:`~SimCanNetwork.advance` returns what the host would have received by then.

Cost per frame does not grow with the number of devices (issue [sim], virtual time >= 50x real
time): a frame is handed only to the devices that listen to its identifier (the others settle up
lazily, see :mod:`servobus.sim.device`), device deadlines are kept in a heap and asked again only of
a device the network has just called or that said it changed, and a device's answer goes straight
into the bus model's queue for the time it is ready (no event of its own). With no real
clock anywhere, timing rules are tested exactly and bus efficiency measured without host noise
(issue [sim], "virtual-clock mode"); a real-time attachment drives the same object from asyncio.

Optional :class:`~servobus.sim.faults.FaultInjector`\\ s sit on the two directions of the link
(host -> devices, devices -> host).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Iterable
from typing import cast

from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel, Transmission
from servobus.sim.deadlines import DeadlineHeap
from servobus.sim.device import BusLink, Device, Emission, FrameLog, Listener
from servobus.sim.faults import FaultInjector

__all__ = ["HOST", "FrameSlots", "SimCanNetwork", "stamped"]

HOST = "host"

#: frame end times kept for listening devices before the network settles them all up and drops them
LOG_LIMIT = 4096


class FrameSlots:
    """A :class:`~servobus.frame.Frame`'s layout, writable: the simulator fills one slot by slot with
    plain attribute stores, then makes it a Frame by assigning ``__class__`` (the layouts are the
    same, so CPython allows it). That skips Frame's checks (the simulator's frames are valid) and
    costs a third of setting a frozen Frame's slots through their descriptors, which the host's edge
    does once per frame received."""

    __slots__ = Frame.__slots__
    arbitration_id: int
    data: bytes
    is_extended_id: bool
    is_fd: bool
    bitrate_switch: bool
    is_serial: bool
    timestamp: float
    is_rx: bool
    error_state_indicator: bool


def stamped(frame: Frame, timestamp: float) -> Frame:
    """A copy of ``frame`` with ``timestamp`` (the frame itself is left as it is): a received frame is
    the sender's own object, the host gets a copy stamped with the time it ended."""
    copy = FrameSlots()
    copy.arbitration_id = frame.arbitration_id
    copy.data = frame.data
    copy.is_extended_id = frame.is_extended_id
    copy.is_fd = frame.is_fd
    copy.bitrate_switch = frame.bitrate_switch
    copy.is_serial = frame.is_serial
    copy.timestamp = timestamp
    copy.is_rx = frame.is_rx
    copy.error_state_indicator = frame.error_state_indicator
    copy.__class__ = Frame  # type: ignore[assignment]
    return copy  # type: ignore[return-value]


class SimCanNetwork:
    """Devices, a bus model and the pending frames between them.

    Args:
        devices: the simulated devices on this bus (unique ``name``\\ s).
        bus: the bus model (1 Mbit/s classic by default).
        to_devices, to_host: fault injectors on each direction (None: a perfect link).
    """

    def __init__(
        self,
        devices: Iterable[Device] = (),
        *,
        bus: CanBusModel | None = None,
        to_devices: FaultInjector | None = None,
        to_host: FaultInjector | None = None,
    ) -> None:
        self.bus = bus or CanBusModel()
        self.devices: dict[str, Device] = {}
        self.to_devices = to_devices
        self.to_host = to_host
        self.now_s = 0.0
        self._seq = itertools.count()
        self._host_pending: list[tuple[float, int, Frame]] = []  # faults can delay delivery to the host
        self._log = FrameLog()
        self._links: dict[str, BusLink] = {}  # listening devices
        self._listeners: dict[str, Listener] = {}
        self._order: dict[str, int] = {}  # device name -> position in the order devices were added
        self._unlinked: list[Device] = []  # devices asked for their deadline at every event
        self._routes: dict[int, list[tuple[str, Device, BusLink | None]]] = {}  # by id, built lazily
        self._listen: dict[str, frozenset[int] | None] = {}  # what each listening device said
        self._deadlines = DeadlineHeap()  # of the listening devices
        self._dirty: list[str] = []  # listening devices that said they changed
        # Ready times of queued frames still ahead of now_s: a frame becoming ready is no event of
        # its own, but run_until_idle() still runs the clock to the last one within its limit.
        self._ready_marks: list[float] = []
        for device in devices:
            self.add(device)

    def add(self, device: Device) -> None:
        """Put ``device`` on the bus.

        Raises:
            ValueError: another device has the same name, or the device is on another network.
        """
        name = device.name
        if name in self.devices or name == HOST:
            raise ValueError(f"a device named {name!r} is already on this bus")
        if all(hasattr(device, method) for method in ("listen_ids", "attach", "settle")):
            listener = cast(Listener, device)
            link = BusLink(self._log, name, self._dirty.append)
            listener.attach(link)
            self._links[name] = link
            self._listeners[name] = listener
            self._dirty.append(name)
        else:
            self._unlinked.append(device)
        self.devices[name] = device
        self._order[name] = next(self._seq)
        self._routes.clear()

    def remove(self, name: str) -> Device:
        """Take a device off the bus (unplugged, powered off)."""
        device = self.devices.pop(name)
        self._order.pop(name)
        if self._links.pop(name, None) is not None:
            self._listeners.pop(name).attach(None)  # settles up first
            self._listen.pop(name, None)
            self._deadlines.discard(name)
        else:
            self._unlinked.remove(device)
        self._routes.clear()
        return device

    def send(self, frame: Frame, now_s: float | None = None) -> None:
        """The host queues ``frame`` for transmission at ``now_s`` (default: the network's time)."""
        at = self.now_s if now_s is None else now_s
        self._queue(at, HOST, frame)

    def next_event_s(self) -> float | None:
        """The earliest time anything happens on this network (None: nothing will)."""
        if self._dirty:
            self._refresh()
        found = self.bus.next_event_s()
        if self._host_pending:
            at = self._host_pending[0][0]
            if found is None or at < found:
                found = at
        deadline = self._deadlines.earliest()
        if deadline is not None and (found is None or deadline < found):
            found = deadline
        for device in self._unlinked:
            deadline = device.next_deadline_s()
            if deadline is not None and (found is None or deadline < found):
                found = deadline
        return found

    def advance(self, until_s: float) -> list[tuple[float, Frame]]:
        """Run the network to ``until_s``; return (time, frame) the host received, in order.

        The host receives every frame the devices put on the wire (not its own), at the time its
        transmission ended.
        """
        received: list[tuple[float, Frame]] = []
        while (t := self.next_event_s()) is not None and t <= until_s:
            self._step(t, received)
        if until_s > self.now_s:
            self.now_s = until_s
        self._tidy()
        return received

    def _step(self, t: float, received: list[tuple[float, Frame]]) -> None:
        """Process what happens at ``t``, the network's next event: in this order, a delayed frame
        reaching the host, the devices whose deadline has come, or the frames ending on the bus."""
        if t > self.now_s:
            self.now_s = t
        if self._host_pending and self._host_pending[0][0] <= t:
            at, _, frame = heapq.heappop(self._host_pending)
            received.append((at, frame))
            return
        due = self._due(t)
        if due:
            for device in due:
                self._queue_all(device.name, device.poll(t))
                if device.name in self._links:
                    self._set_deadline(device)
            return
        for transmission in self.bus.advance(t):
            self._deliver(transmission, received)

    def _tidy(self) -> None:
        marks = self._ready_marks
        while marks and marks[0] <= self.now_s:
            heapq.heappop(marks)
        if len(self._log.ends) >= LOG_LIMIT:
            self._drop_log()

    def run_ahead(self, host_time_s: float) -> float | None:
        """Run on, past ``host_time_s``, over what the host can neither see nor change.

        The host (whose clock reads ``host_time_s``) only sees frames the devices send, and only
        changes the bus by queueing frames. While the host still has a frame queued from before
        ``host_time_s``, anything it queues from then on waits behind that one, so it cannot change
        who wins the wire until that frame has started, nor what the devices receive before then.
        This runs the network over those events (the host's frames ending, devices answering,
        device deadlines) and stops before the next frame the host would receive. The network's
        clock may then be ahead of the host's: frames the host sends meanwhile are queued at the
        network's time, which changes nothing, as they wait behind the queued one anyway.

        Nothing is run with faults towards the devices (their delays reorder the host's frames) or
        on a zero-latency bus (a device frame could end at the same instant a host frame does).

        Returns:
            :meth:`next_event_s` after it (one call where a driver wants both).
        """
        bus = self.bus
        if self.to_devices is not None or not math.isfinite(bus.bitrate):
            return self.next_event_s()
        received: list[tuple[float, Frame]] = []
        while (head := bus.head(HOST)) is not None and head[0] <= host_time_s:
            t = self.next_event_s()
            if t is None or (self._host_pending and self._host_pending[0][0] <= t):
                break
            completion = bus.next_completion()
            if completion is not None and completion[0] <= t and completion[1] != HOST:
                break  # the next frame to end is one the host receives
            self._step(t, received)
            assert not received, "run_ahead() went past a frame the host receives"
        self._tidy()
        return self.next_event_s()

    def host_turn(self, until_s: float, stamp_s: float = 0.0) -> tuple[list[Frame], float | None]:
        """The host's turn: :meth:`advance` to ``until_s``, then :meth:`run_ahead` past it.

        A driver delivers the frames after the run-ahead: what the host sends in answer is queued at
        the network's time, behind the frames the run-ahead went past, which changes nothing
        (:meth:`run_ahead`).

        Returns:
            The frames the host received, each a copy stamped with the time its transmission ended
            plus ``stamp_s`` (a driver's clock offset), and what :meth:`run_ahead` returned.
        """
        received = self.advance(until_s)
        return [stamped(frame, at + stamp_s) for at, frame in received], self.run_ahead(until_s)

    def run_until_idle(self, limit_s: float = 1.0) -> list[tuple[float, Frame]]:
        """Advance until nothing is pending or ``limit_s`` of virtual time has passed."""
        received: list[tuple[float, Frame]] = []
        deadline = self.now_s + limit_s
        while (t := self.next_event_s()) is not None and t <= deadline:
            received += self.advance(t)
        marks = self._ready_marks
        while marks and marks[0] <= deadline:
            self.now_s = max(self.now_s, heapq.heappop(marks))
        return received

    # ---- routing ----

    def _recipients(self, can_id: int) -> list[tuple[str, Device, BusLink | None]]:
        """The devices ``can_id`` is handed to, in the order they were added (built once per id)."""
        found = self._routes.get(can_id)
        if found is None:
            found = self._routes[can_id] = [
                (name, device, self._links.get(name))
                for name, device in self.devices.items()
                if name not in self._links or (ids := self._listen.get(name)) is None or can_id in ids
            ]
        return found

    def _deliver(self, transmission: Transmission, received: list[tuple[float, Frame]]) -> None:
        end, frame, source = transmission.end_s, transmission.frame, transmission.source
        assert isinstance(source, str)
        odd = frame.is_extended_id or frame.is_fd
        self._log.add(end, source, odd)
        sender = self._links.get(source)
        if sender is not None:
            sender.own += 1
            if odd:
                sender.own_odd += 1
        schedule = self._schedule
        for name, device, link in self._recipients(frame.arbitration_id):
            if name == source:
                continue
            if link is not None:
                link.taken += 1
                if odd:
                    link.taken_odd += 1
            for emission in device.receive(frame, end):
                schedule(emission.frame, emission.ready_s, name)  # a device's frames: no faults
            if link is not None:
                self._set_deadline(device)
        if source != HOST:
            outcomes = self.to_host.apply(frame, end) if self.to_host else [(end, frame)]
            for at, item in outcomes:
                assert isinstance(item, Frame)
                if at <= end:
                    received.append((end, item))
                else:
                    heapq.heappush(self._host_pending, (at, next(self._seq), item))

    def _refresh(self) -> None:
        """Ask the devices that said they changed for their identifiers and deadline again."""
        names, self._dirty[:] = set(self._dirty), []
        for name in names:
            device = self._listeners.get(name)
            if device is None:
                continue
            ids = device.listen_ids()
            listen = None if ids is None else frozenset(ids)
            if name not in self._listen or self._listen[name] != listen:
                self._listen[name] = listen
                self._routes.clear()
            self._set_deadline(device)

    # ---- deadlines ----

    def _set_deadline(self, device: Device) -> None:
        self._deadlines.set(device.name, device.next_deadline_s())

    def _due(self, t: float) -> list[Device]:
        """The devices whose deadline has come by ``t``, in the order they were added."""
        devices = self.devices
        due = [devices[name] for name in self._deadlines.pop_due(t)]  # asked again after their poll
        for device in self._unlinked:
            if (when := device.next_deadline_s()) is not None and when <= t:
                due.append(device)
        if len(due) > 1:
            due.sort(key=lambda d: self._order[d.name])
        return due

    # ---- frames ----

    def _drop_log(self) -> None:
        """Settle every listening device up and forget the frame times logged so far."""
        for device in self._listeners.values():
            device.settle()
        if all(not link.behind for link in self._links.values()):
            self._log.drop()

    def _queue_all(self, source: str, emissions: list[Emission]) -> None:
        for emission in emissions:
            self._queue(emission.ready_s, source, emission.frame)

    def _queue(self, ready_s: float, source: str, frame: Frame) -> None:
        if source == HOST and self.to_devices is not None:
            for at, item in self.to_devices.apply(frame, ready_s):
                assert isinstance(item, Frame)
                self._schedule(item, at, source)
        else:
            self._schedule(frame, ready_s, source)

    def _schedule(self, frame: Frame, ready_s: float, source: str) -> None:
        self.bus.schedule(frame, ready_s, source)
        if ready_s > self.now_s:
            heapq.heappush(self._ready_marks, ready_s)

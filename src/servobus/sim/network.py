"""Simulated devices on one simulated CAN bus, in virtual time.

Sans-IO discrete-event loop joining the pieces: the host :meth:`~SimCanNetwork.send`\\ s frames,
the :class:`~servobus.sim.canbus.CanBusModel` decides who gets the wire and for how long, every
device sees every completed frame (except its own) and answers after its turnaround, and
:meth:`~SimCanNetwork.advance` returns what the host would have received by then. With no real
clock anywhere, timing rules are tested exactly and bus efficiency measured without host noise
(issue [sim], "virtual-clock mode"); a real-time attachment drives the same object from asyncio.

Optional :class:`~servobus.sim.faults.FaultInjector`\\ s sit on the two directions of the link
(host -> devices, devices -> host).
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Iterable

from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel, Transmission
from servobus.sim.device import Device, Emission
from servobus.sim.faults import FaultInjector

__all__ = ["HOST", "SimCanNetwork"]

HOST = "host"


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
        for device in devices:
            self.add(device)
        self.to_devices = to_devices
        self.to_host = to_host
        self.now_s = 0.0
        self._emissions: list[tuple[float, int, str, Frame]] = []  # heap: (ready, seq, source, frame)
        self._seq = itertools.count()
        self._host_pending: list[tuple[float, int, Frame]] = []  # faults can delay delivery to the host

    def add(self, device: Device) -> None:
        """Put ``device`` on the bus.

        Raises:
            ValueError: another device has the same name.
        """
        if device.name in self.devices or device.name == HOST:
            raise ValueError(f"a device named {device.name!r} is already on this bus")
        self.devices[device.name] = device

    def remove(self, name: str) -> Device:
        """Take a device off the bus (unplugged, powered off)."""
        return self.devices.pop(name)

    def send(self, frame: Frame, now_s: float | None = None) -> None:
        """The host queues ``frame`` for transmission at ``now_s`` (default: the network's time)."""
        at = self.now_s if now_s is None else now_s
        self._queue(at, HOST, frame)

    def next_event_s(self) -> float | None:
        """The earliest time anything happens on this network (None: nothing will)."""
        times = [self.bus.next_event_s()]
        if self._emissions:
            times.append(self._emissions[0][0])
        if self._host_pending:
            times.append(self._host_pending[0][0])
        times += [d.next_deadline_s() for d in self.devices.values()]
        found = [t for t in times if t is not None]
        return min(found) if found else None

    def advance(self, until_s: float) -> list[tuple[float, Frame]]:
        """Run the network to ``until_s``; return (time, frame) the host received, in order.

        The host receives every frame the devices put on the wire (not its own), at the time its
        transmission ended.
        """
        received: list[tuple[float, Frame]] = []
        while (t := self.next_event_s()) is not None and t <= until_s:
            self.now_s = max(self.now_s, t)
            if self._emissions and self._emissions[0][0] <= t:
                ready, _, source, frame = heapq.heappop(self._emissions)
                self.bus.submit(frame, ready, source)
                continue
            if self._host_pending and self._host_pending[0][0] <= t:
                at, _, frame = heapq.heappop(self._host_pending)
                received.append((at, frame))
                continue
            due = [d for d in self.devices.values() if (dl := d.next_deadline_s()) is not None and dl <= t]
            if due:
                for device in due:
                    self._queue_all(device.name, device.poll(t))
                continue
            for transmission in self.bus.advance(t):
                self._deliver(transmission, received)
        self.now_s = max(self.now_s, until_s)
        return received

    def run_until_idle(self, limit_s: float = 1.0) -> list[tuple[float, Frame]]:
        """Advance until nothing is pending or ``limit_s`` of virtual time has passed."""
        received: list[tuple[float, Frame]] = []
        deadline = self.now_s + limit_s
        while (t := self.next_event_s()) is not None and t <= deadline:
            received += self.advance(t)
        return received

    def _deliver(self, transmission: Transmission, received: list[tuple[float, Frame]]) -> None:
        end, frame, source = transmission.end_s, transmission.frame, transmission.source
        for name, device in list(self.devices.items()):
            if name != source:
                self._queue_all(name, device.receive(frame, end))
        if source != HOST:
            outcomes = self.to_host.apply(frame, end) if self.to_host else [(end, frame)]
            for at, item in outcomes:
                assert isinstance(item, Frame)
                if at <= end:
                    received.append((end, item))
                else:
                    heapq.heappush(self._host_pending, (at, next(self._seq), item))

    def _queue_all(self, source: str, emissions: list[Emission]) -> None:
        for emission in emissions:
            self._queue(emission.ready_s, source, emission.frame)

    def _queue(self, ready_s: float, source: str, frame: Frame) -> None:
        if source == HOST and self.to_devices is not None:
            outcomes = self.to_devices.apply(frame, ready_s)
        else:
            outcomes = [(ready_s, frame)]
        for at, item in outcomes:
            assert isinstance(item, Frame)
            heapq.heappush(self._emissions, (at, next(self._seq), source, item))

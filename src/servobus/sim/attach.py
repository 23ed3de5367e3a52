"""Attachments: the simulated devices, driven in real time, behind real I/O a host can open.

The device models and the network are sans-IO and timed by ``now_s``; these coroutines give them
a clock (the event loop's) and an end a host talks to:

* :func:`serve_slcan`: a simulated SLCAN USB-CAN adapter on a pseudo-terminal, so python-can's own
  ``slcan`` interface (or any LAWICEL tool) exchanges frames with the devices on a
  :class:`~servobus.sim.network.SimCanNetwork`;
* :func:`serve_python_can`: the same network joined to a python-can bus (the ``virtual``
  interface in-process, CAN FD included);
* :func:`serve_rs485`: serial devices on one half-duplex RS485 line on a pseudo-terminal, each
  reply written when its last byte would have arrived at the line's baud rate.

Each runs until cancelled (or its port closes) and leaves the port or bus to its owner to close.
Its tasks run in an anyio task group: an exception in a device model ends the whole attachment and
reaches the caller, never dies silently in a background task. They run on asyncio and on trio.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

import anyio
import can
from anyio.streams.memory import MemoryObjectReceiveStream

from servobus import runtime
from servobus.frame import Frame
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import SerialDevice, SerialEmission
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter
from servobus.timing import uart_time_s
from servobus.transports.can import frame_from_message, message_from_frame

__all__ = ["SimClock", "serve_python_can", "serve_rs485", "serve_slcan"]


class SimClock:
    """Simulated seconds since start, read from the event loop's monotonic clock."""

    def __init__(self) -> None:
        self._time = runtime.current().time
        self._t0 = self._time()

    def now(self) -> float:
        return self._time() - self._t0


def _inbox() -> tuple[Callable[[Frame], None], MemoryObjectReceiveStream[Frame]]:
    """An unbounded queue of host frames: its ``put`` (never blocks) and its receiving end."""
    send, receive = anyio.create_memory_object_stream[Frame](math.inf)
    return send.send_nowait, receive


async def _run_network(
    network: SimCanNetwork | CoreCanNetwork,
    inbox: MemoryObjectReceiveStream[Frame],
    deliver: Callable[[Frame], None],
    clock: SimClock,
) -> None:
    """Feed host frames in as they come, sleep until the network's next event, deliver its output."""
    while True:
        wake = network.next_event_s()
        frame: Frame | None = None
        with anyio.move_on_after(math.inf if wake is None else max(0.0, wake - clock.now())):
            frame = await inbox.receive()
        if frame is not None:
            network.send(frame, max(network.now_s, clock.now()))
        for _, received in network.advance(clock.now()):
            deliver(received)


async def serve_slcan(
    network: SimCanNetwork | CoreCanNetwork, port: PtyPort, adapter: SlcanAdapter | None = None
) -> None:
    """Serve ``network`` to a host that opens ``port.name`` as an SLCAN adapter.

    The adapter's bit rates (``S``/``Y`` commands) set the network's bus model, as a real adapter's
    would set its controller.
    """
    adapter = adapter or SlcanAdapter()
    clock = SimClock()
    put, inbox = _inbox()

    def deliver(frame: Frame) -> None:
        if not port.closed and (line := adapter.to_host(frame, clock.now())):
            port.write(line)

    async def read_host() -> None:
        async for data in port:
            answer, frames = adapter.receive(data, clock.now())
            if adapter.bitrate:
                network.bus.bitrate = adapter.bitrate
            network.bus.data_bitrate = adapter.data_bitrate
            if answer:
                port.write(answer)
            for frame in frames:
                put(frame)
        raise _PortClosed

    await _run_together(_run_network(network, inbox, deliver, clock), read_host())


async def serve_python_can(network: SimCanNetwork | CoreCanNetwork, bus: can.BusABC) -> None:
    """Serve ``network`` on a python-can bus (typically ``virtual``): its frames in, replies out.

    python-can's notifier thread reads the bus; each message is handed to the loop
    (``call_soon_threadsafe`` of :mod:`servobus.runtime`) and stamped there, on the loop's clock.
    """
    lane = runtime.current()
    clock = SimClock()
    put, inbox = _inbox()

    def take(message: can.Message) -> None:  # (on the loop)
        put(frame_from_message(message, clock.now()))

    def on_message(message: can.Message) -> None:  # (on the notifier's thread)
        if not (message.is_error_frame or message.is_remote_frame):
            lane.call_soon_threadsafe(take, message)

    def deliver(frame: Frame) -> None:
        bus.send(message_from_frame(frame))

    notifier = can.Notifier(bus, [on_message])
    try:
        await _run_network(network, inbox, deliver, clock)
    finally:
        notifier.stop()


async def serve_rs485(devices: Sequence[SerialDevice], port: PtyPort, *, baud: int) -> None:
    """Serve serial ``devices`` sharing one RS485 line on ``port`` at ``baud``.

    Every device hears every byte the host writes. Half-duplex: one device talks at a time, so
    replies that are ready together leave one after the other, each taking its bytes' line time.
    """
    clock = SimClock()
    line_free_s = 0.0
    pending: list[SerialEmission] = []
    wakeup = anyio.Event()

    def collect(emissions: list[SerialEmission]) -> None:
        pending.extend(emissions)
        pending.sort(key=lambda e: e.ready_s)
        wakeup.set()

    async def writer() -> None:
        nonlocal line_free_s, wakeup
        while True:
            deadlines = [d for d in (dev.next_deadline_s() for dev in devices) if d is not None]
            due = min([*(e.ready_s for e in pending[:1]), *deadlines], default=None)
            wakeup = anyio.Event()  # (an anyio Event is set once: a fresh one per wait)
            if due is None:
                await wakeup.wait()
                continue
            delay = due - clock.now()
            if delay > 0:
                with anyio.move_on_after(delay):
                    await wakeup.wait()
                    continue  # something new arrived: recompute
            now = clock.now()
            for device in devices:
                if (deadline := device.next_deadline_s()) is not None and deadline <= now:
                    collect(device.poll(now))
            while pending and pending[0].ready_s <= now:
                emission = pending.pop(0)
                start = max(emission.ready_s, line_free_s)
                line_free_s = start + uart_time_s(len(emission.data), baud)
                await anyio.sleep(max(0.0, line_free_s - clock.now()))
                if port.closed:
                    return
                port.write(emission.data)

    async def read_host() -> None:
        async for data in port:
            now = clock.now()
            for device in devices:
                collect(device.receive_bytes(data, now))
        raise _PortClosed

    await _run_together(writer(), read_host())


class _PortClosed(Exception):
    """The host-facing port closed: the attachment ends normally."""


async def _run_together(*coroutines: Coroutine[Any, Any, None]) -> None:
    """Run ``coroutines`` until one ends; its exception (other than a closed port) propagates."""
    try:
        async with anyio.create_task_group() as group:
            for coroutine in coroutines:
                group.start_soon(_awaited, coroutine)
    except* _PortClosed:
        pass


async def _awaited(coroutine: Coroutine[Any, Any, None]) -> None:
    await coroutine

"""The three real I/O paths every transport test runs over, each with a simulated peer.

* ``slcan``: CanTransport -> python-can ``slcan`` -> a pty -> the simulated SLCAN adapter -> a
  simulated CAN bus at 1 Mbit/s with one responder.
* ``rs485``: SerialTransport (the MyActuator family's framing, serial Frames) -> a pty -> a
  simulated RS485 line with one responder, paced at the line's baud rate.
* ``virtual-fd``: CanTransport with CAN FD -> python-can's ``virtual`` bus -> the simulated bus.
* ``native-slcan``: SlcanTransport (no python-can) -> a pty -> the simulated SLCAN adapter -> a
  simulated CAN bus at 1 Mbit/s with one responder.
* ``sim``: SimTransport, the in-process bus: straight onto a simulated CAN bus at 1 Mbit/s with one
  responder, on the loop's clock (real time here).

A path sends numbered requests (:meth:`LinePath.request`) that its peer answers with the same
payload, so a test can check order, loss and duplication from the replies alone. The pty paths
can be unplugged and plugged back in at the same stable link.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
import struct
from collections.abc import AsyncIterator, Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from _serving import serving
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.sim.attach import serve_python_can, serve_rs485, serve_slcan
from servobus.sim.canbus import CanBusModel
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter
from servobus.transports import CanTransport, SerialTransport, SimTransport, SlcanTransport, Transport
from sim._standins import Responder, SerialResponder

PATHS = ("slcan", "rs485", "virtual-fd", "native-slcan", "sim")
REPLY_TIMEOUT_S = 0.2


def payload(seq: int, size: int) -> bytes:
    """``size`` bytes that start with ``seq`` and differ from frame to frame after it."""
    return struct.pack("<I", seq) + random.Random(seq).randbytes(size - 4)


@dataclass
class LinePath:
    """A host transport, its simulated peer, and how to speak to it."""

    name: str
    transport: Transport[Any, Any]
    request: Callable[[int], None]  # send request number ``seq`` (the peer answers it)
    reply_payload: Callable[[Any], bytes]  # the payload of a received reply
    peer_seen: Callable[[], list[bytes]]  # payloads of the requests the peer has received
    unplug: Callable[[], None] | None = None
    replug: Callable[[], Coroutine[Any, Any, None]] | None = None
    tasks: list[asyncio.Task[None]] = field(default_factory=list)

    @staticmethod
    def seq_of(data: bytes) -> int:
        return int(struct.unpack_from("<I", data)[0])


@contextlib.asynccontextmanager
async def open_path(name: str, tmp_path: Path, **transport_options: Any) -> AsyncIterator[LinePath]:
    """``name`` from :data:`PATHS`, opened; ``transport_options`` go to the transport."""
    opener = {
        "slcan": _slcan,
        "rs485": _rs485,
        "virtual-fd": _virtual_fd,
        "native-slcan": _native_slcan,
        "sim": _sim,
    }[name]
    async with opener(tmp_path, **transport_options) as path:
        yield path


class _PtyPeer:
    """A simulated peer behind a pty at a stable link, which can be unplugged and come back."""

    def __init__(self, link: Path, serve: Callable[[PtyPort], Coroutine[Any, Any, None]]) -> None:
        self.link = link
        self._serve = serve
        self.port: PtyPort | None = None
        self._stack = contextlib.AsyncExitStack()

    async def plug(self) -> None:
        self.port = PtyPort(link=self.link)
        await self._stack.enter_async_context(serving(self._serve(self.port)))

    def unplug(self) -> None:
        assert self.port is not None
        self.port.unplug()

    async def close(self) -> None:
        if self.port is not None:
            self.port.close()
        await self._stack.aclose()


@contextlib.asynccontextmanager
async def _slcan(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    responders: list[Responder] = []

    def serve(port: PtyPort) -> Coroutine[Any, Any, None]:
        responders.append(Responder(1))  # a fresh device each time it is plugged in
        return serve_slcan(SimCanNetwork([responders[-1]]), port, SlcanAdapter(bitrate=None))

    peer = _PtyPeer(tmp_path / "ttyCAN", serve)
    await peer.plug()
    transport = CanTransport(
        "slcan", str(peer.link), bitrate=1_000_000, sleep_after_open=0, ignore_config=True, **options
    )
    try:
        async with transport:
            yield LinePath(
                name="slcan",
                transport=transport,
                request=lambda seq: transport.send(Frame(arbitration_id=0x141, data=payload(seq, 8))),
                reply_payload=lambda frame: frame.data,
                peer_seen=lambda: [f.data for _, f in responders[-1].seen],
                unplug=peer.unplug,
                replug=peer.plug,
            )
    finally:
        await peer.close()


@contextlib.asynccontextmanager
async def _native_slcan(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    responders: list[Responder] = []

    def serve(port: PtyPort) -> Coroutine[Any, Any, None]:
        responders.append(Responder(1))  # a fresh device each time it is plugged in
        return serve_slcan(SimCanNetwork([responders[-1]]), port, SlcanAdapter(bitrate=None))

    peer = _PtyPeer(tmp_path / "ttySLCAN", serve)
    await peer.plug()
    transport = SlcanTransport(str(peer.link), bitrate=1_000_000, **options)
    try:
        async with transport:
            yield LinePath(
                name="native-slcan",
                transport=transport,
                request=lambda seq: transport.send(Frame(arbitration_id=0x141, data=payload(seq, 8))),
                reply_payload=lambda frame: frame.data,
                peer_seen=lambda: [f.data for _, f in responders[-1].seen],
                unplug=peer.unplug,
                replug=peer.plug,
            )
    finally:
        await peer.close()


@contextlib.asynccontextmanager
async def _rs485(tmp_path: Path, *, baud: int = 2_500_000, **options: Any) -> AsyncIterator[LinePath]:
    seen: list[bytes] = []

    class Recording(SerialResponder):
        def receive_bytes(self, data: bytes, now_s: float) -> Any:
            emissions = super().receive_bytes(data, now_s)
            seen.extend(e.data[3:-2] for e in emissions)
            return emissions

    def serve(port: PtyPort) -> Coroutine[Any, Any, None]:
        seen.clear()  # a fresh device each time it is plugged in
        return serve_rs485([Recording(1)], port, baud=baud)

    peer = _PtyPeer(tmp_path / "tty485", serve)
    await peer.plug()
    framing = ma.FAMILY.bind(1, link="rs485").framing
    transport = SerialTransport(str(peer.link), framing=framing, baud=baud, **options)

    def request(seq: int) -> None:
        frame = Frame(arbitration_id=1, data=payload(seq, 8), is_serial=True)
        transport.send(frame, reply_timeout_s=REPLY_TIMEOUT_S)

    try:
        async with transport:
            yield LinePath(
                name="rs485",
                transport=transport,
                request=request,
                reply_payload=lambda frame: frame.data,
                peer_seen=lambda: seen,
                unplug=peer.unplug,
                replug=peer.plug,
            )
    finally:
        await peer.close()


@contextlib.asynccontextmanager
async def _virtual_fd(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    channel = f"transport-test-{tmp_path.name}"
    responder = Responder(1)
    network = SimCanNetwork([responder], bus=CanBusModel(bitrate=math.inf))
    sim_side = can.Bus(interface="virtual", channel=channel)
    transport = CanTransport("virtual", channel, fd=True, ignore_config=True, **options)
    try:
        async with serving(serve_python_can(network, sim_side)), transport:
            yield LinePath(
                name="virtual-fd",
                transport=transport,
                request=lambda seq: transport.send(
                    Frame(arbitration_id=0x141, data=payload(seq, 64), is_fd=True, bitrate_switch=True)
                ),
                reply_payload=lambda frame: frame.data,
                peer_seen=lambda: [f.data for _, f in responder.seen],
            )
    finally:
        sim_side.shutdown()


@contextlib.asynccontextmanager
async def _sim(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    responder = Responder(1)
    transport = SimTransport(devices=[responder], **options)

    async def replug() -> None:
        transport.replug()

    async with transport:
        yield LinePath(
            name="sim",
            transport=transport,
            request=lambda seq: transport.send(Frame(arbitration_id=0x141, data=payload(seq, 8))),
            reply_payload=lambda frame: frame.data,
            peer_seen=lambda: [f.data for _, f in responder.seen],
            unplug=transport.unplug,
            replug=replug,
        )

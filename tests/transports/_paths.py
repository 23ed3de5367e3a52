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

import contextlib
import math
import random
import struct
from collections.abc import AsyncIterator, Callable, Coroutine
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
import can

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.sim.attach import serve_python_can, serve_rs485, serve_slcan
from servobus.sim.canbus import CanBusModel
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter
from servobus.transports import CanTransport, SerialTransport, SimTransport, SlcanTransport, Transport
from sim._standins import Responder, SerialResponder

from ._anyio_help import serving

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
    """A simulated peer behind a pty at a stable link, which can be unplugged and come back.

    ``async with`` it around the transport: its servings run in its own task group, entered before
    the transport's (anyio nests task groups: the transport is closed inside it)."""

    def __init__(self, link: Path, serve: Callable[[PtyPort], Coroutine[Any, Any, None]]) -> None:
        self.link = link
        self._serve = serve
        self.port: PtyPort | None = None
        self._group: anyio.abc.TaskGroup | None = None

    async def __aenter__(self) -> _PtyPeer:
        self._group = anyio.create_task_group()
        await self._group.__aenter__()
        await self.plug()
        return self

    async def __aexit__(self, *exc: Any) -> bool | None:
        assert self._group is not None
        if self.port is not None:
            self.port.close()
        self._group.cancel_scope.cancel()
        return await self._group.__aexit__(*exc)

    async def plug(self) -> None:
        assert self._group is not None
        self.port = PtyPort(link=self.link)
        self._group.start_soon(self._serve, self.port)

    def unplug(self) -> None:
        assert self.port is not None
        self.port.unplug()


@contextlib.asynccontextmanager
async def _slcan(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    responders: list[Responder] = []

    def serve(port: PtyPort) -> Coroutine[Any, Any, None]:
        responders.append(Responder(1))  # a fresh device each time it is plugged in
        return serve_slcan(SimCanNetwork([responders[-1]]), port, SlcanAdapter(bitrate=None))

    async with _PtyPeer(tmp_path / "ttyCAN", serve) as peer:
        transport = CanTransport(
            "slcan", str(peer.link), bitrate=1_000_000, sleep_after_open=0, ignore_config=True, **options
        )
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


@contextlib.asynccontextmanager
async def _native_slcan(tmp_path: Path, **options: Any) -> AsyncIterator[LinePath]:
    responders: list[Responder] = []

    def serve(port: PtyPort) -> Coroutine[Any, Any, None]:
        responders.append(Responder(1))  # a fresh device each time it is plugged in
        return serve_slcan(SimCanNetwork([responders[-1]]), port, SlcanAdapter(bitrate=None))

    async with _PtyPeer(tmp_path / "ttySLCAN", serve) as peer:
        transport = SlcanTransport(str(peer.link), bitrate=1_000_000, **options)
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

    framing = ma.FAMILY.bind(1, link="rs485").framing

    def request(seq: int) -> None:
        frame = Frame(arbitration_id=1, data=payload(seq, 8), is_serial=True)
        transport.send(frame, reply_timeout_s=REPLY_TIMEOUT_S)

    async with _PtyPeer(tmp_path / "tty485", serve) as peer:
        transport = SerialTransport(str(peer.link), framing=framing, baud=baud, **options)
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

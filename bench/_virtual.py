"""CanTransport against a naive python-can loop on python-can's ``virtual`` interface (bench_transport).

Four figures, each ours / naive in frames (or transactions) per second, measured in one run with the
repeats alternated:

* **tx**: N frames sent as fast as the API takes them. Naive: ``bus.send(can.Message(...))`` in a
  loop on the event loop. Ours: ``transport.send(Frame(...))`` then ``await transport.drain()``.
* **rx**: a peer thread sends N frames; time until the last one is in the consumer's hands. Naive:
  ``can.Notifier`` + ``can.AsyncBufferedReader`` (python-can's asyncio recipe). Ours: a consumer set
  with ``set_consumer`` (push delivery).
* **rtt**: sequential request/reply with an echo thread on the peer side. Naive: send, then
  ``await reader.get_message()``. Ours: send, then await the reply through the consumer.
* **pipelined32**: 32 requests sent at once, then the 32 replies awaited; repeated.

The echo thread and the peer are the same code for both sides; a frame's data carries its sequence
number, checked on arrival, so both sides do the same work.
"""

from __future__ import annotations

import asyncio
import itertools
import statistics
import threading
import time
from collections.abc import Callable
from typing import Any

import can

from servobus import Frame
from servobus.transports import CanTransport

_channels = itertools.count()


def _channel() -> str:
    return f"bench-virtual-{next(_channels)}"


class _Echo:
    """A peer thread answering every frame on ``id`` with the same data on ``id + 0x100``."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        bus = self.bus
        while not self._stop.is_set():
            message = bus.recv(0.05)
            if message is not None:
                bus.send(
                    can.Message(
                        arbitration_id=message.arbitration_id + 0x100, data=message.data, is_extended_id=False
                    )
                )

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()


def _payload(i: int) -> bytes:
    return i.to_bytes(8, "little")


# ---- tx ----


async def _tx_naive(n: int) -> float:
    channel = _channel()
    bus = can.Bus(interface="virtual", channel=channel)
    sink = can.Bus(interface="virtual", channel=channel)
    start = time.perf_counter()
    for i in range(n):
        bus.send(can.Message(arbitration_id=0x141, data=_payload(i), is_extended_id=False))
    elapsed = time.perf_counter() - start
    bus.shutdown()
    sink.shutdown()
    return n / elapsed


async def _tx_ours(n: int) -> float:
    channel = _channel()
    sink = can.Bus(interface="virtual", channel=channel)
    async with CanTransport("virtual", channel, ignore_config=True, queue_size=n) as transport:
        start = time.perf_counter()
        for i in range(n):
            transport.send(Frame(arbitration_id=0x141, data=_payload(i)))
        await transport.drain()
        elapsed = time.perf_counter() - start
    sink.shutdown()
    return n / elapsed


# ---- rx ----


def _flood(channel: str, n: int, go: threading.Event) -> threading.Thread:
    def run() -> None:
        bus = can.Bus(interface="virtual", channel=channel)
        go.wait()
        for i in range(n):
            bus.send(can.Message(arbitration_id=0x241, data=_payload(i), is_extended_id=False))
        bus.shutdown()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


async def _rx_naive(n: int) -> float:
    channel = _channel()
    bus = can.Bus(interface="virtual", channel=channel)
    reader = can.AsyncBufferedReader()
    notifier = can.Notifier(bus, [reader], timeout=0.05, loop=asyncio.get_running_loop())  # quick stop()
    go = threading.Event()
    thread = _flood(channel, n, go)
    await asyncio.sleep(0.01)
    start = time.perf_counter()
    go.set()
    for i in range(n):
        message = await reader.get_message()
        assert int.from_bytes(message.data, "little") == i
    elapsed = time.perf_counter() - start
    notifier.stop()
    bus.shutdown()
    thread.join()
    return n / elapsed


async def _rx_ours(n: int) -> float:
    channel = _channel()
    loop = asyncio.get_running_loop()
    done = loop.create_future()
    count = 0

    def consume(frames: list[Frame]) -> None:
        nonlocal count
        for frame in frames:
            assert int.from_bytes(frame.data, "little") == count
            count += 1
        if count >= n and not done.done():
            done.set_result(None)

    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        transport.set_consumer(consume)
        go = threading.Event()
        thread = _flood(channel, n, go)
        await asyncio.sleep(0.01)
        start = time.perf_counter()
        go.set()
        await done
        elapsed = time.perf_counter() - start
    thread.join()
    return n / elapsed


# ---- round trips ----


async def _rtt_naive(n: int, depth: int) -> float:
    channel = _channel()
    echo = _Echo(channel)
    bus = can.Bus(interface="virtual", channel=channel)
    reader = can.AsyncBufferedReader()
    notifier = can.Notifier(bus, [reader], timeout=0.05, loop=asyncio.get_running_loop())  # quick stop()
    start = time.perf_counter()
    for round_ in range(n // depth):
        for k in range(depth):
            bus.send(
                can.Message(arbitration_id=0x141, data=_payload(round_ * depth + k), is_extended_id=False)
            )
        for k in range(depth):
            message = await reader.get_message()
            assert int.from_bytes(message.data, "little") == round_ * depth + k
    elapsed = time.perf_counter() - start
    notifier.stop()
    bus.shutdown()
    echo.close()
    return (n // depth) * depth / elapsed


async def _rtt_ours(n: int, depth: int) -> float:
    channel = _channel()
    echo = _Echo(channel)
    loop = asyncio.get_running_loop()
    inbox: list[Frame] = []
    waiter: list[asyncio.Future[None]] = []

    def consume(frames: list[Frame]) -> None:
        inbox.extend(frames)
        if waiter and not waiter[0].done():
            waiter[0].set_result(None)

    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        transport.set_consumer(consume)
        start = time.perf_counter()
        for round_ in range(n // depth):
            for k in range(depth):
                transport.send(Frame(arbitration_id=0x141, data=_payload(round_ * depth + k)))
            while len(inbox) < depth:
                waiter[:] = [loop.create_future()]
                await waiter[0]
            for k, frame in enumerate(inbox):
                assert int.from_bytes(frame.data, "little") == round_ * depth + k
            inbox.clear()
        elapsed = time.perf_counter() - start
    echo.close()
    return (n // depth) * depth / elapsed


Measure = Callable[[], Any]


def run(quick: bool, log: Callable[[str], None]) -> dict[str, Any]:
    """Measure the four pairs, alternating ours and naive, median of the repeats."""
    repeats = 2 if quick else 5
    sizes = {
        "tx": 5_000 if quick else 50_000,
        "rx": 5_000 if quick else 50_000,
        "rtt": 300 if quick else 3_000,
    }
    sizes["pipelined32"] = 32 * (30 if quick else 300)
    pairs: dict[str, tuple[Callable[[], Any], Callable[[], Any]]] = {
        "tx": (lambda: _tx_ours(sizes["tx"]), lambda: _tx_naive(sizes["tx"])),
        "rx": (lambda: _rx_ours(sizes["rx"]), lambda: _rx_naive(sizes["rx"])),
        "rtt": (lambda: _rtt_ours(sizes["rtt"], 1), lambda: _rtt_naive(sizes["rtt"], 1)),
        "pipelined32": (
            lambda: _rtt_ours(sizes["pipelined32"], 32),
            lambda: _rtt_naive(sizes["pipelined32"], 32),
        ),
    }
    out: dict[str, Any] = {}
    for name, (ours, naive) in pairs.items():
        got: dict[str, list[float]] = {"ours": [], "naive": []}
        for _ in range(repeats):
            got["ours"].append(asyncio.run(ours()))
            got["naive"].append(asyncio.run(naive()))
        mine, theirs = statistics.median(got["ours"]), statistics.median(got["naive"])
        out[f"virtual_{name}_per_s"] = round(mine)
        out[f"virtual_{name}_naive_per_s"] = round(theirs)
        out[f"virtual_{name}_vs_naive"] = round(mine / theirs, 2)
        ratio = mine / theirs
        log(f"  virtual {name:<12} servobus {mine:>10,.0f}/s  naive {theirs:>10,.0f}/s  {ratio:.2f}x")
    out["virtual_sizes"] = sizes
    return out


if __name__ == "__main__":
    import sys

    print(run("--quick" in sys.argv, print))

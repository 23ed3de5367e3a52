"""The transport base on an in-memory device: queueing, draining, loss, reopen, events, counters.

The real paths run the same rules in test_contract.py; here each rule is driven exactly (a device
that fails on cue, a wire that stalls on cue) so that every branch is seen.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import warnings

import pytest

from servobus.errors import TransportError
from servobus.transports import (
    FramesDropped,
    SendQueueFull,
    StateChanged,
    Transport,
    TransportEvent,
    TransportState,
)
from servobus.transports.base import Outgoing
from servobus.transports.stats import LoadMeter


class MemoryTransport(Transport[bytes, bytes]):
    """A device in memory: ``wire`` gets what is sent; ``gate`` (when cleared) stalls the writer."""

    batch_size = 1

    def __init__(self, *, fail_connects: int = 0, **options: object) -> None:
        super().__init__(name="memory", **options)  # type: ignore[arg-type]
        self.wire: list[bytes] = []
        self.gate = asyncio.Event()
        self.gate.set()
        self.connects = 0
        self.disconnects = 0
        self.fail_connects = fail_connects

    def send(self, data: bytes) -> None:
        self._enqueue(data)

    async def _connect(self) -> None:
        self.connects += 1
        if self.fail_connects:
            self.fail_connects -= 1
            raise TransportError("memory: not there")

    async def _disconnect(self) -> None:
        self.disconnects += 1

    async def _transmit(self, batch: list[Outgoing[bytes]]) -> None:
        while batch:
            await self.gate.wait()
            self.wire.append(batch.pop(0).item)
            self._stats.frames_out += 1

    def inject(self, *frames: bytes) -> None:
        self._deliver(list(frames))

    def fail(self, cause: BaseException) -> None:
        self._lose(cause)


@pytest.mark.asyncio
async def test_sending_before_open_or_after_close_raises_transport_error() -> None:
    transport = MemoryTransport()
    with pytest.raises(TransportError, match="not open"):
        transport.send(b"x")
    async with transport:
        transport.send(b"x")
        await transport.drain()
    with pytest.raises(TransportError, match="closed"):
        transport.send(b"y")
    assert transport.wire == [b"x"]


@pytest.mark.asyncio
async def test_a_full_queue_refuses_the_frame_and_drain_waits_for_room() -> None:
    async with MemoryTransport(queue_size=2) as transport:
        transport.gate.clear()
        transport.send(b"a")
        await asyncio.sleep(0)  # the writer takes "a" and stalls on the gate
        transport.send(b"b")
        transport.send(b"c")
        assert transport.queue_room == 0
        with pytest.raises(SendQueueFull, match="queue full") as caught:
            transport.send(b"d")
        assert isinstance(caught.value, asyncio.QueueFull)
        drained = asyncio.ensure_future(transport.drain())
        await asyncio.sleep(0.01)
        assert not drained.done()
        transport.gate.set()
        await asyncio.wait_for(drained, 1.0)
        assert transport.wire == [b"a", b"b", b"c"]
        stats = transport.stats()
        assert (stats.queue_full, stats.queue_depth, stats.frames_out) == (1, 0, 3)


@pytest.mark.asyncio
async def test_frames_that_waited_longer_than_stale_after_are_dropped_not_sent() -> None:
    events: list[TransportEvent] = []
    async with MemoryTransport(stale_after_s=0.05) as transport:
        transport.add_listener(events.append)
        transport.gate.clear()
        transport.send(b"first")
        await asyncio.sleep(0)
        transport.send(b"old")
        await asyncio.sleep(0.1)
        transport.gate.set()
        await transport.drain()
        transport.send(b"fresh")
        await transport.drain()
    assert transport.wire == [b"first", b"fresh"]
    assert transport.stats().stale == 1
    assert [(e.reason, e.count) for e in events if isinstance(e, FramesDropped)] == [("stale", 1)]


@pytest.mark.asyncio
async def test_a_loss_fails_every_waiter_at_once_purges_the_queue_and_reopens() -> None:
    events: list[TransportEvent] = []
    transport = MemoryTransport(reopen_backoff_s=(0.01, 0.04), fail_connects=0)
    transport.add_listener(events.append)
    async with transport:
        transport.gate.clear()
        for frame in (b"1", b"2", b"3"):
            transport.send(frame)
        waiters = [asyncio.ensure_future(transport.receive()) for _ in range(2)]
        waiters += [
            asyncio.ensure_future(transport.receive_batch()),
            asyncio.ensure_future(transport.drain()),
        ]
        await asyncio.sleep(0.01)
        transport.fail_connects = 3  # the device stays away for three attempts
        cause = OSError(5, "Input/output error")
        transport.fail(cause)
        transport.fail(OSError("again"))  # a second report of the same loss changes nothing
        results = await asyncio.gather(*waiters, return_exceptions=True)
        assert all(isinstance(r, TransportError) and r.__cause__ is cause for r in results)
        assert "device lost" in str(results[0]) and "Input/output error" in str(results[0])
        assert transport.state is TransportState.LOST
        with pytest.raises(TransportError, match="device lost"):
            transport.send(b"4")
        await transport.wait_open(timeout=2.0)
        transport.gate.set()
        transport.send(b"5")
        await transport.drain()
    assert transport.wire == [b"5"]  # 1 (stalled before its write), 2 and 3 were purged
    assert transport.connects == 1 + 4
    stats = transport.stats()
    assert (stats.losses, stats.reopens, stats.purged) == (1, 1, 3)
    states = [e.state for e in events if isinstance(e, StateChanged)]
    assert states == [
        TransportState.OPENING,
        TransportState.OPEN,
        TransportState.LOST,
        TransportState.OPEN,
        TransportState.CLOSED,
    ]
    lost = next(e for e in events if isinstance(e, StateChanged) and e.state is TransportState.LOST)
    assert lost.cause is cause


@pytest.mark.asyncio
async def test_without_reopen_a_lost_transport_stays_lost_until_closed() -> None:
    async with MemoryTransport(reopen=False) as transport:
        transport.fail(ConnectionError("gone"))
        await asyncio.sleep(0.05)
        assert transport.state is TransportState.LOST and transport.connects == 1
        with pytest.raises(TimeoutError):
            await transport.wait_open(timeout=0.05)
    assert transport.state is TransportState.CLOSED


@pytest.mark.asyncio
async def test_close_during_reopen_attempts_stops_them() -> None:
    transport = MemoryTransport(reopen_backoff_s=(0.01, 0.01))
    await transport.open()
    transport.fail_connects = 1000
    transport.fail(ConnectionError("gone"))
    await asyncio.sleep(0.05)
    waiting = asyncio.ensure_future(transport.wait_open())
    await transport.close()
    attempts = transport.connects
    await asyncio.sleep(0.05)
    assert transport.connects == attempts
    with pytest.raises(TransportError, match="closed"):
        await waiting


@pytest.mark.asyncio
async def test_received_frames_are_buffered_and_the_oldest_dropped_when_nobody_reads() -> None:
    async with MemoryTransport(rx_buffer=3) as transport:
        transport.inject(b"1", b"2")
        transport.inject(b"3", b"4", b"5")
        assert await transport.receive_batch(max_frames=2) == [b"3", b"4"]
        assert await transport.receive() == b"5"
        assert transport.stats().rx_overflow == 2
        later = asyncio.ensure_future(transport.receive_batch())
        await asyncio.sleep(0)
        transport.inject(b"6")
        assert await later == [b"6"]


@pytest.mark.asyncio
async def test_frames_received_before_a_loss_are_still_delivered() -> None:
    async with MemoryTransport(reopen=False) as transport:
        transport.inject(b"last words")
        transport.fail(ConnectionError("gone"))
        assert await transport.receive() == b"last words"
        with pytest.raises(TransportError):
            await transport.receive()


@pytest.mark.asyncio
async def test_close_purges_queued_frames_and_ends_the_event_stream() -> None:
    transport = MemoryTransport()
    await transport.open()
    seen: list[TransportEvent] = []

    async def follow() -> None:
        async for event in transport.events():
            seen.append(event)

    follower = asyncio.ensure_future(follow())
    await asyncio.sleep(0)
    transport.gate.clear()
    for frame in (b"a", b"b", b"c"):
        transport.send(frame)
    await asyncio.sleep(0)
    await transport.close()
    await asyncio.wait_for(follower, 1.0)
    assert transport.stats().purged == 3
    assert [type(e) for e in seen] == [FramesDropped, FramesDropped, StateChanged]
    assert seen[-1].state is TransportState.CLOSED  # type: ignore[union-attr]
    await transport.close()  # twice is harmless
    assert transport.disconnects == 1


@pytest.mark.asyncio
async def test_a_failing_listener_is_logged_and_the_others_still_hear(
    caplog: pytest.LogCaptureFixture,
) -> None:
    heard: list[TransportEvent] = []

    def broken(event: TransportEvent) -> None:
        raise RuntimeError("listener bug")

    transport = MemoryTransport()
    transport.add_listener(broken)
    transport.add_listener(heard.append)
    with caplog.at_level(logging.ERROR, logger="servobus.transports"):
        async with transport:
            pass
    assert len(heard) == 3 and "listener" in caplog.text
    transport.remove_listener(broken)


@pytest.mark.asyncio
async def test_open_failure_leaves_it_closed_and_a_second_open_is_refused() -> None:
    transport = MemoryTransport(fail_connects=1)
    with pytest.raises(TransportError, match="not there"):
        await transport.open()
    assert transport.state is TransportState.CLOSED
    await transport.open()
    with pytest.raises(RuntimeError, match="already open"):
        await transport.open()
    await transport.close()


@pytest.mark.asyncio
async def test_a_transport_never_closed_warns_when_collected() -> None:
    transport = MemoryTransport()
    await transport.open()
    assert transport._writer is not None  # the owner forgot to close; stop its writer by hand
    transport._writer.cancel()
    await asyncio.sleep(0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        del transport
        gc.collect()
    assert any(issubclass(w.category, ResourceWarning) and "never closed" in str(w.message) for w in caught)


def test_options_are_checked() -> None:
    with pytest.raises(ValueError, match="queue_size"):
        MemoryTransport(queue_size=0)
    with pytest.raises(ValueError, match="stale_after_s"):
        MemoryTransport(stale_after_s=0)
    with pytest.raises(ValueError, match="reopen_backoff_s"):
        MemoryTransport(reopen_backoff_s=(1.0, 0.5))


def test_load_meter_sums_a_sliding_window() -> None:
    meter = LoadMeter(window_s=1.0)
    meter.add(0.05, 0.1)
    meter.add(0.55, 0.2)
    assert meter.percent(0.9) == pytest.approx(30.0)
    assert meter.percent(1.02) == pytest.approx(20.0)  # the first slot has left the window
    assert meter.percent(3.0) == 0.0
    with pytest.raises(ValueError):
        LoadMeter(window_s=0)


# ---- push delivery and send reports ----


@pytest.mark.asyncio
async def test_a_consumer_gets_every_batch_and_frames_buffered_before_it() -> None:
    batches: list[list[bytes]] = []
    async with MemoryTransport() as transport:
        transport.inject(b"early")
        transport.set_consumer(batches.append)
        transport.inject(b"a", b"b")
        transport.inject(b"c")
        assert batches == [[b"early"], [b"a", b"b"], [b"c"]]
        transport.set_consumer(None)
        transport.inject(b"d")
        assert await transport.receive() == b"d"


@pytest.mark.asyncio
async def test_a_failing_consumer_is_logged_and_delivery_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    seen: list[bytes] = []

    def consumer(frames: list[bytes]) -> None:
        seen.extend(frames)
        if frames == [b"bad"]:
            raise RuntimeError("consumer bug")

    async with MemoryTransport() as transport:
        transport.set_consumer(consumer)
        transport.inject(b"bad")
        transport.inject(b"good")
        assert transport.is_open
    assert seen == [b"bad", b"good"]
    assert "consumer bug" in caplog.text


@pytest.mark.asyncio
async def test_every_accepted_frame_is_reported_sent_or_dropped_with_the_reason() -> None:
    reports: list[tuple[bytes, float | None, str | None]] = []

    class Reporting(MemoryTransport):
        async def _transmit(self, batch: list[Outgoing[bytes]]) -> None:
            while batch:
                await self.gate.wait()
                item = batch.pop(0).item
                self.wire.append(item)
                self._sent(item, self._now())

    transport = Reporting(stale_after_s=0.05, reopen=False)
    await transport.open()
    transport.set_send_reporter(lambda item, at, why: reports.append((item, at, why)))
    loop = asyncio.get_running_loop()
    before = loop.time()
    transport.send(b"sent")
    await transport.drain()
    transport.gate.clear()
    transport.send(b"held")  # the writer takes it and waits at the gate
    await asyncio.sleep(0)
    transport.send(b"stale")
    await asyncio.sleep(0.1)
    transport.gate.set()
    await transport.drain()
    transport.gate.clear()
    transport.send(b"in flight")
    await asyncio.sleep(0)
    transport.send(b"queued")
    transport.fail(OSError("unplugged"))
    await transport.close()
    by_item = {item: (at, why) for item, at, why in reports}
    assert by_item[b"sent"][1] is None and before <= by_item[b"sent"][0] <= loop.time()  # type: ignore[operator]
    assert by_item[b"held"][1] is None
    assert by_item[b"stale"] == (None, "stale")
    assert by_item[b"in flight"] == (None, "purged") and by_item[b"queued"] == (None, "purged")
    assert len(reports) == 5

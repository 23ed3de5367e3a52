"""The transport base on an in-memory device: queueing, draining, loss, reopen, events, counters, the
task group it owns, on asyncio and on trio (virtual time).

The real paths run the same rules in test_contract.py; here each rule is driven exactly (a device
that fails on cue, a wire that stalls on cue) so that every branch is seen.
"""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import logging
import warnings
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import anyio.lowlevel
import pytest

from _backends import BACKENDS, virtual
from servobus.errors import TransportError
from servobus.transports import (
    FramesDropped,
    SendQueueFull,
    StateChanged,
    Transport,
    TransportEvent,
    TransportState,
    TransportStats,
)
from servobus.transports.base import Outgoing
from servobus.transports.contract import LineRules
from servobus.transports.stats import LoadMeter

pytestmark = pytest.mark.anyio


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


class Gate:
    """A clearable event (anyio's events cannot be cleared)."""

    def __init__(self) -> None:
        self.is_open = True
        self._event: anyio.Event | None = None

    def clear(self) -> None:
        self.is_open = False

    def set(self) -> None:
        self.is_open = True
        if self._event is not None:
            self._event.set()
            self._event = None

    async def wait(self) -> None:
        while not self.is_open:
            if self._event is None:
                self._event = anyio.Event()
            await self._event.wait()


class MemoryTransport(Transport[bytes, bytes]):
    """A device in memory: ``wire`` gets what is sent; ``gate`` (when cleared) stalls the writer."""

    batch_size = 1

    def __init__(self, *, fail_connects: int = 0, **options: Any) -> None:
        super().__init__(name="memory", **options)
        self.wire: list[bytes] = []
        self.gate = Gate()
        self.connects = 0
        self.disconnects = 0
        self.fail_connects = fail_connects

    def send(self, data: bytes, handle: object = None) -> None:
        self._enqueue(data, None, handle)

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
            outgoing = batch.pop(0)
            self.wire.append(outgoing.item)
            self._stats.frames_out += 1
            self._sent(outgoing.handle, self._now())

    def inject(self, *frames: bytes) -> None:
        self._deliver(list(frames))

    def fail(self, cause: BaseException) -> None:
        self._lose(cause)


async def until(condition: Callable[[], bool], turns: int = 1000) -> None:
    """Let the other tasks run until ``condition()`` holds (no time passes)."""
    for _ in range(turns):
        if condition():
            return
        await anyio.lowlevel.checkpoint()
    raise AssertionError("the condition never held")


async def outcome(results: list[object], call: Callable[[], Awaitable[object]]) -> None:
    """Append what ``call()`` returned or raised (a TransportError or TimeoutError) to ``results``."""
    try:
        results.append(await call())
    except (TransportError, TimeoutError) as exc:
        results.append(exc)


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


async def test_a_full_queue_refuses_the_frame_and_drain_waits_for_room() -> None:
    async with MemoryTransport(queue_size=2) as transport:
        transport.gate.clear()
        transport.send(b"a")
        await until(lambda: transport._sending.transmitting)  # the writer took "a", stalls at the gate
        transport.send(b"b")
        transport.send(b"c")
        assert transport.queue_room == 0
        with pytest.raises(SendQueueFull, match="queue full") as caught:
            transport.send(b"d")
        assert isinstance(caught.value, TransportError)  # (no longer an asyncio.QueueFull)
        drained: list[object] = []
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(outcome, drained, transport.drain)
            await anyio.sleep(0.01)
            assert drained == []
            transport.gate.set()
        assert drained == [None]
        assert transport.wire == [b"a", b"b", b"c"]
        stats = transport.stats()
        assert (stats.queue_full, stats.queue_depth, stats.frames_out) == (1, 0, 3)


async def test_frames_that_waited_longer_than_stale_after_are_dropped_not_sent() -> None:
    events: list[TransportEvent] = []
    async with MemoryTransport(stale_after_s=0.05) as transport:
        transport.add_listener(events.append)
        transport.gate.clear()
        transport.send(b"first")
        await until(lambda: transport._sending.transmitting)
        transport.send(b"old")
        await anyio.sleep(0.1)
        transport.gate.set()
        await transport.drain()
        transport.send(b"fresh")
        await transport.drain()
    assert transport.wire == [b"first", b"fresh"]
    assert transport.stats().stale == 1
    assert [(e.reason, e.count) for e in events if isinstance(e, FramesDropped)] == [("stale", 1)]


async def test_a_loss_fails_every_waiter_at_once_purges_the_queue_and_reopens() -> None:
    events: list[TransportEvent] = []
    transport = MemoryTransport(reopen_backoff_s=(0.01, 0.04), fail_connects=0)
    transport.add_listener(events.append)
    async with transport:
        transport.gate.clear()
        for frame in (b"1", b"2", b"3"):
            transport.send(frame)
        results: list[object] = []
        async with anyio.create_task_group() as tasks:
            for call in (transport.receive, transport.receive, transport.receive_batch, transport.drain):
                tasks.start_soon(outcome, results, call)
            await anyio.sleep(0.01)
            assert results == []
            transport.fail_connects = 3  # the device stays away for three attempts
            cause = OSError(5, "Input/output error")
            lost_at = anyio.current_time()
            transport.fail(cause)
            transport.fail(OSError("again"))  # a second report of the same loss changes nothing
        assert anyio.current_time() == lost_at  # every waiter failed at once
        assert len(results) == 4
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


async def test_reopen_attempts_back_off_exponentially() -> None:
    attempts: list[float] = []

    class Counting(MemoryTransport):
        async def _connect(self) -> None:
            attempts.append(anyio.current_time())
            await super()._connect()

    async with Counting(reopen_backoff_s=(0.01, 0.04)) as transport:
        transport.fail_connects = 4
        lost_at = anyio.current_time()
        transport.fail(OSError("gone"))
        await transport.wait_open(timeout=1.0)
    gaps = [round(b - a, 6) for a, b in zip([lost_at, *attempts[1:]], attempts[1:], strict=False)]
    assert gaps == [0.01, 0.02, 0.04, 0.04, 0.04]


async def test_a_loss_reported_from_a_loop_callback_fails_waiters_and_recovers() -> None:
    """A reader's callback (asyncio's add_reader, a thread's call_soon_threadsafe) runs in no task."""
    async with MemoryTransport(reopen_backoff_s=(0.01, 0.01)) as transport:
        assert transport._runtime is not None
        results: list[object] = []
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(outcome, results, transport.receive)
            await anyio.sleep(0.001)
            transport._runtime.call_soon(transport.fail, OSError("from a callback"))
        assert len(results) == 1 and isinstance(results[0], TransportError)
        await transport.wait_open(timeout=1.0)
    assert (transport.stats().losses, transport.stats().reopens) == (1, 1)


def test_a_loss_reported_from_a_bare_asyncio_callback_recovers() -> None:
    """Under plain asyncio (no anyio.run naming the backend to sniffio) a loop callback is no task:
    the loss must still start the recovery (asyncio-specific, so asyncio.run)."""

    async def main() -> TransportStats:
        async with MemoryTransport(reopen_backoff_s=(0.01, 0.01)) as transport:
            asyncio.get_running_loop().call_soon(transport.fail, OSError("from add_reader"))
            await asyncio.sleep(0.005)
            assert transport.stats().losses == 1
            await transport.wait_open(timeout=1.0)
        return transport.stats()

    stats = asyncio.run(main())
    assert (stats.losses, stats.reopens) == (1, 1)


async def test_without_reopen_a_lost_transport_stays_lost_until_closed() -> None:
    async with MemoryTransport(reopen=False) as transport:
        transport.fail(ConnectionError("gone"))
        await anyio.sleep(0.05)
        assert transport.state is TransportState.LOST and transport.connects == 1
        with pytest.raises(TimeoutError):
            await transport.wait_open(timeout=0.05)
    assert transport.state is TransportState.CLOSED


async def test_close_during_reopen_attempts_stops_them() -> None:
    transport = MemoryTransport(reopen_backoff_s=(0.01, 0.01))
    results: list[object] = []
    async with anyio.create_task_group() as tasks:
        await transport.open()
        transport.fail_connects = 1000
        transport.fail(ConnectionError("gone"))
        await anyio.sleep(0.05)
        tasks.start_soon(outcome, results, transport.wait_open)
        await anyio.sleep(0.001)
        await transport.close()
        attempts = transport.connects
        await anyio.sleep(0.05)
    assert transport.connects == attempts
    assert len(results) == 1 and isinstance(results[0], TransportError) and "closed" in str(results[0])


async def test_received_frames_are_buffered_and_the_oldest_dropped_when_nobody_reads() -> None:
    async with MemoryTransport(rx_buffer=3) as transport:
        transport.inject(b"1", b"2")
        transport.inject(b"3", b"4", b"5")
        assert await transport.receive_batch(max_frames=2) == [b"3", b"4"]
        assert await transport.receive() == b"5"
        assert transport.stats().rx_overflow == 2
        later: list[object] = []
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(outcome, later, transport.receive_batch)
            await anyio.sleep(0.001)
            transport.inject(b"6")
        assert later == [[b"6"]]


async def test_frames_received_before_a_loss_are_still_delivered() -> None:
    async with MemoryTransport(reopen=False) as transport:
        transport.inject(b"last words")
        transport.fail(ConnectionError("gone"))
        assert await transport.receive() == b"last words"
        with pytest.raises(TransportError):
            await transport.receive()


async def test_close_purges_queued_frames_and_ends_the_event_stream_and_iteration() -> None:
    transport = MemoryTransport()
    seen: list[TransportEvent] = []
    received: list[bytes] = []

    async def follow() -> None:
        async for event in transport.events():
            seen.append(event)

    async def iterate() -> None:
        async for frame in transport:
            received.append(frame)

    async with anyio.create_task_group() as tasks:
        await transport.open()
        tasks.start_soon(follow)
        tasks.start_soon(iterate)
        await anyio.sleep(0.001)
        transport.inject(b"in")
        transport.gate.clear()
        for frame in (b"a", b"b", b"c"):
            transport.send(frame)
        await until(lambda: transport._sending.transmitting)
        await transport.close()
    assert transport.stats().purged == 3
    assert received == [b"in"]
    assert [type(e) for e in seen] == [FramesDropped, FramesDropped, StateChanged]
    assert seen[-1].state is TransportState.CLOSED  # type: ignore[union-attr]
    await transport.close()  # twice is harmless
    assert transport.disconnects == 1


async def test_the_event_stream_drops_the_oldest_when_its_reader_lags() -> None:
    async with MemoryTransport() as transport:
        stream = transport.events(maxsize=2)
        first: list[TransportEvent] = []

        async def read_one() -> None:
            first.append(await stream.__anext__())

        async with anyio.create_task_group() as tasks:
            tasks.start_soon(read_one)
            await anyio.sleep(0.001)
            transport._emit(FramesDropped("stale", 1, 0.0))  # the reader takes this one
            await until(lambda: len(first) == 1)
            for count in (2, 3, 4):
                transport._emit(FramesDropped("stale", count, 0.0))
        rest = [await stream.__anext__() for _ in range(2)]
        await stream.aclose()  # type: ignore[attr-defined]
    assert [e.count for e in [*first, *rest]] == [1, 3, 4]  # type: ignore[union-attr]


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


async def test_open_failure_leaves_it_closed_and_a_second_open_is_refused() -> None:
    transport = MemoryTransport(fail_connects=1)
    with pytest.raises(TransportError, match="not there"):
        await transport.open()
    assert transport.state is TransportState.CLOSED and transport._owned.tasks is None
    await transport.open()
    with pytest.raises(RuntimeError, match="already open"):
        await transport.open()
    await transport.close()


def test_a_transport_never_closed_warns_when_collected() -> None:
    transport = MemoryTransport()
    transport._ever_opened = True  # as if opened and forgotten (a test cannot leave a task group open)
    transport._state = TransportState.OPEN
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


def test_the_rules_are_built_from_what_the_subclass_declares() -> None:
    assert MemoryTransport(stale_after_s=0.2).rules == LineRules(stale_after_s=0.2)

    class HalfDuplex(MemoryTransport):
        half_duplex = True
        bitrate = 115_200

        @property
        def gap_s(self) -> float:
            return 0.001

    assert HalfDuplex(stale_after_s=None).rules == LineRules(
        half_duplex=True, bitrate=115_200, gap_s=0.001, stale_after_s=None
    )


# ---- the task group the transport owns ----


async def test_close_from_another_task_is_refused_and_the_owner_still_closes() -> None:
    transport = MemoryTransport()
    refused: list[BaseException] = []

    async def close_elsewhere() -> None:
        try:
            await transport.close()
        except RuntimeError as exc:
            refused.append(exc)

    async with anyio.create_task_group() as tasks:
        await transport.open()
        tasks.start_soon(close_elsewhere)
        await until(lambda: bool(refused))
        assert transport.is_open
        await transport.close()
    assert "must be called by the task that opened it" in str(refused[0])
    assert transport.state is TransportState.CLOSED


class Reading(MemoryTransport):
    """Starts a reader task per connection in the transport's task group, as a real transport does."""

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.readers_running = 0
        self.reader_error: BaseException | None = None

    async def _connect(self) -> None:
        await super()._connect()
        self._tasks.start_soon(self._read, self._generation)

    async def _read(self, generation: int) -> None:
        self.readers_running += 1
        try:
            while generation == self._generation:
                await anyio.sleep(0.01)
                if self.reader_error is not None:
                    raise self.reader_error
                self._deliver([b"tick"])
        finally:
            self.readers_running -= 1


async def test_nothing_the_transport_started_runs_after_close() -> None:
    transport = Reading(reopen_backoff_s=(0.01, 0.01))
    async with transport:
        assert await transport.receive() == b"tick"
        transport.fail(OSError("gone"))  # a recovery task, then a second reader
        await transport.wait_open(timeout=1.0)
        await anyio.sleep(0.05)
        assert await transport.receive() == b"tick"
        assert transport.readers_running == 1  # the lost connection's reader has ended
    assert transport.readers_running == 0 and transport._owned.tasks is None
    await anyio.sleep(0.1)
    assert transport.readers_running == 0


async def test_a_background_task_failure_is_raised_at_close_not_lost() -> None:
    transport = Reading()
    with pytest.raises(BaseExceptionGroup) as caught:
        async with transport:
            transport.reader_error = ValueError("reader bug")
            await anyio.sleep(1.0)  # cancelled when the reader fails
            raise AssertionError("not reached: the task group cancels its owner")
    assert caught.group_contains(ValueError, match="reader bug")
    assert transport.state is TransportState.CLOSED


async def test_the_block_s_own_error_leaves_as_it_is() -> None:
    with pytest.raises(KeyError):
        async with MemoryTransport() as transport:
            transport.send(b"x")
            raise KeyError("mine")
    assert transport.state is TransportState.CLOSED


async def test_a_transmit_bug_is_logged_as_a_loss_and_the_transport_reopens(
    caplog: pytest.LogCaptureFixture,
) -> None:
    class Buggy(MemoryTransport):
        bugs = 1

        async def _transmit(self, batch: list[Outgoing[bytes]]) -> None:
            if self.bugs:
                self.bugs -= 1
                raise ZeroDivisionError("transmit bug")
            await super()._transmit(batch)

    with caplog.at_level(logging.WARNING, logger="servobus.transports"):
        async with Buggy(reopen_backoff_s=(0.01, 0.01)) as transport:
            transport.send(b"lost")
            await until(lambda: transport.state is TransportState.LOST)
            await transport.wait_open(timeout=1.0)
            transport.send(b"sent")
            await transport.drain()
    assert transport.wire == [b"sent"] and "transmit bug" in caplog.text
    assert transport.stats().purged == 1


# ---- push delivery and send reports ----


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


async def test_every_accepted_frame_is_reported_sent_or_dropped_with_the_reason() -> None:
    reports: list[tuple[object, float | None, str | None]] = []
    transport = MemoryTransport(stale_after_s=0.05, reopen=False)
    async with transport:
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        before = anyio.current_time()
        transport.send(b"sent")
        await transport.drain()
        transport.gate.clear()
        transport.send(b"held")  # the writer takes it and waits at the gate
        await until(lambda: transport._sending.transmitting)
        transport.send(b"stale")
        await anyio.sleep(0.1)
        transport.gate.set()
        await transport.drain()
        transport.gate.clear()
        transport.send(b"in flight")
        await until(lambda: transport._sending.transmitting)
        transport.send(b"queued")
        transport.fail(OSError("unplugged"))
    by_item = {item: (at, why) for item, at, why in reports}
    assert by_item[b"sent"] == (before, None)
    assert by_item[b"held"] == (before + 0.1, None)
    assert by_item[b"stale"] == (None, "stale")
    assert by_item[b"in flight"] == (None, "purged") and by_item[b"queued"] == (None, "purged")
    assert len(reports) == 5


@dataclasses.dataclass
class Handle:
    """A sender's own handle (the Bus passes its Request)."""

    n: int


async def test_reports_echo_the_handle_given_whatever_the_transport_sends() -> None:
    reports: list[tuple[object, str | None]] = []

    class Copying(MemoryTransport):
        def send(self, data: bytes, handle: object = None) -> None:
            self._enqueue(bytes(bytearray(data)), None, data if handle is None else handle)

    async with Copying(reopen=False) as transport:
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, why)))
        first, second = Handle(1), Handle(2)
        transport.send(b"one", first)
        await transport.drain()
        transport.gate.clear()
        transport.send(b"two", second)
        transport.send(b"three")
        await until(lambda: transport._sending.transmitting)
        transport.fail(OSError("gone"))
    assert reports[0] == (first, None) and reports[0][0] is first
    assert {id(handle): why for handle, why in reports[1:]} == {id(second): "purged", id(b"three"): "purged"}
    assert len(reports) == 3

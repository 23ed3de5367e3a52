"""One contract over every path: SLCAN on a pty (python-can's and native), RS485 on a pty, CAN FD on
the virtual bus, and the in-process simulated bus.

Every test here runs over each path of tests/transports/_paths.py; the unplug and reopen tests
over the two pty paths, where a device can really vanish.
"""

from __future__ import annotations

import asyncio
import time
import zlib
from pathlib import Path

import pytest

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.transports import TransportState

from ._paths import PATHS, LinePath, open_path

PTY_PATHS = ("slcan", "rs485", "native-slcan")
SHORT_SOAK = 2_000
LONG_SOAK = 100_000


async def soak(path: LinePath, n: int, *, window: int = 32) -> None:
    """Send ``n`` numbered requests (``window`` in flight) and check every reply, in order, once.

    Checks order and uniqueness frame by frame (a reply's number must be the next expected one),
    completeness by count, and content by a CRC-32 over every payload on both sides.
    """
    transport = path.transport
    sent_crc = received_crc = 0
    sent = received = 0
    while received < n:
        while sent < n and sent - received < window and transport.queue_room:
            path.request(sent)
            sent += 1
        for reply in await asyncio.wait_for(transport.receive_batch(), 5.0):
            data = path.reply_payload(reply)
            assert path.seq_of(data) == received, f"reply {path.seq_of(data)} where {received} was due"
            received_crc = zlib.crc32(data, received_crc)
            received += 1
    for data in path.peer_seen():
        sent_crc = zlib.crc32(data, sent_crc)
    assert len(path.peer_seen()) == n
    assert received_crc == sent_crc
    stats = transport.stats()
    assert (stats.frames_out, stats.frames_in) == (n, n)
    assert (stats.stale, stats.purged, stats.rx_overflow, stats.queue_full) == (0, 0, 0, 0)
    assert (stats.discarded_bytes, stats.crc_errors) == (0, 0)


@pytest.mark.asyncio
@pytest.mark.parametrize("name", PATHS)
async def test_requests_are_answered_through_the_real_path(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path) as path:
        path.request(7)
        reply = await asyncio.wait_for(path.transport.receive(), 2.0)
        assert path.seq_of(path.reply_payload(reply)) == 7
        assert abs(reply.timestamp - time.monotonic()) < 1.0  # the loop's clock
        stats = path.transport.stats()
        assert stats.state is TransportState.OPEN
        assert stats.frames_in == stats.frames_out == 1 and stats.bytes_in > 0
        assert stats.bytes_out == stats.bytes_in


@pytest.mark.asyncio
@pytest.mark.parametrize("name", PATHS)
async def test_no_frame_lost_duplicated_or_reordered_short(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path) as path:
        await soak(path, SHORT_SOAK)


@pytest.mark.slow
@pytest.mark.asyncio
@pytest.mark.parametrize("name", PATHS)
async def test_no_frame_lost_duplicated_or_reordered_over_100k_frames(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path, queue_size=1024) as path:
        started = time.perf_counter()
        await soak(path, LONG_SOAK)
        print(f"{name}: {LONG_SOAK} round trips in {time.perf_counter() - started:.1f} s")


async def _stall_writer(path: LinePath) -> None:
    """Leave frames queued, unanswered, so a drain() stays pending (no device has id 9).

    RS485 holds the line for each frame's reply; the slcan paths are opened with a long gap.
    """
    for seq in range(3):
        if path.name == "rs485":
            frame = Frame(arbitration_id=9, data=bytes([seq, 0, 0, 0, 0, 0, 0, 0]), is_serial=True)
            path.transport.send(frame, reply_timeout_s=5.0)
        else:
            path.transport.send(Frame(arbitration_id=0x149, data=bytes([seq])))


@pytest.mark.asyncio
@pytest.mark.parametrize("name", PTY_PATHS)
async def test_unplug_fails_every_pending_waiter_within_100_ms(name: str, tmp_path: Path) -> None:
    # slcan (both): keep frames queued for a while
    options = {"min_gap_s": 0.5} if name in ("slcan", "native-slcan") else {}
    async with open_path(name, tmp_path, reopen=False, **options) as path:
        transport = path.transport
        await _stall_writer(path)
        waiters = [asyncio.ensure_future(transport.receive()) for _ in range(3)]
        waiters.append(asyncio.ensure_future(transport.receive_batch()))
        waiters.append(asyncio.ensure_future(transport.drain()))
        await asyncio.sleep(0.05)
        assert not any(w.done() for w in waiters)
        assert path.unplug is not None
        unplugged = time.monotonic()
        path.unplug()
        results = await asyncio.wait_for(asyncio.gather(*waiters, return_exceptions=True), 1.0)
        elapsed = time.monotonic() - unplugged
        assert all(isinstance(r, TransportError) for r in results), results
        assert elapsed < 0.1, f"waiters failed {elapsed * 1000:.1f} ms after the unplug"
        assert all(r.__cause__ is not None for r in results)  # chained to the I/O error
        assert transport.state is TransportState.LOST
        with pytest.raises(TransportError, match="device lost"):
            path.request(99)
        await asyncio.sleep(0.05)  # a batch already in the CAN writer thread reports back
        stats = transport.stats()
        assert (stats.losses, stats.purged, stats.queue_depth) == (1, 3 - stats.frames_out, 0)


@pytest.mark.asyncio
@pytest.mark.parametrize("name", PTY_PATHS)
async def test_the_transport_reopens_when_the_device_returns_and_replays_nothing(
    name: str, tmp_path: Path
) -> None:
    async with open_path(name, tmp_path, reopen_backoff_s=(0.02, 0.1)) as path:
        transport = path.transport
        path.request(1)
        await asyncio.wait_for(transport.receive(), 2.0)
        await _stall_writer(path)
        assert path.unplug is not None and path.replug is not None
        path.unplug()
        with pytest.raises(TransportError):
            await asyncio.wait_for(transport.receive(), 1.0)
        await asyncio.sleep(0.3)  # several reopen attempts fail while the device is away
        assert transport.state is TransportState.LOST
        await path.replug()
        await transport.wait_open(timeout=5.0)
        path.request(2)
        reply = await asyncio.wait_for(transport.receive(), 2.0)
        assert path.seq_of(path.reply_payload(reply)) == 2
        # The new device saw only what was sent after it came back: nothing queued before the loss.
        assert [path.seq_of(p) for p in path.peer_seen()] == [2]
        stats = transport.stats()
        assert (stats.losses, stats.reopens, stats.state) == (1, 1, TransportState.OPEN)


@pytest.mark.asyncio
@pytest.mark.parametrize("name", PATHS)
async def test_close_ends_async_iteration_and_pending_receivers_fail(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path) as path:
        transport = path.transport
        path.request(1)

        async def iterate() -> list[object]:
            return [frame async for frame in transport]

        iteration = asyncio.ensure_future(iterate())
        await asyncio.sleep(0.2)
        await transport.close()
        assert len(await asyncio.wait_for(iteration, 1.0)) == 1
        with pytest.raises(TransportError, match="closed"):
            await transport.receive()
        assert transport.state is TransportState.CLOSED

"""Both readiness lanes of the descriptor readers (``servobus.transports._watch``), on both backends.

asyncio reads through the loop's reader callback (the measured fast lane) and trio through a task
waiting with ``anyio.wait_readable``; asyncio can be put on the task lane too
(``ASYNCIO_CALLBACKS = False``). Here the watch itself is tested on every lane, and scenarios of the
transports that read descriptors (the native SLCAN adapter, python-can's slcan through CanTransport's
descriptor reader, an RS485 line) are run again on asyncio's task lane.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest

from servobus import runtime
from servobus.transports import _watch

from . import test_can, test_rs485, test_slcan

pytestmark = pytest.mark.anyio


@pytest.fixture(params=["callback", "task"])
def lane(
    request: pytest.FixtureRequest, anyio_backend: object, monkeypatch: pytest.MonkeyPatch
) -> Iterator[str]:
    """The lane asyncio reads on; trio has only the task lane (its "callback" run is skipped)."""
    backend = anyio_backend if isinstance(anyio_backend, str) else anyio_backend[0]  # type: ignore[index]
    if backend == "trio" and request.param == "callback":
        pytest.skip("trio has one lane: a task waiting with anyio.wait_readable")
    monkeypatch.setattr(_watch, "ASYNCIO_CALLBACKS", request.param == "callback")
    yield request.param


async def test_the_watch_calls_back_per_readiness_until_cancelled_and_stop_waits(lane: str) -> None:
    read_fd, write_fd = os.pipe()
    os.set_blocking(read_fd, False)
    got: list[bytes] = []
    arrived = anyio.Event()

    def on_ready() -> None:
        got.append(os.read(read_fd, 100))
        arrived.set()

    try:
        async with anyio.create_task_group() as tasks:
            watch = _watch.ReadWatch(runtime.current(), tasks, read_fd, on_ready, "test")
            assert watch.lane == lane
            watch.start()
            for chunk in (b"a", b"bc"):
                arrived = anyio.Event()
                os.write(write_fd, chunk)
                with anyio.fail_after(1):
                    await arrived.wait()
            await watch.stop()
            os.write(write_fd, b"late")
            await anyio.sleep(0.02)
        assert got == [b"a", b"bc"]  # nothing read after stop()
        assert os.read(read_fd, 100) == b"late"
    finally:
        os.close(read_fd)
        os.close(write_fd)


async def test_a_failing_callback_is_logged_and_ends_the_watch_without_spinning(
    lane: str, caplog: pytest.LogCaptureFixture
) -> None:
    read_fd, write_fd = os.pipe()
    calls = 0

    def on_ready() -> None:  # never reads: the descriptor stays readable
        nonlocal calls
        calls += 1
        raise RuntimeError("reader bug")

    try:
        async with anyio.create_task_group() as tasks:
            watch = _watch.ReadWatch(runtime.current(), tasks, read_fd, on_ready, "test")
            watch.start()
            os.write(write_fd, b"x")
            with caplog.at_level(logging.ERROR, logger="servobus.transports"):
                await anyio.sleep(0.05)
            await watch.stop()
        assert calls == 1
        assert "the reader failed" in caplog.text
    finally:
        os.close(read_fd)
        os.close(write_fd)


async def test_native_slcan_reads_on_the_lane(lane: str) -> None:
    async with test_slcan.raw_open() as (transport, _):
        assert transport._port is not None and transport._port._watch is not None
        assert transport._port._watch.lane == lane
    await test_slcan.test_a_malformed_line_is_one_bad_frame_and_the_transport_stays_open()
    await test_slcan.test_one_mebibyte_without_cr_costs_bounded_memory_and_little_loop_time()


async def test_python_can_descriptor_reader_on_the_lane(lane: str) -> None:
    await test_can.test_a_malformed_slcan_line_on_a_real_pty_is_one_bad_frame_not_a_lost_adapter()


async def test_rs485_reads_and_loses_a_port_on_the_lane(lane: str, tmp_path: Path) -> None:
    await test_rs485.test_garbage_and_corrupt_frames_are_counted_and_the_good_frame_still_comes()
    await test_rs485.test_modbus_rtu_at_19200_and_a_truncated_frame_is_dropped_on_the_silence()
    await test_rs485.test_a_loss_while_waiting_for_a_reply_leaves_the_line_usable_after_the_reopen(tmp_path)


def test_callbacks_outside_a_task_can_use_anyio_under_plain_asyncio(channel: str) -> None:
    """Under ``asyncio.run`` (no anyio runner), a reader callback and a thread's hand-over run in no
    task: the transports run them in a context that names asyncio to sniffio, so a consumer or a
    send reporter (the Bus's intake) may call anyio there."""
    import asyncio

    import can
    import sniffio

    from servobus.frame import Frame
    from servobus.transports import CanTransport

    seen: dict[str, list[str]] = {"can rx": [], "can report": [], "slcan rx": []}

    def probe(where: str) -> None:
        try:
            seen[where].append(sniffio.current_async_library())
        except sniffio.AsyncLibraryNotFoundError:
            seen[where].append("none")

    async def scenario() -> None:
        peer = can.Bus(interface="virtual", channel=channel)
        try:
            # min_gap_s: sends go through the writer thread, so their reports are handed over
            async with CanTransport("virtual", channel, ignore_config=True, min_gap_s=0.001) as transport:
                transport.set_consumer(lambda frames: probe("can rx"))
                transport.set_send_reporter(lambda handle, at, why: probe("can report"))
                peer.send(can.Message(arbitration_id=0x241, data=b"\x01", is_extended_id=False))
                transport.send(Frame(arbitration_id=0x141, data=b"\x02"))
                await transport.drain()
                for _ in range(100):
                    if seen["can rx"]:
                        break
                    await asyncio.sleep(0.01)
        finally:
            peer.shutdown()
        async with test_slcan.raw_open() as (slcan, adapter):
            slcan.set_consumer(lambda frames: probe("slcan rx"))
            adapter.inject(test_slcan.GOOD)
            for _ in range(100):
                if seen["slcan rx"]:
                    break
                await asyncio.sleep(0.01)

    asyncio.run(scenario())
    assert seen == {"can rx": ["asyncio"], "can report": ["asyncio"], "slcan rx": ["asyncio"]}

"""CanTransport's send errors that keep the loop (issue [field], case 4): a full adapter buffer costs
one short wait per episode, then frames fail fast; bus-off is a state of the open bus.

The adapter is a python-can bus whose sends fail on cue (test_can's ``_FlakyBus``), or python-can's
``virtual`` bus for error frames.
"""

from __future__ import annotations

import errno
import time
from typing import Any

import anyio
import can
import pytest

from servobus.frame import Frame
from servobus.transports import (
    BusOff,
    BusOffError,
    BusRestarted,
    CanTransport,
    ErrorFrame,
    TransportEvent,
    TransportStats,
)

from . import test_can
from ._anyio_help import within

pytestmark = pytest.mark.anyio

Reports = list[tuple[Any, float | None, str | None]]


@pytest.fixture
def flaky(monkeypatch: pytest.MonkeyPatch) -> type[test_can._FlakyBus]:
    test_can._FlakyBus.sent = []
    test_can._FlakyBus.failures = []
    monkeypatch.setattr(can, "Bus", lambda **config: test_can._FlakyBus(**config))
    return test_can._FlakyBus


def _down() -> can.CanOperationError:
    return can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)


def _frame(n: int) -> Frame:
    return Frame(arbitration_id=0x141, data=bytes([n]))


async def test_a_full_buffer_is_waited_for_once_then_each_frame_gets_one_try(
    flaky: type[test_can._FlakyBus],
) -> None:
    flaky.failures = [test_can._enobufs() for _ in range(10_000)]
    reports: Reports = []
    async with CanTransport("flaky", "x", ignore_config=True, enobufs_timeout_s=0.05) as transport:
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        started = time.perf_counter()
        for n in range(40):
            transport.send(_frame(n), n)
            await anyio.sleep(0)  # (one batch each, as a control loop's ticks would)
        await transport.drain()
        took_s = time.perf_counter() - started
        stats: TransportStats = transport.stats()
    assert [why for _, _, why in reports] == ["queue_full"] * 40
    assert stats.enobufs_dropped == 40 and stats.losses == 0
    assert took_s < 0.05 + 0.2  # one wait (the first frame's), not forty (it was 0.1 s a frame)
    flaky.failures = [test_can._enobufs()]  # ... and a frame that goes through ends the episode
    async with CanTransport("flaky", "x", ignore_config=True, enobufs_timeout_s=0.5) as transport:
        transport.send(_frame(1))
        await transport.drain()
        assert transport.stats().enobufs_waits == 1 and transport.stats().frames_out == 1


async def test_enetdown_is_bus_off_not_a_lost_device_and_a_probe_finds_the_restart(
    flaky: type[test_can._FlakyBus],
) -> None:
    flaky.failures = [_down(), _down()]
    events: list[TransportEvent] = []
    reports: Reports = []
    async with CanTransport("flaky", "x", ignore_config=True) as transport:
        transport.add_listener(events.append)
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        transport.send(_frame(1), 1)
        await within(2.0, transport.drain())  # the worker's ENETDOWN reaches the loop
        assert transport.bus_off and transport.is_open
        with pytest.raises(BusOffError):
            transport.send(_frame(2), 2)  # refused at once, nothing queued
        await anyio.sleep(transport.bus_off_probe_s * 1.5)
        transport.send(_frame(3), 3)  # the probe: the adapter refuses it again
        await transport.drain()
        assert transport.bus_off
        await anyio.sleep(transport.bus_off_probe_s * 1.5)
        transport.send(_frame(4), 4)  # the next probe goes through: the controller is back
        await transport.drain()
        assert not transport.bus_off
        transport.send(_frame(5), 5)
        await transport.drain()
        stats: TransportStats = transport.stats()
    assert [(h, why) for h, _, why in reports] == [(1, "bus_off"), (3, "bus_off"), (4, None), (5, None)]
    assert [bytes(m.data) for m in flaky.sent] == [b"\x04", b"\x05"]
    assert (stats.losses, stats.reopens, stats.bus_off, stats.restarted) == (0, 0, 1, 1)
    assert stats.bus_off_dropped == 3  # 1 and 3 by the adapter, 2 at once
    assert [type(e) for e in events if isinstance(e, BusOff | BusRestarted)] == [BusOff, BusRestarted]


async def test_bus_off_and_restarted_error_frames_move_the_state_and_are_each_counted(
    channel: str, peer: can.BusABC
) -> None:
    events: list[TransportEvent] = []
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        transport.add_listener(events.append)
        peer.send(can.Message(is_error_frame=True, arbitration_id=0x040, data=bytes(8)))
        with anyio.fail_after(2.0):
            while not transport.bus_off:
                await anyio.sleep(0.005)
        with pytest.raises(BusOffError):
            transport.send(_frame(1))
        peer.send(can.Message(is_error_frame=True, arbitration_id=0x100, data=bytes(8)))
        with anyio.fail_after(2.0):
            while transport.bus_off:
                await anyio.sleep(0.005)
        transport.send(_frame(2))
        stats: TransportStats = transport.stats()
    assert (stats.error_frames, stats.bus_off, stats.restarted, stats.losses) == (2, 1, 1, 0)
    kinds = [type(e) for e in events if isinstance(e, ErrorFrame | BusOff | BusRestarted)]
    assert kinds == [ErrorFrame, BusOff, ErrorFrame, BusRestarted]
    (message,) = test_can._recv_all(peer, 1)
    assert bytes(message.data) == b"\x02"


@pytest.fixture
def peer(channel: str) -> Any:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


async def test_on_the_loop_native_virtual_path_enetdown_is_bus_off_at_once(
    channel: str, peer: can.BusABC, monkeypatch: pytest.MonkeyPatch
) -> None:
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        assert transport.bus is not None
        refuse = [_down()]
        send = transport.bus.send

        def failing(message: can.Message, timeout: float | None = None) -> None:
            if refuse:
                raise refuse.pop()
            send(message, timeout)

        monkeypatch.setattr(transport.bus, "send", failing)
        with pytest.raises(BusOffError):
            transport.send(_frame(1))  # written from send() itself: refused there, at once
        assert transport.bus_off and transport.is_open
        await anyio.sleep(transport.bus_off_probe_s * 1.5)
        transport.send(_frame(2))  # the probe goes through: back
        assert not transport.bus_off
        stats: TransportStats = transport.stats()
    assert (stats.bus_off, stats.restarted, stats.bus_off_dropped, stats.losses) == (1, 1, 1, 0)
    (message,) = test_can._recv_all(peer, 1)
    assert bytes(message.data) == b"\x02"

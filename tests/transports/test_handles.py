"""The FrameLink contract on the hardware transports: ``send(frame, handle)`` reports name the handle,
whichever path the frame took (written from ``send`` itself, a writer thread, the port's writer), and
so do the drops; each transport's ``rules`` come from its own settings. On asyncio and trio."""

from __future__ import annotations

import os
import tty
from collections.abc import Iterator
from typing import Any

import anyio
import can
import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.transports import CanTransport, SerialTransport
from servobus.transports.contract import FrameLink, LineRules

from . import test_can, test_slcan
from ._anyio_help import within

pytestmark = pytest.mark.anyio


class Handle:
    """What a Bus passes: an object of its own, never the frame."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __repr__(self) -> str:
        return f"Handle({self.n})"


Reports = list[tuple[Any, float | None, str | None]]


@pytest.fixture
def peer(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


@pytest.mark.parametrize("min_gap_s", [0.0, 0.001], ids=["from-send", "writer-thread"])
async def test_can_reports_name_the_handle(channel: str, peer: can.BusABC, min_gap_s: float) -> None:
    reports: Reports = []
    async with CanTransport("virtual", channel, ignore_config=True, min_gap_s=min_gap_s) as transport:
        assert isinstance(transport, FrameLink)
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        handles = [Handle(i) for i in range(3)]
        for i, handle in enumerate(handles):
            transport.send(Frame(arbitration_id=0x141, data=bytes([i])), handle)
        transport.send(Frame(arbitration_id=0x141, data=b"\x09"))  # no handle: the frame is one
        await transport.drain()
    assert [h for h, _, _ in reports[:3]] == handles
    assert all(at is not None and why is None for _, at, why in reports)
    assert reports[3][0] == Frame(arbitration_id=0x141, data=b"\x09")
    assert len(test_can._recv_all(peer, 4)) == 4


async def test_can_drops_name_the_handle(flaky: type[test_can._FlakyBus]) -> None:
    flaky.failures = [test_can._enobufs()]
    reports: Reports = []
    async with CanTransport("flaky", "x", ignore_config=True, enobufs="drop") as transport:
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"), Handle(1))
        transport.send(Frame(arbitration_id=0x141, data=b"\x02"), Handle(2))
        await transport.drain()
    assert [(h.n, at is None, why) for h, at, why in reports] == [
        (1, True, "queue_full"),  # (counted enobufs_dropped)
        (2, False, None),
    ]


@pytest.fixture
def flaky(monkeypatch: pytest.MonkeyPatch) -> type[test_can._FlakyBus]:
    test_can._FlakyBus.sent = []
    test_can._FlakyBus.failures = []
    monkeypatch.setattr(can, "Bus", lambda **config: test_can._FlakyBus(**config))
    return test_can._FlakyBus


async def test_slcan_reports_name_the_handle() -> None:
    reports: Reports = []
    async with test_slcan.raw_open() as (transport, adapter):
        transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"), Handle(1))
        transport.send(Frame(arbitration_id=0x141, data=b"\x02"), Handle(2))
        await transport.drain()
        assert transport.rules == LineRules(bitrate=1_000_000, stale_after_s=0.5)
        await anyio.sleep(0.01)
        assert adapter.read_all() == b"t141101\rt141102\r"
    assert [(h.n, why) for h, _, why in reports] == [(1, None), (2, None)]


async def test_rs485_reports_name_the_handle_and_the_rules_are_its_settings() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    codec = ma.FAMILY.bind(1, link="rs485")
    reports: Reports = []
    try:
        transport = SerialTransport(
            os.ttyname(slave), framing=codec.framing, gap_s=0.001, turnaround_s=0.002, stale_after_s=0.3
        )
        assert transport.rules == LineRules(
            half_duplex=True, gap_s=0.001, turnaround_s=0.002, stale_after_s=0.3
        )
        async with transport:
            transport.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
            transport.send(codec.encode(ma.ReadStatus1()), Handle(1))
            transport.send(codec.encode(ma.ReadStatus1()), Handle(2), reply_timeout_s=0.01)
            await within(2.0, transport.drain())
    finally:
        os.close(master)
        os.close(slave)
    assert [(h.n, at is not None, why) for h, at, why in reports] == [(1, True, None), (2, True, None)]


def test_can_rules_come_from_its_bit_rate(channel: str) -> None:
    transport = CanTransport("virtual", channel, ignore_config=True, bitrate=500_000, stale_after_s=None)
    assert transport.rules == LineRules(bitrate=500_000, stale_after_s=None)

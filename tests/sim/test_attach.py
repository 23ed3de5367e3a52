"""The simulator behind real I/O: python-can's slcan over a pty, python-can's virtual bus, RS485 on a pty.

Stand-in devices (tests/sim/_standins.py) keep these about the attachments; the family device
models are exercised through the same attachments in tests/sim/devices. Every test runs on asyncio and
on trio (anyio's plugin): the attachments are anyio's task groups, waits and clock.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Coroutine
from typing import Any

import anyio
import can
import pytest
import serial

from servobus.core import crc16_modbus
from servobus.sim.attach import serve_python_can, serve_rs485, serve_slcan
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter

from ._standins import Responder, SerialResponder

pytestmark = pytest.mark.anyio


async def _awaited(coroutine: Coroutine[Any, Any, None]) -> None:
    await coroutine


@contextlib.asynccontextmanager
async def serving(coroutine: Coroutine[Any, Any, None]) -> AsyncIterator[None]:
    """Run an attachment in a task group for the length of the block, cancelled at its end."""
    async with anyio.create_task_group() as group:
        group.start_soon(_awaited, coroutine)
        yield
        group.cancel_scope.cancel()


def _exchange(bus: can.BusABC, requests: list[can.Message], expect: int) -> list[can.Message]:
    for message in requests:
        bus.send(message)
    replies = []
    while len(replies) < expect and (message := bus.recv(timeout=2.0)) is not None:
        replies.append(message)
    return replies


async def test_python_can_slcan_talks_to_thirty_two_simulated_devices_over_a_pty() -> None:
    network = SimCanNetwork([Responder(i) for i in range(1, 33)])
    port = PtyPort()
    adapter = SlcanAdapter(bitrate=None)
    async with serving(serve_slcan(network, port, adapter)):
        bus = can.Bus(interface="slcan", channel=port.path, bitrate=1_000_000, sleep_after_open=0)
        try:
            requests = [
                can.Message(arbitration_id=0x140 + i, data=[0x9C, i, 0, 0, 0, 0, 0, 0], is_extended_id=False)
                for i in range(1, 33)
            ]
            replies = await anyio.to_thread.run_sync(_exchange, bus, requests, 32)
        finally:
            bus.shutdown()
    port.close()
    assert sorted((m.arbitration_id, bytes(m.data)) for m in replies) == [
        (0x240 + i, bytes([0x9C, i, 0, 0, 0, 0, 0, 0])) for i in range(1, 33)
    ]
    assert adapter.bitrate == 1_000_000 and network.bus.bitrate == 1_000_000  # python-can's S8 reached it
    assert network.bus.frames == 64  # the 32 requests and the 32 replies


async def test_python_can_virtual_bus_carries_classic_and_fd_frames() -> None:
    network = SimCanNetwork([Responder(1)])
    channel = f"sim-{id(network)}"
    sim_side = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    host = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    async with serving(serve_python_can(network, sim_side)):
        requests = [
            can.Message(arbitration_id=0x141, data=[0x9C] + [0] * 7, is_extended_id=False),
            can.Message(arbitration_id=0x141, data=bytes(range(16)), is_fd=True, is_extended_id=False),
        ]
        replies = await anyio.to_thread.run_sync(_exchange, host, requests, 2)
    host.shutdown()
    sim_side.shutdown()
    assert [(m.arbitration_id, bytes(m.data), m.is_fd) for m in replies] == [
        (0x241, bytes([0x9C] + [0] * 7), False),
        (0x241, bytes(range(16)), True),
    ]


def _rs485_frame(motor_id: int) -> bytes:
    body = bytes([0x3E, motor_id, 0x08, 0x9C, motor_id, 0, 0, 0, 0, 0, 0])
    return body + crc16_modbus(body).to_bytes(2, "little")


def _transact(path: str, baud: int) -> tuple[list[bytes], float]:
    """Request/reply with 32 motors, one at a time (half-duplex); returns the replies and the time taken."""
    import time

    replies = []
    with serial.Serial(path, baud, timeout=2.0) as host:
        start = time.perf_counter()
        for motor_id in range(1, 33):
            host.write(_rs485_frame(motor_id))
            replies.append(host.read(13))
        return replies, time.perf_counter() - start


@pytest.mark.parametrize("baud", [115_200, 1_000_000])
async def test_rs485_request_reply_with_thirty_two_devices_over_a_pty(baud: int) -> None:
    port = PtyPort()
    async with serving(serve_rs485([SerialResponder(i) for i in range(1, 33)], port, baud=baud)):
        replies, elapsed = await anyio.to_thread.run_sync(_transact, port.path, baud)
    port.close()
    assert replies == [_rs485_frame(i) for i in range(1, 33)]
    # Each reply is paced by the line: 13 bytes x 10 bits at the baud rate, at least.
    assert elapsed >= 32 * 130 / baud


class _Broken(Responder):
    def receive(self, frame: can.Message, now_s: float) -> list:  # type: ignore[override]
        raise RuntimeError("device model bug")


async def test_a_device_model_error_ends_the_attachment_loudly() -> None:
    network = SimCanNetwork([_Broken(1)])
    channel = f"sim-{id(network)}"
    sim_side = can.Bus(interface="virtual", channel=channel)
    host = can.Bus(interface="virtual", channel=channel)
    host.send(can.Message(arbitration_id=0x141, data=[0x9C] + [0] * 7, is_extended_id=False))
    try:
        with pytest.raises(RuntimeError, match="device model bug"), anyio.fail_after(2.0):
            await serve_python_can(network, sim_side)
    finally:
        host.shutdown()
        sim_side.shutdown()


async def test_unplugging_the_pty_ends_the_attachment() -> None:
    port = PtyPort()
    with anyio.fail_after(2.0):
        async with anyio.create_task_group() as tg:
            tg.start_soon(serve_slcan, SimCanNetwork(), port)
            await anyio.sleep(0.01)
            port.unplug()  # the attachment returns normally

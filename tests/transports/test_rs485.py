"""SerialTransport on a real pty: the three framings, two baud rates, half-duplex, bad bytes.

The far end is the simulator's RS485 line (``serve_rs485``), which writes each reply when its
last byte would have arrived at the line's baud rate.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from _serving import serving
from servobus.core import crc16_modbus
from servobus.errors import TransportError
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.rs485 import (
    ModbusRead,
    ModbusReadReply,
    TransparentReply,
    TransparentRequest,
    decode_modbus_reply,
)
from servobus.protocols.myactuator.ids import RS485_BROADCAST_ID
from servobus.protocols.myactuator.rs485 import decode_rs485_reply, encode_rs485
from servobus.sim.attach import serve_rs485
from servobus.sim.device import SerialDevice, SerialEmission
from servobus.sim.devices.hollow import HollowMotor
from servobus.sim.devices.hollow_converter import ConverterMode, HollowConverter
from servobus.sim.devices.myactuator import MyActuatorMotor
from servobus.sim.devices.myactuator_rs485 import MyActuatorRs485Motor
from servobus.sim.pty import PtyPort
from servobus.timing import uart_time_s
from servobus.transports import SerialFrame, SerialTransport


@contextlib.asynccontextmanager
async def line(
    devices: Sequence[SerialDevice], *, baud: int, **options: object
) -> AsyncIterator[SerialTransport]:
    port = PtyPort()
    try:
        transport = SerialTransport(port.path, baud=baud, **options)  # type: ignore[arg-type]
        async with serving(serve_rs485(devices, port, baud=baud)), transport:
            yield transport
    finally:
        port.close()


@dataclass
class Scripted:
    """Writes ``script`` (delay after the first request, bytes) and records when requests came."""

    script: list[tuple[float, bytes]]
    turnaround_s: float = 0.0
    heard: list[float] = field(default_factory=list)
    name: str = "scripted"

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        self.heard.append(now_s)
        if len(self.heard) > 1:
            return [SerialEmission(now_s + self.turnaround_s, data)] if self.turnaround_s else []
        return [SerialEmission(now_s + delay, chunk) for delay, chunk in self.script]

    def poll(self, now_s: float) -> list[SerialEmission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


def test_modes_baud_rates_and_parity_are_checked() -> None:
    with pytest.raises(ValueError, match="mode='can'"):
        SerialTransport("/dev/null", mode="can")
    with pytest.raises(ValueError, match=r"baud=2000000 is not one of myactuator's rates"):
        SerialTransport("/dev/null", mode="myactuator", baud=2_000_000)
    with pytest.raises(ValueError, match="parity"):
        SerialTransport("/dev/null", mode="modbus-rtu", parity="X")
    modbus = SerialTransport("/dev/null", mode="modbus-rtu", parity="E")
    assert modbus.baud == 19_200 and modbus.bits_per_char == 11
    assert modbus.gap_s == pytest.approx(3.5 * 11 / 19_200)  # the Modbus RTU silence, 2.0 ms
    assert SerialTransport("/dev/null", mode="hollow-transparent").baud == 1_000_000


@pytest.mark.asyncio
@pytest.mark.parametrize("baud", [115_200, 1_000_000])
async def test_myactuator_motors_answer_at_two_baud_rates_and_the_line_time_shows(baud: int) -> None:
    motors = [MyActuatorRs485Motor(MyActuatorMotor(i)) for i in (1, 2, 3)]
    async with line(motors, baud=baud, mode="myactuator") as transport:
        started = time.monotonic()
        for motor_id in (1, 2, 3):
            transport.send(encode_rs485(motor_id, ma.ReadStatus1()), reply_timeout_s=0.1)
        replies = [await asyncio.wait_for(transport.receive(), 1.0) for _ in range(3)]
        elapsed = time.monotonic() - started
    decoded = [decode_rs485_reply(r.data) for r in replies]
    assert [(i, type(reply)) for i, reply in decoded] == [(i, ma.Status1Reply) for i in (1, 2, 3)]
    # Three half-duplex transactions of 13 + 13 bytes cannot take less than their line time.
    assert elapsed >= 3 * uart_time_s(26, baud)
    assert all(b.timestamp > a.timestamp for a, b in itertools.pairwise(replies))


@pytest.mark.asyncio
async def test_the_line_is_held_for_a_reply_then_released_by_the_reply_or_the_timeout() -> None:
    slow = Scripted(script=[(0.03, encode_rs485(1, ma.ReadStatus1()))], turnaround_s=0.03)
    async with line([slow], baud=1_000_000, mode="myactuator") as transport:
        transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=0.5)  # answered at 30 ms
        transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=0.5)  # answered 30 ms later
        await transport.drain()
        assert len(await transport.receive_batch()) in (1, 2)
        assert slow.heard[1] - slow.heard[0] >= 0.03  # the second waited for the first reply
        # No reply expected: frames follow each other with only the gap between them.
        before = len(slow.heard)
        for _ in range(3):
            transport.send(encode_rs485(RS485_BROADCAST_ID, ma.MotorStop()))
        await transport.drain()
        await asyncio.sleep(0.1)
        quick = slow.heard[before:]
        assert quick[-1] - quick[0] < 0.03
        # A reply that never comes holds the line for reply_timeout_s, no longer.
        silent = Scripted(script=[])
    async with line([silent], baud=1_000_000, mode="myactuator") as transport:
        transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=0.05)
        transport.send(encode_rs485(1, ma.ReadStatus1()))
        await transport.drain()
        await asyncio.sleep(0.02)
    assert 0.05 <= silent.heard[1] - silent.heard[0] < 0.5


@pytest.mark.asyncio
async def test_garbage_and_corrupt_frames_are_counted_and_the_good_frame_still_comes() -> None:
    good = encode_rs485(1, ma.ReadStatus1())
    corrupt = good[:-1] + bytes([good[-1] ^ 0xFF])
    noisy = Scripted(script=[(0.0, corrupt + b"\x00\x11\x22" + good)])
    async with line([noisy], baud=1_000_000, mode="myactuator") as transport:
        transport.send(good, reply_timeout_s=0.2)
        frame = await asyncio.wait_for(transport.receive(), 1.0)
        await asyncio.sleep(0.01)
        stats = transport.stats()
    assert frame == SerialFrame(good)
    assert (stats.crc_errors, stats.discarded_bytes) == (1, len(corrupt) + 3)
    assert stats.frames_in == 1


@pytest.mark.asyncio
async def test_hollow_transparent_mode_through_the_converter_at_1_mbaud() -> None:
    converter = HollowConverter([HollowMotor(i, fd_enabled=True) for i in (1, 2)])
    async with line([converter], baud=1_000_000, mode="hollow-transparent") as transport:
        for motor_id in (1, 2):
            transport.send(TransparentRequest(motor_id=motor_id).encode(), reply_timeout_s=0.1)
        replies = [
            TransparentReply.decode((await asyncio.wait_for(transport.receive(), 1.0)).data) for _ in range(2)
        ]
    assert [r.motor_id for r in replies] == [1, 2]


@pytest.mark.asyncio
async def test_modbus_rtu_at_19200_and_a_truncated_frame_is_dropped_on_the_silence() -> None:
    converter = HollowConverter([HollowMotor(5, fd_enabled=True)], mode=ConverterMode.MODBUS)
    async with line([converter], baud=19_200, mode="modbus-rtu") as transport:
        transport.send(ModbusRead(slave_id=5).encode(), reply_timeout_s=0.2)
        reply = decode_modbus_reply((await asyncio.wait_for(transport.receive(), 1.0)).data)
    assert isinstance(reply, ModbusReadReply) and reply.slave_id == 5

    whole = ModbusRead(slave_id=5).encode()  # the 8-byte form the de-framer also knows as a reply
    body = bytes([5, 0x03, 0x20]) + bytes(32)
    read_reply = body + crc16_modbus(body).to_bytes(2, "little")
    cut = Scripted(script=[(0.0, read_reply[:10]), (0.05, read_reply)])
    async with line([cut], baud=19_200, mode="modbus-rtu") as transport:
        transport.send(whole, reply_timeout_s=0.5)
        frame = await asyncio.wait_for(transport.receive(), 1.0)
        stats = transport.stats()
    assert frame.data == read_reply
    # Dropped as noise when the line went quiet, not counted as a frame that failed its CRC (which
    # is what the de-framer says if the cut frame's bytes run into the next one without a silence).
    assert (stats.discarded_bytes, stats.crc_errors, stats.frames_in) == (10, 0, 1)


@pytest.mark.asyncio
async def test_a_frame_split_by_a_usb_style_burst_gap_is_still_whole() -> None:
    # A USB adapter can deliver the second half of a frame milliseconds after the first: far longer
    # than 3.5 characters at 1 Mbaud (35 us), so the host must not take that gap for the line's
    # inter-frame silence.
    reply = encode_rs485(1, ma.ReadStatus1())
    bursty = Scripted(script=[(0.0, reply[:5]), (0.008, reply[5:])])
    async with line([bursty], baud=1_000_000, mode="myactuator") as transport:
        transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=0.2)
        frame = await asyncio.wait_for(transport.receive(), 1.0)
        stats = transport.stats()
    assert frame.data == reply and stats.discarded_bytes == 0


@pytest.mark.asyncio
async def test_a_loss_while_waiting_for_a_reply_leaves_the_line_usable_after_the_reopen(
    tmp_path: Path,
) -> None:
    link = tmp_path / "tty485"
    first, second = PtyPort(link=link), None
    transport = SerialTransport(str(link), mode="myactuator", reopen_backoff_s=(0.01, 0.05))
    try:
        async with serving(serve_rs485([Scripted(script=[])], first, baud=1_000_000)), transport:
            transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=5.0)  # never answered
            await asyncio.sleep(0.05)
            first.unplug()  # while the writer waits for that reply
            with pytest.raises(TransportError):
                await asyncio.wait_for(transport.receive(), 1.0)
            second = PtyPort(link=link)
            async with serving(
                serve_rs485([MyActuatorRs485Motor(MyActuatorMotor(1))], second, baud=1_000_000)
            ):
                await transport.wait_open(timeout=5.0)
                transport.send(encode_rs485(RS485_BROADCAST_ID, ma.MotorStop()))  # no reply expected
                transport.send(encode_rs485(1, ma.ReadStatus1()), reply_timeout_s=0.2)
                reply = await asyncio.wait_for(transport.receive(), 1.0)
    finally:
        for port in (first, second):
            if port is not None:
                port.close()
    assert decode_rs485_reply(reply.data)[0] == 1

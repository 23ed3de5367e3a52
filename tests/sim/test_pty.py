"""The simulator's pseudo-terminal (servobus.sim.pty): binary-clean real serial I/O, unplug, replug."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
import serial

from servobus.sim.pty import PtyPort

ALL_BYTES = bytes(range(256)) * 4  # CR, LF, XON/XOFF, 0x00 and 0xFF must all pass untouched


async def _read_exactly(port: PtyPort, n: int) -> bytes:
    data = bytearray()
    while len(data) < n:
        data += await asyncio.wait_for(port.read(), 2.0)
    return bytes(data)


@pytest.mark.asyncio
async def test_bytes_cross_both_ways_untouched_through_pyserial() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=2.0)
    try:
        host.write(ALL_BYTES)
        assert await _read_exactly(port, len(ALL_BYTES)) == ALL_BYTES
        port.write(ALL_BYTES)
        assert await asyncio.to_thread(host.read, len(ALL_BYTES)) == ALL_BYTES
        assert (port.bytes_in, port.bytes_out) == (1024, 1024)
    finally:
        host.close()
        port.close()


@pytest.mark.asyncio
async def test_large_writes_wait_for_the_host_to_drain() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=2.0)
    try:
        big = bytes(range(256)) * 1024  # 256 KiB: far beyond the pty's buffer
        port.write(big)
        received = await asyncio.to_thread(host.read, len(big))
        assert received == big
    finally:
        host.close()
        port.close()


@pytest.mark.asyncio
async def test_unplug_fails_the_host_and_ends_pending_reads() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=0.5)
    reader = asyncio.create_task(port.read())
    await asyncio.sleep(0)
    port.unplug()
    assert await asyncio.wait_for(reader, 1.0) == b""
    with pytest.raises(serial.SerialException):
        host.read(1)
    host.close()
    with pytest.raises(ConnectionError, match="is closed"):
        port.write(b"x")


@pytest.mark.asyncio
async def test_the_link_follows_replug(tmp_path: Path) -> None:
    link = tmp_path / "ttySIM0"
    first = PtyPort(link)
    assert link.resolve() == Path(first.path).resolve()
    first.unplug()
    assert not link.exists()  # unplugged: the name is gone, as /dev/ttyUSB0 would be
    second = PtyPort(link)
    try:
        host = serial.Serial(str(link), 1_000_000, timeout=2.0)
        host.write(b"back")
        assert await _read_exactly(second, 4) == b"back"
        host.close()
    finally:
        second.close()

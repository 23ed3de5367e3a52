"""The simulator's pseudo-terminal (servobus.sim.pty): binary-clean real serial I/O, unplug, replug; on
asyncio and on trio."""

from __future__ import annotations

from pathlib import Path

import anyio
import pytest
import serial

from servobus.sim.pty import PtyPort

pytestmark = pytest.mark.anyio

ALL_BYTES = bytes(range(256)) * 4  # CR, LF, XON/XOFF, 0x00 and 0xFF must all pass untouched


async def _read_exactly(port: PtyPort, n: int) -> bytes:
    data = bytearray()
    while len(data) < n:
        with anyio.fail_after(2.0):
            data += await port.read()
    return bytes(data)


async def test_bytes_cross_both_ways_untouched_through_pyserial() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=2.0)
    try:
        host.write(ALL_BYTES)
        assert await _read_exactly(port, len(ALL_BYTES)) == ALL_BYTES
        port.write(ALL_BYTES)
        assert await anyio.to_thread.run_sync(host.read, len(ALL_BYTES)) == ALL_BYTES
        assert (port.bytes_in, port.bytes_out) == (1024, 1024)
    finally:
        host.close()
        port.close()


async def test_large_writes_wait_for_the_host_to_drain() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=2.0)
    try:
        big = bytes(range(256)) * 1024  # 256 KiB: far beyond the pty's buffer
        port.write(big)  # never blocks: the rest goes as the host reads
        async with anyio.create_task_group() as tg:
            tg.start_soon(port.drain)
            received = await anyio.to_thread.run_sync(host.read, len(big))
        assert received == big and port.bytes_out == len(big)
    finally:
        host.close()
        port.close()


async def test_unplug_fails_the_host_and_ends_pending_reads() -> None:
    port = PtyPort()
    host = serial.Serial(port.path, 1_000_000, timeout=0.5)
    got: list[bytes] = []

    async def read() -> None:
        got.append(await port.read())

    with anyio.fail_after(1.0):
        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            await anyio.sleep(0.01)  # (the read waits)
            port.unplug()
    assert got == [b""]
    with pytest.raises(serial.SerialException):
        host.read(1)
    host.close()
    with pytest.raises(ConnectionError, match="is closed"):
        port.write(b"x")


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

"""A pseudo-terminal the simulator holds, that a host opens as if it were a USB serial port.

Real serial I/O through the kernel, without hardware (design.md, "Environment facts"): the
simulator owns the master side; ``path`` (or the stable ``link`` beside it) is what pyserial,
pyserial-asyncio-fast or python-can's ``slcan`` interface open. :meth:`PtyPort.unplug` closes the
master, so the host's next read fails the way an unplugged USB adapter's does (EIO); a new
:class:`PtyPort` created with the same ``link`` re-points the link, so the device "returns" at
the path the host knows.

The slave is put in raw mode (no echo, no CR/LF translation, no XON/XOFF), since every protocol
here is binary or CR-terminated ASCII. The baud rate of a pty means nothing; the simulator paces
its writes itself with ``timing.uart_time_s``.

Reads wait through ``anyio.wait_readable``, on asyncio and on trio. :meth:`PtyPort.write` never
blocks: what the pty cannot take at once (a host that stopped reading) is written when it drains, by
a writer callback on asyncio's loop; on trio, which has no such callbacks, by the next ``write``,
``read`` or :meth:`PtyPort.drain`.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
import tty
from collections.abc import AsyncIterator
from pathlib import Path

import anyio

__all__ = ["PtyPort"]

_READ_SIZE = 4096


def _running_loop() -> asyncio.AbstractEventLoop | None:
    """The running asyncio loop, or None (trio, or no loop): only when a write found the pty full."""
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


class PtyPort:
    """The simulator's end of one pseudo-terminal.

    Args:
        link: optional path of a symlink to create (or re-point) at the slave device, a stable
            name for hosts to reopen across unplug/replug.

    Attributes:
        path: the slave device (``/dev/pts/N``).
        bytes_in, bytes_out: traffic counters.
    """

    def __init__(self, link: str | os.PathLike[str] | None = None) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self.link = Path(link) if link is not None else None
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            tmp.symlink_to(self.path)
            tmp.replace(self.link)  # atomic: a host never sees the link missing
        self.bytes_in = 0
        self.bytes_out = 0
        self._pending = bytearray()
        self._writer_armed = False
        self._reading = False
        self._closed = False

    @property
    def name(self) -> str:
        """What a host should open: the stable link if there is one, else the slave device."""
        return str(self.link) if self.link is not None else self.path

    @property
    def closed(self) -> bool:
        return self._closed

    def write(self, data: bytes) -> None:
        """Queue ``data`` for the host; what the pty cannot take now is sent when it drains.

        Raises:
            ConnectionError: the port has been unplugged or closed.
        """
        if self._closed:
            raise ConnectionError(f"{self.name} is closed")
        self._pending += data
        self._drain()

    def _drain(self) -> None:
        while self._pending and not self._closed:
            try:
                sent = os.write(self._master, self._pending)
            except BlockingIOError:
                sent = 0
            except OSError as exc:
                if exc.errno != errno.EIO:  # EIO: no host has the slave open; keep the bytes
                    raise
                sent = 0
            if sent == 0:
                loop = _running_loop()  # (None: trio, or no loop; see the module's docstring)
                if not self._writer_armed and loop is not None:
                    loop.add_writer(self._master, self._on_writable)
                    self._writer_armed = True
                return
            self.bytes_out += sent
            del self._pending[:sent]

    def _on_writable(self) -> None:
        asyncio.get_running_loop().remove_writer(self._master)
        self._writer_armed = False
        self._drain()

    async def drain(self) -> None:
        """Wait until every byte :meth:`write` queued was taken by the pty (a host reading)."""
        while self._pending and not self._closed:
            self._disarm()  # (one watcher per fd: the wait below takes the writer's place)
            await anyio.wait_writable(self._master)
            self._drain()

    def _disarm(self) -> None:
        if self._writer_armed and (loop := _running_loop()) is not None:
            loop.remove_writer(self._master)
            self._writer_armed = False

    async def read(self) -> bytes:
        """The next bytes the host wrote (waits for them); b"" once the port is closed."""
        while not self._closed:
            self._drain()  # (bytes a full pty held back, where no writer callback is armed)
            try:
                data = os.read(self._master, _READ_SIZE)
            except BlockingIOError:
                data = b""
            if data:
                self.bytes_in += len(data)
                return data
            self._reading = True
            try:
                await anyio.wait_readable(self._master)
            except anyio.ClosedResourceError:
                pass  # close() while waiting: b""
            finally:
                self._reading = False
        return b""

    async def __aiter__(self) -> AsyncIterator[bytes]:
        while data := await self.read():
            yield data

    def unplug(self) -> None:
        """Close the master: the host's reads and writes fail as on a vanished USB device."""
        self.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._disarm()
        if self._reading:
            anyio.notify_closing(self._master)  # a pending read() returns b""
        os.close(self._master)
        os.close(self._slave)
        if self.link is not None and self.link.is_symlink() and os.readlink(self.link) == self.path:
            self.link.unlink()

    def __del__(self) -> None:  # the fds are the kernel's: never leak them with the object
        if not getattr(self, "_closed", True):
            self._closed = True
            os.close(self._master)
            os.close(self._slave)

"""What the serial transports (RS485 lines, the native SLCAN adapter) share: one open port, read and
written through its file descriptor on the running loop, asyncio or trio (private).

pyserial opens and configures the port (baud rate, parity, the exclusive lock; any pyserial URL with a
file descriptor); from then on the port is a non-blocking descriptor:

* **Reading**: a :class:`~servobus.transports._watch.ReadWatch` (asyncio's reader callback, a task on
  trio) reads up to ``read_size`` bytes per wake-up and hands them to the owner. EOF or an OS error is
  a lost port, reported once.
* **Writing**: ``os.write`` (never blocks; EAGAIN raises ``BlockingIOError``), ``wait_writable`` when
  the kernel is full, ``TIOCOUTQ`` for what the OS still holds and ``tcflush`` to discard it.

Why not pyserial-asyncio-fast any more: it is asyncio only, and the transports already wrote to the
descriptor themselves (its write path spins on a slow port: see rs485's docstring). Its read side was
the loop's reader callback calling ``Serial.read``; :class:`ReadWatch`'s asyncio lane is that same
callback around ``os.read``, so asyncio keeps its speed (bench: ``transport`` part) and trio gets a path.

pyserial is imported when a port opens, so CAN-only users never load it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import struct
import termios
from collections.abc import Callable
from typing import Any

import anyio

from servobus.errors import TransportError
from servobus.runtime import Runtime
from servobus.transports._owned import LinkTasks
from servobus.transports._watch import ReadWatch

__all__ = ["SerialPort"]

READ_SIZE = 16384  # bytes taken from the port per wake-up, at most
_TIOCOUTQ_ARG = bytes(4)


class SerialPort:
    """One open port: what it reads goes to ``on_bytes(data)`` from :meth:`open` until :meth:`close`,
    and its failure (EOF, an OS error) to ``lose(cause)``, once.

    Attributes:
        serial: the pyserial object (for the port's settings; never read or written through it).
        fd: the port's non-blocking descriptor.
        failed: the port failed (reported to the owner once) or was closed: write no more.
    """

    def __init__(
        self,
        name: str,
        on_bytes: Callable[[bytes], object],
        lose: Callable[[BaseException], object],
        serial: Any,
        fd: int,
        read_size: int,
        runtime: Runtime,
        tasks: LinkTasks,
    ) -> None:
        self.serial = serial
        self.fd = fd
        self.failed = False
        self._on_bytes = on_bytes
        self._lose = lose
        self._read_size = read_size
        self._watch: ReadWatch | None = ReadWatch(runtime, tasks, fd, self._on_readable, name)
        self._watch.start()

    @classmethod
    def open(
        cls,
        name: str,
        on_bytes: Callable[[bytes], object],
        lose: Callable[[BaseException], object],
        port: str,
        runtime: Runtime,
        tasks: LinkTasks,
        *,
        read_size: int = READ_SIZE,
        **serial_options: Any,
    ) -> SerialPort:
        """Open ``port`` with pyserial and start reading it (``name``: the owner's, for errors).

        Raises:
            TransportError: the port cannot be opened or has no file descriptor (chained to the cause).
        """
        import serial

        try:
            device = serial.serial_for_url(port, timeout=0, write_timeout=0, **serial_options)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f"{name}: cannot open: {exc}") from exc
        try:
            fd = device.fileno()
            os.set_blocking(fd, False)
        except (AttributeError, OSError, ValueError, TypeError, NotImplementedError) as exc:
            device.close()
            raise TransportError(f"{name}: {port!r} has no file descriptor to read") from exc
        return cls(name, on_bytes, lose, device, fd, read_size, runtime, tasks)

    def _on_readable(self) -> None:
        try:
            data = os.read(self.fd, self._read_size)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:  # EIO: unplugged, or the pty's far end closed
            self._fail(exc)
            return
        if not data:
            self._fail(ConnectionError("the port closed (end of file)"))
            return
        self._on_bytes(data)

    def _fail(self, cause: BaseException) -> None:
        if self._watch is not None:
            self._watch.cancel()  # a vanished port stays readable: stop watching it
        self.failed = True
        self._lose(cause)

    # ----------------------------------------------------------------- writing

    def write(self, data: bytes | memoryview) -> int:
        """Hand bytes to the kernel without blocking: how many it took.

        Raises:
            BlockingIOError: it takes nothing now (wait with :meth:`wait_writable`).
            OSError: the port failed.
        """
        return os.write(self.fd, data)

    async def wait_writable(self, timeout_s: float | None = None) -> bool:
        """Until the kernel takes bytes again: True, or False when ``timeout_s`` passed first."""
        with anyio.move_on_after(timeout_s):
            await anyio.wait_writable(self.fd)
            return True
        return False

    def out_waiting(self) -> int:
        """Bytes the OS still holds for the port (0 where the driver cannot tell, as on a pty).

        Raises:
            OSError: the port failed.
        """
        try:
            return int(struct.unpack("I", fcntl.ioctl(self.fd, termios.TIOCOUTQ, _TIOCOUTQ_ARG))[0])
        except OSError as exc:
            if exc.errno in (errno.ENOTTY, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
                return 0
            raise

    def flush_output(self) -> bool:
        """Discard what the OS holds for the port and has not sent (``tcflush``): True if it could."""
        try:
            termios.tcflush(self.fd, termios.TCOFLUSH)
        except OSError:
            return False
        return True

    # ----------------------------------------------------------------- closing

    async def close(self) -> None:
        """Stop reading (waiting until the reader is done with the descriptor), then close the port."""
        self.failed = True  # no longer usable: a writer that still holds it stops
        if self._watch is not None:
            await self._watch.stop()
            self._watch = None
        with contextlib.suppress(Exception):  # a vanished port cannot be closed cleanly
            self.serial.close()

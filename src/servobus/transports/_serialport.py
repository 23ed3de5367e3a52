"""What the serial transports (RS485 lines, the native SLCAN adapter) share: opening a port through
pyserial-asyncio-fast, its callbacks, and letting go of it (private).

pyserial-asyncio-fast is imported when a port opens, so CAN-only users never load it. Its reading side
is used as it is (one reader on the loop, 16 KiB per wake-up instead of its 1 KiB); both transports
write to the port's file descriptor themselves (see their module docstrings for why).
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any, Protocol

from servobus.errors import TransportError

__all__ = ["LineProtocol", "Owner", "close_port", "open_port"]

READ_SIZE = 16384  # bytes taken from the port per wake-up, at most


class Owner(Protocol):
    """The transport a port's callbacks go to (tagged with its connection's generation)."""

    name: str

    def _on_bytes(self, data: bytes, generation: int) -> None: ...

    def _lose(self, cause: BaseException, generation: int | None = None) -> None: ...


class LineProtocol(asyncio.Protocol):
    """pyserial-asyncio-fast's callbacks, forwarded to the transport of one connection."""

    def __init__(self, owner: Owner, generation: int) -> None:
        self._owner = owner
        self._generation = generation
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self._owner._on_bytes(data, self._generation)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed.done():
            self.closed.set_result(None)
        if exc is None:
            exc = ConnectionError("the port closed")
        self._owner._lose(exc, self._generation)


async def open_port(
    owner: Owner, generation: int, port: str, *, read_size: int = READ_SIZE, **serial_options: Any
) -> tuple[asyncio.Transport, LineProtocol]:
    """Open ``port`` with pyserial-asyncio-fast, its reads (``read_size`` bytes at most per wake-up)
    going to ``owner``.

    Raises:
        TransportError: the port cannot be opened (chained to the cause).
    """
    import serial
    import serial_asyncio_fast

    loop = asyncio.get_running_loop()
    protocol = LineProtocol(owner, generation)
    try:
        line, _ = await serial_asyncio_fast.create_serial_connection(
            loop, lambda: protocol, port, **serial_options
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        raise TransportError(f"{owner.name}: cannot open: {exc}") from exc
    # pyserial-asyncio-fast reads at most 1 KiB per wake-up (its own TODO says so); a larger read
    # takes a burst in one call, which is what the de-framers are built for.
    if hasattr(line, "_max_read_size"):
        line._max_read_size = read_size
    return line, protocol


async def close_port(line: asyncio.Transport | None, protocol: LineProtocol | None) -> None:
    """Abort ``line`` and wait (1 s at most) until its connection_lost has run."""
    if line is None or protocol is None:
        return
    if not line.is_closing():  # a failed line is already closing (closing twice breaks it)
        line.abort()
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(asyncio.shield(protocol.closed), 1.0)

"""Writing one frame at a time to a serial port, only while it is fresh (private: rs485's writer).

See :mod:`servobus.transports.rs485` ("Backpressure and freshness") for the rules it keeps.
"""

from __future__ import annotations

from collections.abc import Callable

import anyio

from servobus.transports._serialport import SerialPort

__all__ = ["FreshWriter"]

_POLL_MIN_S = 0.001  # the OS output buffer is polled no faster than this: never a spin
_POLL_MAX_S = 0.05


class FreshWriter:
    """Hands a frame's bytes to a port whole, only while the frame is fresh.

    The OS output buffer holds at most ``high_water_bytes`` when a frame is written (polled, at most
    every millisecond); EAGAIN waits for the descriptor to become writable; a frame cut by its deadline
    is flushed from the OS buffer, and bytes the OS holds without taking more for longer than
    ``stale_after_s`` are flushed too.

    Args:
        clock: the loop's clock (the transport's ``_now``).
    """

    def __init__(
        self,
        *,
        high_water_bytes: int,
        char_time_s: float,
        stale_after_s: float | None,
        clock: Callable[[], float],
    ) -> None:
        self.high_water_bytes = high_water_bytes
        self._char_time_s = char_time_s
        self._stale_after_s = stale_after_s
        self._clock = clock
        #: loop time the port last took bytes from us
        self.written_at = 0.0
        self._blocked = False  # the port's last write took nothing (or part): wait before the next

    def reset(self) -> None:
        """A new connection: its port has taken nothing yet, so nothing it holds is old."""
        self.written_at = self._clock()
        self._blocked = False

    async def write(self, port: SerialPort, data: bytes, deadline: float | None) -> float | None:
        """Hand ``data`` to ``port`` whole, when it can take it.

        Returns:
            The loop time its last bytes were handed over, or None: ``deadline`` came first (the
            frame went stale) and nothing of it is left in front of the next frame.

        Raises:
            OSError: the port failed (not EAGAIN).
        """
        while (queued := port.out_waiting()) > self.high_water_bytes:
            if not await self._pause(port, deadline, (queued - self.high_water_bytes) * self._char_time_s):
                return None
        clock = self._clock
        view = memoryview(data)
        done = 0
        while True:
            now = clock()
            if deadline is not None and now > deadline:  # went stale while we waited
                if done:  # a cut frame must not sit in front of the next one
                    port.flush_output()
                return None
            if self._blocked:
                # The port took nothing last time: wait for room (event-driven) before writing again;
                # a write into a full tty costs about as much as the wait (0.25 ms on a pty).
                timeout = None if deadline is None else max(deadline - now, 0.0)
                if not await port.wait_writable(timeout):
                    if done:
                        port.flush_output()
                    return None  # stale before the port had room
                self._blocked = False
            try:
                done += port.write(view[done:])
            except BlockingIOError:
                self._blocked = True
                continue
            except InterruptedError:
                continue
            if done:
                self.written_at = now
            if done == len(data):
                return now
            self._blocked = True  # the kernel took part of it: it is full

    async def _pause(self, port: SerialPort, deadline: float | None, drain_s: float) -> bool:
        """Sleep while the port drains (at least 1 ms: never a spin); False once ``deadline`` passed."""
        now = self._clock()
        self._flush_if_stalled(port, now)
        if deadline is not None and now >= deadline:
            return False
        wait = min(max(drain_s, _POLL_MIN_S), _POLL_MAX_S)
        await anyio.sleep(wait if deadline is None else min(wait, deadline - now))
        return True

    def _flush_if_stalled(self, port: SerialPort, now: float) -> None:
        """The OS holds bytes for the port (above the high-water mark) and has taken nothing from us
        for longer than ``stale_after_s``: what it holds was written before that, so it is stale."""
        limit = self._stale_after_s
        if limit is None or now - self.written_at <= limit:
            return
        port.flush_output()
        self.written_at = now  # once per stall period, not on every poll

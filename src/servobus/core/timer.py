"""A CLOCK_MONOTONIC timer an event loop can wait on (Linux timerfd, through the C core: csrc/timer.c).

Python 3.11 has no ``os.timerfd_create``. :class:`MonotonicTimer` owns one timerfd: armed at an
absolute deadline in ns (:func:`now_ns` reads the same clock; so does ``time.monotonic_ns()`` on
Linux), its descriptor reads as ready once the deadline has passed, until :meth:`~MonotonicTimer.clear`.
Nothing here waits: the pacer (servobus.ticks) hands :meth:`~MonotonicTimer.fileno` to the event
loop, which sleeps in its own poll until the kernel's timer fires (a hrtimer: no poll timeout rounding
to milliseconds, no timer slack).

Where the platform has no timerfd (not Linux), :func:`available` is False and opening one raises
:class:`TimerUnsupported`; the pacer then falls back to yielding until its deadlines.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from types import TracebackType
from typing import Any

from servobus.core._lib import ffi, lib, raise_status

__all__ = ["MonotonicTimer", "TimerUnsupported", "available", "now_ns"]

# A core compiled before csrc/timer.c has no timer: the pacer then spins, as where there is no timerfd,
# rather than the whole package failing to import (rebuild it: `pip install -e .` in a checkout).
_BUILT_WITH_TIMER = hasattr(lib, "sb_timer_open")
_STALE = "the compiled core predates csrc/timer.c: rebuild it (`pip install -e .` in a checkout)"
_E_OS: int = lib.SB_E_OS if _BUILT_WITH_TIMER else -5
_E_UNSUPPORTED: int = lib.SB_E_UNSUPPORTED if _BUILT_WITH_TIMER else -6


class TimerUnsupported(OSError):
    """This platform has no timer the event loop can wait on (the C core was built without timerfd)."""


def _check(status: int, err: Any, what: str) -> None:
    # The timer's statuses besides the core's common ones (servobus.core._lib maps those).
    if status >= 0:
        return
    if status == _E_OS:
        code = int(err[0])
        raise OSError(code, f"{what}: {os.strerror(code)}")
    if status == _E_UNSUPPORTED:
        raise TimerUnsupported(f"{what}: no timerfd on this platform")
    raise_status(status, what)


def available() -> bool:
    """True when this platform has the timer (the C core was built for Linux, with csrc/timer.c)."""
    return _BUILT_WITH_TIMER and bool(lib.sb_timer_now_ns() != _E_UNSUPPORTED)


def now_ns() -> int:
    """CLOCK_MONOTONIC now, in ns: the clock :meth:`MonotonicTimer.arm` takes.

    Raises:
        TimerUnsupported: no timer on this platform.
    """
    if not _BUILT_WITH_TIMER:  # pragma: no cover - a stale build
        raise TimerUnsupported(_STALE)
    now: int = lib.sb_timer_now_ns()
    _check(now, None, "now_ns")
    return now


class MonotonicTimer:
    """One timerfd, owned: closed by :meth:`close`, by leaving its ``with`` block, or when collected.

    Single-threaded like the event loop that waits on it. Methods called after :meth:`close` raise
    ValueError (as a closed file's do).

    Raises:
        TimerUnsupported: no timer on this platform.
        OSError: the system refused one (out of descriptors).
    """

    __slots__ = ("_err", "_fd", "before_close")

    def __init__(self) -> None:
        self._fd = -1  # (set before anything can fail: __del__ reads it)
        #: called just before the descriptor is closed, however it is (an event loop's registration
        #: must go first: closed by the collector, its number may soon name another descriptor, and
        #: a selector still holding the stale key would never poll that one)
        self.before_close: Callable[[], object] | None = None
        if not _BUILT_WITH_TIMER:  # pragma: no cover - a stale build
            raise TimerUnsupported(_STALE)
        self._err = ffi.new("int *")
        fd: int = lib.sb_timer_open(self._err)
        _check(fd, self._err, "timerfd_create")
        self._fd = fd

    def _live_fd(self) -> int:
        if self._fd < 0:
            raise ValueError("I/O operation on a closed MonotonicTimer")
        return self._fd

    def fileno(self) -> int:
        """The descriptor, for the event loop to wait on (readable once the deadline has passed)."""
        return self._live_fd()

    @property
    def closed(self) -> bool:
        return self._fd < 0

    def arm(self, deadline_ns: int) -> None:
        """Expire at ``deadline_ns`` (absolute, CLOCK_MONOTONIC), replacing any earlier deadline.

        A deadline already passed expires at once. An expiry not yet cleared is dropped.

        Raises:
            ValueError: a negative deadline, beyond 64 bits, or the timer is closed.
            OSError: the system refused it.
        """
        fd = self._live_fd()
        try:
            status: int = lib.sb_timer_arm(fd, deadline_ns, self._err)
        except OverflowError:
            raise ValueError(f"deadline_ns={deadline_ns} does not fit in 64 bits") from None
        if status == lib.SB_E_ARG:
            raise ValueError(f"deadline_ns={deadline_ns} must be >= 0")
        _check(status, self._err, "timerfd_settime")

    def disarm(self) -> None:
        """Stop the pending deadline, if any, and drop an expiry not yet cleared."""
        _check(lib.sb_timer_disarm(self._live_fd(), self._err), self._err, "timerfd_settime")

    def clear(self) -> int:
        """Take the expiry: how many deadlines expired since the last clear; 0 (at once) when none did."""
        count: int = lib.sb_timer_clear(self._live_fd(), self._err)
        _check(count, self._err, "read(timerfd)")
        return count

    def close(self) -> None:
        """Close the descriptor (again: nothing). Wake any waiter first (``anyio.notify_closing``)."""
        if self._fd < 0:
            return
        before, self.before_close = self.before_close, None
        try:
            if before is not None:
                before()
        finally:
            fd, self._fd = self._fd, -1
            os.close(fd)

    def __enter__(self) -> MonotonicTimer:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __del__(self) -> None:
        # A pacer abandoned mid-iteration without aclose(): the descriptor must not leak.
        if self._fd >= 0:
            self.close()

    def __repr__(self) -> str:
        return f"<MonotonicTimer fd={self._fd}>" if self._fd >= 0 else "<MonotonicTimer closed>"

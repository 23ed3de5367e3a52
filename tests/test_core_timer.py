"""servobus.core.timer and csrc/timer.c: a CLOCK_MONOTONIC timerfd armed at absolute deadlines.

Through the wrapper (what the pacer uses) and through ``lib`` directly (every bad argument answers with
a status, never undefined behaviour). Linux only: elsewhere the core reports the timer unsupported,
which the last test checks on the platforms that lack it.
"""

from __future__ import annotations

import errno
import gc
import os
import select
import sys
import time

import pytest

from servobus.core import timer
from servobus.core._lib import ffi, lib

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="timerfd is Linux's")


def _readable(t: timer.MonotonicTimer, wait_s: float = 0.0) -> bool:
    ready, _, _ = select.select([t.fileno()], [], [], wait_s)
    return bool(ready)


@linux
def test_the_timer_reads_the_clock_python_reads() -> None:
    assert timer.available()
    before = time.monotonic_ns()
    now = timer.now_ns()
    after = time.monotonic_ns()
    assert before <= now <= after


@linux
def test_a_deadline_in_the_past_fires_at_once() -> None:
    with timer.MonotonicTimer() as t:
        assert not _readable(t) and t.clear() == 0  # disarmed when new; clearing never blocks
        t.arm(timer.now_ns() - 5_000_000)
        assert _readable(t)
        assert t.clear() == 1
        assert not _readable(t) and t.clear() == 0  # taken: no longer readable
        t.arm(0)  # the earliest deadline there is (a zero itimerspec would disarm instead)
        assert _readable(t) and t.clear() == 1


@linux
def test_a_deadline_ahead_fires_at_it_not_before() -> None:
    with timer.MonotonicTimer() as t:
        deadline = timer.now_ns() + 20_000_000
        t.arm(deadline)
        assert not _readable(t)
        assert _readable(t, 2.0)
        woke = time.monotonic_ns()
        assert woke >= deadline
        assert t.clear() == 1


@linux
def test_re_arming_replaces_the_deadline_and_drops_an_expiry_not_taken() -> None:
    with timer.MonotonicTimer() as t:
        t.arm(timer.now_ns() + 10_000_000_000)
        t.arm(timer.now_ns() - 1)  # the far deadline is gone: this one fires now
        assert _readable(t) and t.clear() == 1
        t.arm(timer.now_ns() - 1)
        t.arm(timer.now_ns() + 10_000_000_000)  # re-armed before it was taken: the expiry is dropped
        assert not _readable(t) and t.clear() == 0
        t.disarm()
        time.sleep(0.001)
        assert not _readable(t)
        t.arm(timer.now_ns() - 1)
        t.disarm()  # disarming drops a pending expiry too
        assert not _readable(t) and t.clear() == 0


@linux
def test_close_releases_the_descriptor_and_the_timer_refuses_use_after() -> None:
    t = timer.MonotonicTimer()
    fd = t.fileno()
    assert os.readlink(f"/proc/self/fd/{fd}") == "anon_inode:[timerfd]"
    assert os.get_inheritable(fd) is False  # close-on-exec
    assert os.get_blocking(fd) is False
    t.close()
    assert t.closed and "closed" in repr(t)
    with pytest.raises(OSError):
        os.fstat(fd)
    t.close()  # again: nothing
    for call in (t.fileno, t.clear, t.disarm, lambda: t.arm(1)):
        with pytest.raises(ValueError, match="closed"):
            call()


@linux
def test_an_abandoned_timer_closes_its_descriptor_when_collected() -> None:
    fds_before = len(os.listdir("/proc/self/fd"))
    for _ in range(50):
        timer.MonotonicTimer().arm(1)
    gc.collect()
    assert len(os.listdir("/proc/self/fd")) == fds_before


@linux
def test_bad_deadlines_are_refused_by_the_wrapper_and_the_core() -> None:
    with timer.MonotonicTimer() as t:
        with pytest.raises(ValueError, match=">= 0"):
            t.arm(-1)
        with pytest.raises(ValueError, match="64 bits"):
            t.arm(1 << 64)
        err = ffi.new("int *")
        assert lib.sb_timer_arm(t.fileno(), -1, err) == lib.SB_E_ARG
        assert lib.sb_timer_arm(-1, 1, err) == lib.SB_E_ARG
        assert lib.sb_timer_disarm(-1, err) == lib.SB_E_ARG
        assert lib.sb_timer_clear(-1, err) == lib.SB_E_ARG
        assert lib.sb_timer_arm(t.fileno(), 1, ffi.NULL) == lib.SB_OK  # err may be NULL


@linux
def test_a_descriptor_that_is_not_a_timer_is_an_os_error_with_its_errno() -> None:
    err = ffi.new("int *")
    read_end, write_end = os.pipe2(os.O_NONBLOCK)
    try:
        assert lib.sb_timer_arm(read_end, 1, err) == lib.SB_E_OS
        assert err[0] != 0
        assert lib.sb_timer_clear(read_end, ffi.NULL) == 0  # an empty non-blocking pipe: nothing
    finally:
        os.close(read_end)
        os.close(write_end)
    with timer.MonotonicTimer() as t:
        read_end, write_end = os.pipe()
        os.dup2(read_end, t.fileno())  # the timer's number now names a pipe: the system refuses it
        os.close(read_end)
        os.close(write_end)
        with pytest.raises(OSError) as caught:
            t.arm(1)
        assert caught.value.errno == errno.EINVAL and "timerfd_settime" in str(caught.value)


@pytest.mark.skipif(sys.platform.startswith("linux"), reason="the fallback of platforms without timerfd")
def test_without_timerfd_the_core_says_unsupported() -> None:  # pragma: no cover - not Linux
    assert not timer.available()
    with pytest.raises(timer.TimerUnsupported):
        timer.MonotonicTimer()
    assert lib.sb_timer_open(ffi.NULL) == lib.SB_E_UNSUPPORTED

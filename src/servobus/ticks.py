"""A fixed-rate pacer for control loops: ``async for tick in ticks(hz=1000): ...``.

Ticks are due at absolute times ``start + n / hz``, never "period after the last one", so a slow
iteration does not push every later tick back. A tick whose deadline has already passed when the
previous iteration ends is reported (``late_s``); ticks that were missed entirely are skipped, not run
in a burst, and counted (``skipped``). One pacer can drive several buses: await their cycles in the
body (or use :class:`servobus.Loop`, which runs on this pacer).

How it waits. An event loop's own sleep cannot hit a deadline inside a millisecond: asyncio's epoll
selector, and trio's, round their timeout up to whole milliseconds, so a 0.5 ms sleep takes 1 ms or
more. On Linux the pacer therefore arms a timerfd (CLOCK_MONOTONIC, absolute deadline: the C core's
:mod:`servobus.core.timer`) and lets the event loop wait for it to become readable, as for a socket:
the process sleeps in the loop's poll, other tasks run, and the kernel's timer wakes it. The loop's
deadlines are converted to CLOCK_MONOTONIC through an offset measured at the start (asyncio's clock is
``time.monotonic()``, trio's ``perf_counter()`` plus a random offset); the timer is armed early by the
median wake-up delay it has seen, and the last microseconds are yielded to the loop.

Measured (``python bench/bench_pacer.py``, bench/RESULTS.md, "The pacer"; a 2-core VM shared with
other work, load 3.5, medians of 5 runs of 3 s): an idle 1 kHz pacer costs 10.3% of a core on asyncio
(10.7% on trio; 8.1% and 9.1% in an earlier run at load 2.6), 0.15 of what the spin of before took
in the same runs (69%: all of the core it could get) and 2.3 times a bare timerfd loop without an
event loop (4.5%, the machine's cost of 1,000 sleeps and wake-ups a second). Ticks start 11 µs late
(median, both backends). The p99 (2.5 ms there) is the wait for a core on a loaded machine, which a
sleeping process pays and a spinning one does not: the same runs at SCHED_FIFO priority 10 (``chrt
-f 10``, safe for a pacer that sleeps) give p99 81 µs (trio 73 µs).

Elsewhere (no timerfd, or a C core built before it), or with ``precise=False``, the pacer spins as
it always did: it sleeps until ``spin_s`` (default 1.2 ms) before the deadline and then yields to the
loop (``anyio.sleep(0)``) until the deadline has come. At 1 kHz that holds one core at 100%, with
ticks 2 µs late (median; p99 13 µs); ``spin_s=0.0005`` takes the CPU down to 15% and the median
lateness up to 0.3 ms.

Runs on asyncio and trio (through anyio; the clock is the loop's, :func:`servobus.runtime.current`),
including virtual time (looptime, ``servobus.sim.virtual``, or trio's ``MockClock``), where every tick
is exactly on time: a clock that does not move while the pacer yields is a virtual one, which moves
only when every task waits, so the pacer sleeps on it (no timer). So does it on a clock that runs at
another rate than CLOCK_MONOTONIC (checked over 1 ms at the start, and at every wake-up).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import AsyncGenerator, AsyncIterator, Callable
from dataclasses import dataclass

import anyio

from servobus import runtime
from servobus.core import timer as _timer

__all__ = ["Tick", "ticks"]

#: a clock whose offset from CLOCK_MONOTONIC moves by more than this is not the real one: checked over
#: CLOCK_PROBE_S at the start, and again at every wake-up of the timer
CLOCK_DRIFT_S = 0.0001
CLOCK_PROBE_S = 0.001
#: the timer is armed early by the median wake-up delay of this many waits, at most LEAD_MAX_S
LEAD_WINDOW = 32
LEAD_MAX_S = 0.0003


@dataclass(frozen=True, slots=True)
class Tick:
    """One tick of a pacer.

    Attributes:
        index: the tick's number since the pacer started (skipped numbers are not yielded).
        deadline: when it was due (the loop's clock).
        started: when the body got it (the loop's clock).
        late_s: ``started - deadline``.
        skipped: ticks dropped since the previous one because their time had passed entirely.
    """

    index: int
    deadline: float
    started: float
    late_s: float
    skipped: int


def ticks(
    hz: float, *, spin_s: float = 0.0012, count: int | None = None, precise: bool | None = None
) -> AsyncIterator[Tick]:
    """Yield a :class:`Tick` at ``hz`` per second, on absolute deadlines, until ``count`` (or forever).

    Args:
        hz: the rate, > 0.
        spin_s: when the pacer yields to the loop until its deadlines (no timer, or ``precise=False``):
            how long before each deadline to stop sleeping and yield instead: more than the selector's
            1 ms resolution for ticks on time; less saves CPU at the cost of lateness. Unused by the
            timer.
        count: how many ticks to yield (None: no end).
        precise: None (auto): wait on the timer where the platform has one and the loop's clock is the
            real one; True: the same, but a platform without the timer raises; False: yield to the
            loop until each deadline (the spin). A virtual clock always sleeps on the loop.

    Raises:
        ValueError: a rate or spin that is not a positive finite number (spin may be 0).
        servobus.core.timer.TimerUnsupported: ``precise=True`` on a platform without the timer.

    Both are raised by the first iteration. The iterator's ``aclose()`` may be called while another
    task's ``__anext__`` waits for a deadline (a blocking caller interrupted, as servobus.sync's): it
    waits for that tick, then closes.
    """
    return _Pacer(_ticks(hz, spin_s, count, precise), 1.0 / hz if _valid_rate(hz) else 0.0)


def _valid_rate(hz: object) -> bool:
    return isinstance(hz, int | float) and math.isfinite(hz) and hz > 0


class _Pacer:
    """The pacer's async iterator: the generator below, with an ``aclose()`` that is safe while an
    ``__anext__`` is in flight (an async generator's own raises "already running" then)."""

    __slots__ = ("_gen", "_in_flight", "_period_s")

    def __init__(self, gen: AsyncGenerator[Tick, None], period_s: float) -> None:
        self._gen = gen
        self._period_s = period_s
        self._in_flight = False

    def __aiter__(self) -> _Pacer:
        return self

    async def __anext__(self) -> Tick:
        self._in_flight = True
        try:
            return await self._gen.__anext__()
        finally:
            self._in_flight = False

    async def aclose(self) -> None:
        while self._in_flight:  # ends at the tick it waits for: at most about a period
            await anyio.sleep(min(self._period_s, 0.01))
        await self._gen.aclose()


async def _ticks(
    hz: float, spin_s: float, count: int | None, precise: bool | None
) -> AsyncGenerator[Tick, None]:
    """:func:`ticks`' generator."""
    if not _valid_rate(hz):
        raise ValueError(f"hz={hz!r} must be a positive number")
    if not (math.isfinite(spin_s) and spin_s >= 0):
        raise ValueError(f"spin_s={spin_s!r} must be >= 0")
    lane = runtime.current()
    clock = lane.time
    period = 1.0 / hz
    waiter = await _timer_wait(lane, precise, spin_s, period)
    start = clock()
    index = 0
    yielded = 0
    try:
        while count is None or yielded < count:
            deadline = start + index * period
            now = clock()
            skipped = 0
            if now - deadline >= period:  # whole periods passed: skip them, keep the grid
                skipped = int((now - deadline) // period)
                index += skipped
                deadline = start + index * period
            if now < deadline:
                if waiter is not None and waiter.usable:
                    await waiter.wait(deadline)
                else:
                    await _yield_until(clock, deadline, spin_s)
            started = clock()
            yield Tick(index, deadline, started, started - deadline, skipped)
            yielded += 1
            index += 1
    finally:
        if waiter is not None:
            waiter.close()


async def _yield_until(clock: Callable[[], float], deadline: float, spin_s: float) -> None:
    """Sleep until ``spin_s`` before ``deadline``, then yield to the loop until it (the spin)."""
    now = clock()
    if deadline - now > spin_s:
        await anyio.sleep(deadline - now - spin_s)
    while (before := clock()) < deadline:
        await anyio.sleep(0)
        if clock() == before:  # a virtual clock moves only when the loop idles: sleep on it
            await anyio.sleep(deadline - before)
            if clock() == before:  # (looptime rounds timers to its resolution: a hair short)
                break


def _offset_ns(clock: Callable[[], float]) -> tuple[int, int]:
    """(CLOCK_MONOTONIC - ``clock``, in ns; the uncertainty of that, ns): the tightest of a few reads."""
    best: tuple[int, int] | None = None
    for _ in range(5):
        before = time.monotonic_ns()
        at = clock()
        after = time.monotonic_ns()
        if best is None or after - before < best[1]:
            best = ((before + after) // 2 - round(at * 1e9), after - before)
    assert best is not None
    return best


async def _is_real(clock: Callable[[], float]) -> tuple[int, int] | None:
    """The clock's offset (as :func:`_offset_ns`) when it runs with CLOCK_MONOTONIC; None otherwise.

    A virtual clock (looptime, trio's MockClock) moves only when every task waits: it stands still
    while this task yields. A clock that moves at another rate drifts against CLOCK_MONOTONIC over
    :data:`CLOCK_PROBE_S` of yielding (spent once, before the first tick's deadline is set).
    """
    first = clock()
    offset, _ = _offset_ns(clock)
    began_ns = time.monotonic_ns()
    await anyio.sleep(0)
    if clock() == first:  # (a real clock reads in ns: it has moved over a turn of the loop)
        return None
    while time.monotonic_ns() - began_ns < CLOCK_PROBE_S * 1e9:
        await anyio.sleep(0)
    again = _offset_ns(clock)
    return again if abs(again[0] - offset) <= CLOCK_DRIFT_S * 1e9 else None


async def _timer_wait(
    lane: runtime.Runtime, precise: bool | None, spin_s: float, period_s: float
) -> _TimerWait | None:
    """The timer wait for this loop, or None for the spin (asked for, no timer, or a virtual clock)."""
    if precise is False:
        return None
    if not _timer.available():
        if precise:
            raise _timer.TimerUnsupported("ticks(precise=True): no timerfd on this platform")
        return None
    offset = await _is_real(lane.time)
    if offset is None:
        return None
    return _TimerWait(lane, offset, spin_s, period_s)


class _AsyncioReady:
    """The timer's expiry on asyncio: the descriptor stays registered with the loop for the pacer's
    life, and its callback takes the expiry and resolves the waiting future. (``anyio.wait_readable``
    registers and unregisters it at every wait: two more system calls per tick, measured at 12-13 %
    of a core at 1 kHz against 5-6 % this way.)"""

    __slots__ = ("_fd", "_future", "_loop", "_timer")

    def __init__(self, timer: _timer.MonotonicTimer) -> None:
        self._timer = timer
        self._fd = timer.fileno()
        self._loop = asyncio.get_running_loop()
        self._future: asyncio.Future[None] | None = None
        self._loop.add_reader(self._fd, self._on_ready)
        timer.before_close = self.close  # (unregistered before the descriptor goes, in any order)

    def _on_ready(self) -> None:
        self._timer.clear()  # (level-triggered: an expiry left in would call back at every turn)
        future = self._future
        if future is not None and not future.done():
            future.set_result(None)

    def __call__(self) -> asyncio.Future[None]:
        # The future itself, awaited by the caller: no coroutine of its own to step through at each
        # tick. One that ends otherwise (cancelled) is done, and the callback leaves it alone.
        self._future = future = self._loop.create_future()
        return future

    def close(self) -> None:
        # Before the descriptor is closed, whoever closes it (the timer calls this first: see
        # MonotonicTimer.before_close); once it is closed, its number is not ours to touch.
        if not self._loop.is_closed() and not self._timer.closed:
            self._loop.remove_reader(self._fd)


class _TrioReady:
    """The timer's expiry on trio: trio's own wait for a descriptor (what ``anyio.wait_readable``
    calls there), then the expiry taken."""

    __slots__ = ("_fd", "_timer", "_wait")

    def __init__(self, timer: _timer.MonotonicTimer) -> None:
        import trio

        self._timer = timer
        self._fd = timer.fileno()
        self._wait = trio.lowlevel.wait_readable

    async def __call__(self) -> None:
        await self._wait(self._fd)
        self._timer.clear()

    def close(self) -> None:
        import trio

        # No wait is pending when the pacer closes; this drops trio's registration of the descriptor,
        # unless it is closed already: its number may name another descriptor by now.
        if not self._timer.closed:
            with contextlib.suppress(RuntimeError):  # (outside trio: a collection, nothing registered)
                trio.lowlevel.notify_closing(self._fd)


class _TimerWait:
    """Waits for a deadline of the loop's clock on a :class:`~servobus.core.timer.MonotonicTimer`.

    The loop's deadline becomes a CLOCK_MONOTONIC one through the offset measured at the start (a
    trio clock is ``perf_counter()`` plus a random offset; asyncio's is ``time.monotonic()``), armed
    half the measurement's uncertainty late so the loop's clock has passed the deadline at the wake-up.

    Waking takes time (the kernel's wake-up, the loop's turn: a median of 40-90 µs on the machine of
    bench/RESULTS.md), so the timer is armed that much early (``lead``: the median wake-up delay of the
    last :data:`LEAD_WINDOW` waits, at most :data:`LEAD_MAX_S` or a quarter period) and the rest is
    yielded to the loop.
    Each wake-up checks the offset again: a clock that drifted (not the real one after all) turns the
    timer off and the pacer back to yielding (``usable``).
    """

    __slots__ = (
        "_clock",
        "_closed",
        "_delays_ns",
        "_lead_max_ns",
        "_lead_ns",
        "_margin_ns",
        "_offset_ns",
        "_ready",
        "_spin_s",
        "_timer",
        "usable",
    )

    def __init__(
        self, lane: runtime.Runtime, offset: tuple[int, int], spin_s: float, period_s: float
    ) -> None:
        self._clock = lane.time
        self._offset_ns, uncertainty_ns = offset
        self._margin_ns = (uncertainty_ns + 1) // 2
        self._spin_s = spin_s
        self._lead_ns = 0
        # (at most a quarter period: at very high rates the timer cannot beat the yield anyway)
        self._lead_max_ns = round(min(LEAD_MAX_S, period_s / 4) * 1e9)
        self._delays_ns: list[int] = []
        self._closed = False
        self._timer = _timer.MonotonicTimer()
        try:
            self._ready: _AsyncioReady | _TrioReady = (
                _TrioReady(self._timer) if lane.name == "trio" else _AsyncioReady(self._timer)
            )
        except BaseException:
            self._closed = True
            self._timer.close()
            raise
        self.usable = True

    async def wait(self, deadline: float) -> None:
        due_ns = round(deadline * 1e9) + self._offset_ns + self._margin_ns
        armed_ns = due_ns - self._lead_ns
        self._timer.arm(armed_ns)
        await self._ready()
        woke_ns = time.monotonic_ns()
        now = self._clock()
        self._learn(woke_ns - armed_ns)
        # A drift means not CLOCK_MONOTONIC plus a constant: yield from now on. (Being preempted
        # between the two reads looks the same: measured properly before deciding.)
        if (
            abs(woke_ns - round(now * 1e9) - self._offset_ns) > CLOCK_DRIFT_S * 1e9
            and abs(_offset_ns(self._clock)[0] - self._offset_ns) > CLOCK_DRIFT_S * 1e9
        ):
            self.usable = False
        if now < deadline:
            await _yield_until(self._clock, deadline, self._spin_s)

    def _learn(self, delay_ns: int) -> None:
        delays = self._delays_ns
        delays.append(delay_ns)
        if len(delays) >= LEAD_WINDOW:
            delays.sort()
            self._lead_ns = min(max(delays[len(delays) // 2], 0), self._lead_max_ns)
            delays.clear()

    def close(self) -> None:
        """Unregister the descriptor from the loop, then close it (again: nothing)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._ready.close()
        finally:
            self._timer.close()

    def __del__(self) -> None:
        # A pacer left by `break` in a reference cycle: the collector finalises every object of the
        # cycle before the loop's hook resurrects the generator to run its `finally` later, by which
        # time the timer's number may name another descriptor. Unregister and close here, in order.
        self.close()

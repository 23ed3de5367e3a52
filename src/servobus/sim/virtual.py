"""Virtual time: run async code on a clock that jumps to the next timer whenever the loop is idle.

With the in-process bus (:class:`~servobus.transports.sim.SimTransport`) every timer in a
simulation is either the network's next event or the host's own sleep or timeout, so on a
virtual-time loop a 10-second scenario costs only the computing it takes, and gives the same result
every run (no real clock anywhere). The loop is ``looptime``'s (``pip install looptime``, part of
``servobus[test]``): ``loop.time()`` starts at ``start`` and moves in steps of 1 µs, exactly.

In pytest, mark a test ``@pytest.mark.looptime`` instead (looptime's plug-in does the same to
pytest-asyncio's loop)::

    @pytest.mark.asyncio
    @pytest.mark.looptime
    async def test_ten_seconds() -> None:
        await asyncio.sleep(10)   # instant

Outside pytest (benchmarks, demos)::

    from servobus.sim import virtual

    async def scenario() -> float:
        async with SimTransport(devices=[MyActuatorMotor(1)]) as bus:
            ...
            await asyncio.sleep(10)
        return asyncio.get_running_loop().time()

    virtual.run(scenario())        # 10.0..., in milliseconds of wall time

On trio the same is trio's own ``MockClock(autojump_threshold=0)``: ``virtual.run(scenario(),
backend="trio")`` (in tests, tests/_backends.py's ``virtual("trio")``).

Real I/O still works on such a loop, but while the loop waits on it the clock moves in real time
(and threads, executors and ``to_thread`` slow it down to real time): keep virtual-time scenarios
in process.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any, TypeVar

__all__ = ["new_event_loop", "run"]

T = TypeVar("T")

#: loop iterations with nothing to do that looptime lets pass before it moves the clock (its own
#: default is 42: room for chains of call_soon callbacks to settle before time moves). Anything that
#: is ready runs first in any case; a few cycles are enough for asyncio's own hand-offs and make
#: every clock step an order of magnitude cheaper.
NOOP_CYCLES = 0


def new_event_loop(
    *, start: float = 0.0, noop_cycles: int = NOOP_CYCLES, **options: Any
) -> asyncio.AbstractEventLoop:
    """A new event loop on virtual time, starting at ``start`` seconds.

    Args:
        start: the loop's time at creation.
        noop_cycles: see :data:`NOOP_CYCLES`.
        **options: any other option of ``looptime.new_event_loop`` (``end``, ``idle_timeout``, ...).

    Raises:
        ModuleNotFoundError: looptime is not installed (it comes with ``servobus[test]``).
    """
    try:
        import looptime
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(
            "virtual time needs looptime: pip install looptime (or servobus[test])"
        ) from exc
    loop: asyncio.AbstractEventLoop = looptime.new_event_loop(start=start, noop_cycles=noop_cycles, **options)
    return loop


def run(main: Coroutine[Any, Any, T], *, start: float = 0.0, backend: str = "asyncio", **options: Any) -> T:
    """Run ``main`` to completion on a new virtual-time loop (like :func:`asyncio.run`) and close it.

    Args:
        main: the coroutine.
        start, **options: see :func:`new_event_loop` (asyncio only).
        backend: "asyncio" (looptime's loop) or "trio" (``trio.testing.MockClock(autojump_threshold=0)``).
    """
    if backend == "trio":
        if options:
            raise TypeError(f"options {sorted(options)} are looptime's: asyncio only")
        import trio
        import trio.testing

        clock = trio.testing.MockClock(autojump_threshold=0)
        clock.jump(start)

        async def body() -> T:
            return await main

        return trio.run(body, clock=clock)
    if backend != "asyncio":
        raise ValueError(f"backend={backend!r}: 'asyncio' or 'trio'")
    loop = new_event_loop(start=start, **options)
    with asyncio.Runner(loop_factory=lambda: loop) as runner:
        return runner.run(main)

"""One frame for several motors (:func:`broadcast`, behind ``Bus.broadcast``), and the waits of a
Bus on several requests at once (:func:`wait_any`, :func:`wait_all`): one runtime waiter each,
resolved by done callbacks (no gathering of one future per request, nothing backend-specific)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import anyio

from servobus.bus.tick import Result
from servobus.protocols import Command, get_family
from servobus.runtime import Runtime
from servobus.scheduler import Request

if TYPE_CHECKING:
    from servobus.bus.engine import Engine
    from servobus.bus.motor import Motor

__all__ = ["broadcast", "wait_all", "wait_any"]


async def broadcast(
    engine: Engine, command: Command, motors: Sequence[Motor], timeout_s: float | None
) -> dict[int, Result]:
    """:meth:`servobus.bus.Bus.broadcast` (the caller checked the loop): waits while a reply's key
    is in flight or held, then the engine sends the frame past its queue and awaits the replies."""
    families = {m.codec.family for m in motors}
    if len(families) != 1:
        raise ValueError(f"a broadcast goes to motors of one family, not {sorted(families)}")
    family = families.pop()
    # One frame reaches every motor of the family on the bus, asked or not: within each one's limits
    # (clamped to the tightest), a value per motor (LK's multi-motor torque) within its own.
    for motor in engine.registry.named.values():
        if motor.limits is not None and motor.codec.family == family:
            command = motor.limited(command, slot=motor.motor_id - 1)
    plan = get_family(family).broadcast(command, [m.codec for m in motors])
    runtime, now = engine.runtime, engine.time
    assert runtime is not None
    keys = list(plan.replies.values())
    while True:
        held_until, flying = engine.blocking(keys)
        if flying:
            await wait_any(runtime, flying, math.inf if held_until is None else held_until - now())
        elif held_until is not None:
            await anyio.sleep(max(0.0, held_until - now()))
        else:
            break
    if engine.closing:  # (the block was left while it waited)
        raise engine.closed_error()
    by_id = {m.motor_id: m for m in motors}
    timeout = timeout_s if timeout_s is not None else max(m.codec.timeout_s(command) for m in motors)
    expected = {
        motor_id: engine.expect(by_id[motor_id], command, key, timeout)
        for motor_id, key in plan.replies.items()
    }
    try:
        engine.send_broadcast(plan.frame, [m for m in motors if not m.codec.retry_safe(command)])
        results = await wait_all(runtime, [r.context for r in expected.values()])
    except BaseException:
        engine.abandon(expected.values())
        raise
    return dict(zip(expected, results, strict=True))


async def wait_any(runtime: Runtime, requests: Sequence[Request], timeout_s: float = math.inf) -> None:
    """Until one of ``requests`` ended, or ``timeout_s`` passed."""
    if timeout_s <= 0:
        return
    waiter = runtime.waiter()

    def ended(_: object) -> None:
        if not waiter.done():
            waiter.set_result(None)

    for request in requests:
        request.context.add_done_callback(ended)
    with anyio.move_on_after(timeout_s):
        await waiter


async def wait_all(runtime: Runtime, contexts: Sequence[Any]) -> list[Result]:
    """The outcome of each of ``contexts`` (waiters), in order, once all ended: a result, or the
    exception as a value."""
    if contexts:
        waiter = runtime.waiter()
        left = len(contexts)

        def ended(_: object) -> None:
            nonlocal left
            left -= 1
            if not left and not waiter.done():
                waiter.set_result(None)

        for context in contexts:
            context.add_done_callback(ended)
        await waiter
    return [context.exception() or context.result() for context in contexts]

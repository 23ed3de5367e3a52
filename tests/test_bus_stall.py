"""A host that stalls (a GC pause, a busy machine) in the middle of a tick: replies that came in
time are taken, not timed out, on asyncio and trio (real time: a stall is the host's own clock
running while the loop does not).

The loop is blocked with ``time.sleep`` right after half the buses sent their tick, for much longer
than the requests' timeout (5 ms, the floor, once round trips were measured). When it goes on, the
Bus's timer and the replies that came during the stall are both due: the replies must go first.
"""

from __future__ import annotations

import contextlib
import time

import anyio
import pytest

from servobus import Bus
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio

BUSES, MOTORS, ROUNDS, STALL_S = 4, 3, 120, 0.03


async def test_replies_that_came_during_a_stall_are_taken_not_timed_out() -> None:
    async with contextlib.AsyncExitStack() as stack:
        buses = []
        for b in range(BUSES):
            link = SimTransport(devices=[MyActuatorMotor(i) for i in range(1, MOTORS + 1)], name=f"sim{b}")
            buses.append(await stack.enter_async_context(Bus(link, name=f"bus {b}")))
        items = [[(bus.motor(ma.FAMILY, i), ma.ReadStatus2()) for i in range(1, MOTORS + 1)] for bus in buses]
        failed: list[BaseException] = []
        stalls = 0
        for r in range(ROUNDS):
            async with anyio.create_task_group() as group:

                async def tick(k: int) -> None:
                    failed.extend(x for x in await buses[k].cycle(items[k]) if isinstance(x, BaseException))

                for k in range(BUSES):
                    group.start_soon(tick, k)
                    if k == BUSES // 2 and r % 10 == 5:
                        await anyio.sleep(0)  # (the first half sent their tick)
                        time.sleep(STALL_S)  # the host stalls; the wire does not
                        stalls += 1
        timeouts = [bus.scheduler.motor_timeout_s(bus.motors[("myactuator", 1)].codec) for bus in buses]
    assert stalls == ROUNDS // 10
    assert max(timeouts) < STALL_S  # (so a stall outlasts a timeout: the case is the one meant)
    assert failed == []

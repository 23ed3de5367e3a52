"""The timer-paced loop over a real link: a Bus on the simulator's SLCAN adapter behind a pseudo-terminal
(tests/test_bus_pty.py's bench), ``bus.ticks()`` driving a ``cycle()`` per tick on asyncio and trio. The
pacer's timerfd and the pty share the event loop's poll: every cycle answered, the ticks on their grid."""

from __future__ import annotations

import contextlib
import os
import statistics
import sys

import anyio
import pytest

from servobus.protocols import myactuator as ma
from test_bus_pty import MA_IDS, CanBench, slcan_bus

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="timerfd is Linux's"),
]

HZ = 200


def _timerfds() -> int:
    count = 0
    for name in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):
            count += os.readlink(f"/proc/self/fd/{name}") == "anon_inode:[timerfd]"
    return count


async def test_a_timer_paced_loop_over_a_pty_slcan_bus_answers_every_cycle_on_the_grid() -> None:
    bench = CanBench()
    before = _timerfds()
    async with slcan_bus(bench) as bus:
        motors = [bus.motor("myactuator", i) for i in MA_IDS]
        late: list[float] = []  # past the deadline, or past the end of the previous body if that was later
        ended = 0.0
        deadlines: list[tuple[int, float]] = []
        opened = 0
        async for tick in bus.ticks(HZ, count=60):
            late.append(tick.started - max(tick.deadline, ended))
            deadlines.append((tick.index, tick.deadline))
            opened = max(opened, _timerfds())
            results = await bus.cycle([(m, ma.ReadStatus2()) for m in motors], timeout_s=0.5)
            assert all(isinstance(r, ma.StatusReply) for r in results), results
            ended = anyio.current_time()
    assert opened == before + 1  # the pacer waited on its timer, beside the pty
    assert _timerfds() == before
    first_index, first = deadlines[0]
    for index, deadline in deadlines:
        assert deadline == pytest.approx(first + (index - first_index) / HZ, abs=1e-9)
    assert statistics.median(late) < 0.001, statistics.median(late)

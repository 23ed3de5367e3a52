"""servobus.ticks: absolute deadlines, late and skipped ticks, on virtual time (exact)."""

from __future__ import annotations

import asyncio

import pytest

from servobus.sim import virtual
from servobus.ticks import Tick, ticks


def _collect(hz: float, count: int, work_s: tuple[float, ...] = ()) -> list[Tick]:
    async def scenario() -> list[Tick]:
        out: list[Tick] = []
        async for tick in ticks(hz, count=count):
            out.append(tick)
            if work_s:
                await asyncio.sleep(work_s[len(out) - 1])
        return out

    return virtual.run(scenario(), start=10.0)


def test_ticks_come_on_the_grid_and_on_time() -> None:
    got = _collect(1000, 5)
    assert [t.index for t in got] == [0, 1, 2, 3, 4]
    assert [round(t.deadline - 10.0, 6) for t in got] == [0.0, 0.001, 0.002, 0.003, 0.004]
    assert all(t.late_s == pytest.approx(0.0, abs=1e-9) and t.skipped == 0 for t in got)


def test_a_slow_body_makes_the_next_tick_late_and_whole_missed_periods_are_skipped() -> None:
    # Tick 0 works 1.5 periods: tick 1 starts 5 ms late. Tick 1 works 3.2 periods (ends at +47 ms):
    # ticks 2 and 3 (due +20, +30 ms) passed entirely and are skipped; tick 4 (+40 ms) runs 7 ms late.
    got = _collect(100, 4, (0.015, 0.032, 0.0, 0.0))
    assert [t.index for t in got] == [0, 1, 4, 5]
    assert got[1].late_s == pytest.approx(0.005, abs=1e-6) and got[1].skipped == 0
    assert got[2].skipped == 2 and got[2].deadline == pytest.approx(10.04)
    assert got[2].late_s == pytest.approx(0.007, abs=1e-6)
    assert got[3].late_s == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize(("hz", "spin"), [(0, 0.0), (-1, 0.0), (float("nan"), 0.0), (100, -1.0)])
def test_bad_rates_are_refused(hz: float, spin: float) -> None:
    async def scenario() -> None:
        async for _ in ticks(hz, spin_s=spin, count=1):
            pass

    with pytest.raises(ValueError):
        virtual.run(scenario())

"""servobus.ticks: absolute deadlines, late and skipped ticks, on virtual time (exact), on asyncio and
trio; and on the real clock, ticks on time."""

from __future__ import annotations

import anyio
import pytest

from _backends import BACKENDS, real, virtual
from servobus.ticks import Tick, ticks


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


async def _collect(hz: float, count: int, work_s: tuple[float, ...] = ()) -> list[Tick]:
    out: list[Tick] = []
    async for tick in ticks(hz, count=count):
        out.append(tick)
        if work_s:
            await anyio.sleep(work_s[len(out) - 1])
    return out


@pytest.mark.anyio
async def test_ticks_come_on_the_grid_and_on_time() -> None:
    await anyio.sleep(10.0)  # (the grid starts where the clock is, not at 0)
    got = await _collect(1000, 5)
    start = got[0].deadline
    assert start == pytest.approx(10.0, abs=1e-6)
    assert [t.index for t in got] == [0, 1, 2, 3, 4]
    assert [round(t.deadline - start, 6) for t in got] == [0.0, 0.001, 0.002, 0.003, 0.004]
    assert all(t.late_s == pytest.approx(0.0, abs=1e-9) and t.skipped == 0 for t in got)


@pytest.mark.anyio
async def test_a_slow_body_makes_the_next_tick_late_and_whole_missed_periods_are_skipped() -> None:
    # Tick 0 works 1.5 periods: tick 1 starts 5 ms late. Tick 1 works 3.2 periods (ends at +47 ms):
    # ticks 2 and 3 (due +20, +30 ms) passed entirely and are skipped; tick 4 (+40 ms) runs 7 ms late.
    got = await _collect(100, 4, (0.015, 0.032, 0.0, 0.0))
    start = got[0].deadline
    assert [t.index for t in got] == [0, 1, 4, 5]
    assert got[1].late_s == pytest.approx(0.005, abs=1e-6) and got[1].skipped == 0
    assert got[2].skipped == 2 and got[2].deadline - start == pytest.approx(0.04)
    assert got[2].late_s == pytest.approx(0.007, abs=1e-6)
    assert got[3].late_s == pytest.approx(0.0, abs=1e-6)


@pytest.mark.anyio
async def test_other_tasks_run_while_the_pacer_waits() -> None:
    beats: list[int] = []

    async def beat() -> None:
        for n in range(3):
            await anyio.sleep(0.004)
            beats.append(n)

    async with anyio.create_task_group() as tg:
        tg.start_soon(beat)
        got = await _collect(1000, 20)
    assert beats == [0, 1, 2] and len(got) == 20


@pytest.mark.anyio
async def test_cancelling_the_loop_ends_the_pacer() -> None:
    got: list[Tick] = []
    with anyio.move_on_after(0.0105):
        async for tick in ticks(1000):
            got.append(tick)
    assert len(got) == 11


@pytest.mark.anyio
@pytest.mark.parametrize(("hz", "spin"), [(0, 0.0), (-1, 0.0), (float("nan"), 0.0), (100, -1.0)])
async def test_bad_rates_are_refused(hz: float, spin: float) -> None:
    with pytest.raises(ValueError):
        async for _ in ticks(hz, spin_s=spin, count=1):
            pass


@pytest.mark.parametrize("backend", BACKENDS)
def test_on_the_real_clock_ticks_start_on_time(backend: str) -> None:
    """The spin before each deadline: the median tick starts within 0.3 ms of its deadline at 500 Hz
    (a sleep alone is up to 1 ms late); generous, for a loaded machine."""

    async def main() -> list[Tick]:
        return [tick async for tick in ticks(500, count=100)]

    name, options = real(backend)
    got = anyio.run(main, backend=name, backend_options=options)
    late = sorted(t.late_s for t in got)
    assert [t.index - t.skipped for t in got][:1] == [0]
    assert 0.0 <= late[len(late) // 2] < 0.0003, late[len(late) // 2]


@pytest.mark.parametrize("backend", BACKENDS)
def test_servobus_sim_virtual_runs_the_pacer_on_either_backend(backend: str) -> None:
    from servobus.sim import virtual

    async def main() -> list[float]:
        return [tick.deadline async for tick in ticks(100, count=3)]

    assert virtual.run(main(), start=10.0, backend=backend) == pytest.approx([10.0, 10.01, 10.02])

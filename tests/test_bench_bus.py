"""bench/bench_bus.py: its bound is the one the simulator keeps, and its reflector paths work.

The efficiency figure runs on virtual time, so it is deterministic: the issue's target (``cycle()``
over 32 motors keeps the simulated 1 Mbit/s wire >= 95 % busy) is checked here on every test run,
not only when someone runs the benchmark. The transaction rates are machine-dependent and are not
asserted; only that each path returns typed replies (the benchmark raises otherwise).
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

import pytest

from servobus.protocols import myactuator as ma
from servobus.sim import virtual

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import bench_bus  # noqa: E402


def test_cycle_keeps_the_simulated_wire_busy() -> None:
    run = virtual.run(bench_bus.efficiency_run(3, ma.ReadStatus2, sequential=False))
    assert run["achieved_cycles_s"] / run["bound_cycles_s"] >= bench_bus.EFFICIENCY_TARGET
    # 64 classic 8-byte frames: 111..135 bits each, at 1 Mbit/s.
    assert 64 * 111e-6 <= run["wire_us_per_cycle"] * 1e-6 <= 64 * 135e-6


def test_sequential_baseline_meets_its_own_bound_wire_plus_turnaround() -> None:
    run = virtual.run(bench_bus.efficiency_run(2, ma.ReadStatus2, sequential=True))
    per_cycle = run["wire_s"] / run["cycles"] + bench_bus.MOTORS * run["turnaround_s"]
    assert run["achieved_cycles_s"] == pytest.approx(1 / per_cycle, rel=0.01)


@pytest.mark.parametrize("fd", [False, True])
def test_reflector_paths_return_typed_replies(fd: bool) -> None:
    replies = bench_bus.prebuilt_replies(ma.ReadStatus2())
    assert asyncio.run(bench_bus.ours_reflector(3, replies)).rate > 0
    assert asyncio.run(bench_bus.naive_reflector(40, replies, fd=fd)).rate > 0
    assert asyncio.run(bench_bus.naive_reflector(64, replies, pipelined=True)).rate > 0


@pytest.mark.parametrize("motors", [1, 4, 32])
def test_cycle_and_the_asyncio_floor_on_the_reflector(motors: int) -> None:
    replies = bench_bus.prebuilt_replies(ma.ReadStatus2())
    ours = asyncio.run(bench_bus.ours_reflector(5, replies, motors))
    floor = asyncio.run(bench_bus.floor_reflector(5, replies, motors))
    assert ours.rate > 0 and floor.rate > 0
    assert ours.cpu_us >= 0 and floor.cpu_us >= 0


@pytest.mark.parametrize("motors", [1, 32])
def test_cycle_and_the_trio_floor_on_the_reflector(motors: int) -> None:
    import trio

    replies = bench_bus.prebuilt_replies(ma.ReadStatus2())
    ours = trio.run(bench_bus.ours_reflector, 5, replies, motors)
    floor = trio.run(bench_bus.floor_reflector_trio, 5, replies, motors)
    assert ours.rate > 0 and floor.rate > 0
    assert ours.cpu_us >= 0 and floor.cpu_us >= 0

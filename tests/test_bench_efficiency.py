"""bench/bench_efficiency.py: its bounds are right and the Bus meets them, on virtual time (deterministic).

The efficiency figures of the benchmark suite run on a virtual clock, so they are the same on every
machine: the issue's target (>= 95 % of the bound on every bus) is checked here on every test run, on
small sizes, and the bounds themselves are checked against hand arithmetic, so a wrong bound cannot make
a slow Bus look efficient.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.timing import frame_time_s, uart_time_s

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import bench_efficiency as be  # noqa: E402


def test_can_bound_one_motor_is_request_turnaround_reply() -> None:
    assert be.can_cycle_bound([120e-6], [125e-6], 200e-6) == pytest.approx(445e-6)


def test_can_bound_many_motors_is_the_wire_when_the_turnaround_hides() -> None:
    requests, replies = [120e-6] * 32, [125e-6] * 32
    assert be.can_cycle_bound(requests, replies, 200e-6) == pytest.approx(32 * 245e-6)


def test_can_bound_broadcast_is_request_turnaround_all_replies() -> None:
    assert be.can_cycle_bound([120e-6], [125e-6] * 4, 200e-6) == pytest.approx(120e-6 + 200e-6 + 500e-6)


def test_can_bound_takes_the_critical_path_when_it_is_longer_than_the_wire() -> None:
    # 2 motors, turnaround 500 µs: request, request, then 500 µs of turnaround before the last reply
    assert be.can_cycle_bound([60e-6] * 2, [60e-6] * 2, 500e-6) == pytest.approx(120e-6 + 500e-6 + 60e-6)


def test_one_motor_on_can_runs_at_its_bound() -> None:
    run = virtual.run(be.can_run(be.CAN, 1, 3))
    request = get_family("myactuator").bind(1).encode(ma.ReadStatus2())
    reply = MyActuatorMotor(1).receive(request, 0.0)[0].frame
    expected = frame_time_s(request) + 200e-6 + frame_time_s(reply)
    assert run["bound_us_per_cycle"] == pytest.approx(expected * 1e6)
    assert run["efficiency"] >= be.TARGET


@pytest.mark.parametrize(("spec", "motors"), [(be.CAN, 4), (be.CAN, 32), (be.CANFD, 1), (be.CANFD, 8)])
def test_cycle_keeps_the_can_buses_near_their_bound(spec: be.CanSpec, motors: int) -> None:
    run = virtual.run(be.can_run(spec, motors, 2))
    assert be.TARGET <= run["efficiency"] <= 1.0 + 1e-9
    assert run["bus_load"] <= 1.0 + 1e-9


def test_rs485_bound_is_bytes_turnaround_and_the_declared_gap() -> None:
    run = virtual.run(be.rs485_run(115_200, 1, 3))
    per_exchange = uart_time_s(26, 115_200) + 200e-6 + 3.5 * uart_time_s(1, 115_200)
    assert run["bound_us_per_cycle"] == pytest.approx(per_exchange * 1e6)
    assert run["gap_us"] == pytest.approx(3.5 * 10 / 115_200 * 1e6)
    assert run["efficiency"] >= be.TARGET


@pytest.mark.parametrize("baud", [1_000_000, 2_500_000])
def test_rs485_lines_run_near_their_bound(baud: int) -> None:
    run = virtual.run(be.rs485_run(baud, 4, 2))
    assert be.TARGET <= run["efficiency"] <= 1.0 + 1e-9


def test_broadcast_and_lk_multi_motor_torque_and_streams() -> None:
    bcast = virtual.run(be.can_run(be.CAN, 4, 2, "broadcast"))
    lk_multi = virtual.run(be.can_run(be.LK, 4, 2, "broadcast"))
    stream = virtual.run(be.stream_run(2, 0.2))
    for run in (bcast, lk_multi, stream):
        assert be.TARGET <= run["efficiency"] <= 1.0 + 1e-9
    assert stream["achieved_cycles_s"] == pytest.approx(100.0)


def test_the_figures_are_the_same_every_run() -> None:
    first = virtual.run(be.can_run(be.CANFD, 4, 2))
    again = virtual.run(be.can_run(be.CANFD, 4, 2))
    assert first == again

"""Seeded link faults (servobus.sim.faults): every kind, and the same seed gives the same run."""

from __future__ import annotations

import pytest

from servobus.core import MyActuatorRs485Deframer, crc16_modbus
from servobus.frame import Frame
from servobus.sim.faults import FaultInjector, FaultPlan

FRAME = Frame(arbitration_id=0x141, data=bytes.fromhex("9C00000000000000"))


def _rs485(motor_id: int) -> bytes:
    body = bytes([0x3E, motor_id, 0x08, 0x9C, 0, 0, 0, 0, 0, 0, 0])
    return body + crc16_modbus(body).to_bytes(2, "little")


def _run(plan: FaultPlan, seed: int, n: int = 200) -> list[tuple[float, object]]:
    injector = FaultInjector(plan, seed)
    out = []
    for i in range(n):
        out += injector.apply(_rs485(1 + i % 32), float(i))
    return out + injector.flush(float(n))


def test_same_seed_same_run_other_seed_other_run() -> None:
    plan = FaultPlan(drop=0.1, corrupt=0.1, duplicate=0.1, reorder=0.1, delay=0.1)
    assert _run(plan, seed=7) == _run(plan, seed=7)
    assert _run(plan, seed=7) != _run(plan, seed=8)


def test_drop() -> None:
    injector = FaultInjector(FaultPlan(drop=1.0))
    assert injector.apply(FRAME, 1.0) == []
    assert injector.counts["drop"] == 1


def test_duplicate() -> None:
    assert FaultInjector(FaultPlan(duplicate=1.0)).apply(FRAME, 1.0) == [(1.0, FRAME), (1.0, FRAME)]


def test_delay_stays_in_its_window() -> None:
    injector = FaultInjector(FaultPlan(delay=1.0, delay_s=(0.002, 0.004)), seed=3)
    for i in range(50):
        [(at, item)] = injector.apply(FRAME, float(i))
        assert item == FRAME and 0.002 <= at - i <= 0.004


def test_reorder_swaps_with_the_next_item_and_flush_releases() -> None:
    injector = FaultInjector(FaultPlan(reorder=0.5), seed=1)
    delivered = []
    for i in range(100):
        delivered += [item for _, item in injector.apply(_rs485(1 + i % 32), float(i))]
    delivered += [item for _, item in injector.flush(100.0)]
    sent = [_rs485(1 + i % 32) for i in range(100)]
    assert sorted(delivered) == sorted(sent) and delivered != sent  # nothing lost, order changed
    assert injector.counts["reorder"] > 0


def test_corrupt_serial_fails_the_crc_and_corrupt_can_is_a_retransmission() -> None:
    injector = FaultInjector(FaultPlan(corrupt=1.0), seed=5)
    deframer = MyActuatorRs485Deframer()
    for i in range(50):
        [(_, damaged)] = injector.apply(_rs485(1 + i % 32), 0.0)
        assert isinstance(damaged, bytes) and damaged != _rs485(1 + i % 32)
        deframer.feed(damaged)
    assert deframer.frames == 0 and (deframer.crc_errors + deframer.discarded_bytes) > 0
    [(at, same)] = FaultInjector(FaultPlan(corrupt=1.0)).apply(FRAME, 1.0)
    assert same == FRAME and at == pytest.approx(1.000135)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"drop": 1.5}, r"drop=1.5 is outside \[0.0, 1.0\]"),
        ({"drop": 0.6, "delay": 0.6}, "add up to more than 1"),
        ({"delay_s": (0.2, 0.1)}, "must be 0 <= low <= high"),
    ],
)
def test_plans_are_checked(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FaultPlan(**kwargs)  # type: ignore[arg-type]

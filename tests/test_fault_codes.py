"""Fault codes as well as fault flags: a reply declares the field of one error code
(``Reply.FAULT_CODE``) and the codes that are states, not faults (``NO_FAULT_CODES``); the Bus keeps
``motor.fault`` from it, a :class:`~servobus.errors.MotorFault` with ``code`` (and no flags), cleared
when the motor reports a state again. Through the Bus on ``SimTransport`` with the ``twin`` family
(tests/cli/_twin.py: Damiao's state code, 0 disabled, 1 enabled, 8.. faults), and in ``status`` and
``scan``'s errors column."""

from __future__ import annotations

from collections.abc import Iterator
from types import ModuleType
from typing import Any

import anyio
import pytest

import servobus.cli._connect as connect
from cli._bus_cli import run_json
from servobus import Bus
from servobus.cli.plugin import fault_names
from servobus.errors import MotorFault
from servobus.protocols import Reply
from servobus.protocols import myactuator as ma
from servobus.transports.sim import SimTransport


@pytest.fixture(scope="module")
def twin(toy: ModuleType) -> Iterator[ModuleType]:
    from cli._twin import installed

    with installed() as module:
        yield module


def test_a_fault_is_told_by_flags_or_by_a_code() -> None:
    flagged = MotorFault("over voltage", flags=ma.ErrorFlags.OVER_VOLTAGE, motor_id=2)
    assert flagged.flags == ma.ErrorFlags.OVER_VOLTAGE and flagged.code is None and flagged.motor_id == 2
    coded = MotorFault("over current", code=0xA, motor_id=3)
    assert coded.code == 0xA and coded.flags is None and coded.motor_id == 3
    assert Reply.FAULT_CODE is None and frozenset({0}) == Reply.NO_FAULT_CODES


def _faults_seen(twin: ModuleType, codes: list[int]) -> list[MotorFault | None]:
    """``motor.fault`` after each state read, the simulated motor reporting each of ``codes`` in turn."""
    device = twin.TwinMotor(1)
    seen: list[MotorFault | None] = []

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[device]), safe=None) as bus:
            motor = bus.motor("twin", 1)
            for code in codes:
                device.faults = twin.ToyFaults(code)  # (DATA[7]: the state code the twin reads)
                reply = await motor.request(twin.ReadState())
                assert isinstance(reply, twin.CodedState) and reply.state == code
                seen.append(motor.fault)

    anyio.run(scenario)
    return seen


def test_a_reply_with_a_fault_code_sets_a_motor_fault_with_the_code(twin: ModuleType) -> None:
    DmState = twin.DmState
    seen = _faults_seen(twin, [1, 0xA, 0xA, 0xD, 0, 7])
    enabled, over_current, again, lost, disabled, unknown = seen
    assert enabled is None  # 1: enabled, a state
    assert isinstance(over_current, MotorFault) and over_current.code is DmState.OVER_CURRENT
    assert over_current.flags is None and over_current.motor_id == 1
    assert "reports DmState.OVER_CURRENT" in str(over_current)
    assert again is over_current  # the same code: the same fault, not a new one
    assert isinstance(lost, MotorFault) and lost.code is DmState.COMMUNICATION_LOST
    assert disabled is None  # 0: disabled, a state: the fault is over
    assert isinstance(unknown, MotorFault) and unknown.code == 7 and "reports code 7" in str(unknown)


def test_fault_names_read_flags_or_a_code(twin: ModuleType) -> None:
    state: Any = twin.CodedState
    assert fault_names(state(position_deg=0.0, speed_dps=0.0, state=twin.DmState.ENABLED)) == []
    assert fault_names(state(position_deg=0.0, speed_dps=0.0, state=twin.DmState.OVERLOAD)) == ["OVERLOAD"]
    assert fault_names(state(position_deg=0.0, speed_dps=0.0, state=7)) == ["code 7"]
    toy_state = twin.StateReply(position_deg=0.0, speed_dps=0.0, faults=twin.ToyFaults.STALL)
    assert fault_names(toy_state) == ["STALL"]
    assert fault_names(None) is None and fault_names(twin.SpeedLimitEcho(limit_dps=1.0)) is None


def test_status_and_scan_show_the_code_as_errors(
    twin: ModuleType, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def devices(family: str, ids: tuple[int, ...], revision: str | None = None) -> list[Any]:
        made = [twin.TwinMotor(i) for i in ids]
        made[-1].report(twin.DmState.MOS_OVER_TEMPERATURE)
        return made

    monkeypatch.setattr(connect, "sim_devices", devices)
    rows = run_json(capsys, ["status", "--family", "twin", "--sim", "2"])
    assert [(r["id"], r["errors"]) for r in rows] == [(1, []), (2, ["MOS_OVER_TEMPERATURE"])]
    rows = run_json(capsys, ["scan", "--family", "twin", "--sim", "2", "--ids", "1-2"])
    assert [(r["id"], r["state"], r["errors"]) for r in rows] == [
        (1, "DISABLED", []),
        (2, "MOS_OVER_TEMPERATURE", ["MOS_OVER_TEMPERATURE"]),
    ]


def test_a_fault_code_reaches_status_through_python_can_virtual(
    twin: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    from cli._virtual import served_on_virtual

    devices = [twin.TwinMotor(1), twin.TwinMotor(17)]
    devices[1].report(twin.DmState.UNDER_VOLTAGE)
    with served_on_virtual(devices) as channel:
        bus = ["--family", "twin", "-i", "virtual", "-c", channel, "--timeout-ms", "500"]
        rows = run_json(capsys, ["status", *bus, "--ids", "1"])
        assert rows[0]["errors"] == []
        rows = run_json(capsys, ["status", *bus, "--ids", "17"])
        assert rows[0]["errors"] == ["UNDER_VOLTAGE"]


def test_the_dashboard_names_a_fault_code(twin: ModuleType) -> None:
    from servobus.dashboard._board import _fault_names

    assert _fault_names(MotorFault("m", code=twin.DmState.OVERLOAD, motor_id=1)) == ["OVERLOAD"]
    assert _fault_names(MotorFault("m", flags=ma.ErrorFlags.OVER_VOLTAGE, motor_id=1)) == ["OVER_VOLTAGE"]
    assert _fault_names(MotorFault("m", flags=None, motor_id=1)) == []  # (an event's: no names)

"""The typed calls (protocols/<family>/_motor.py) on their protocols-layer base, composed with the
Bus's Motor by hand the way the Bus composes them (issue 38: a family never imports the Bus)."""

from __future__ import annotations

from typing import Any

import anyio
import pytest

from servobus.bus import Motor as BusMotor
from servobus.protocols import FAMILIES, Command, get_family
from servobus.protocols import myactuator as ma
from servobus.protocols._calls import TypedCalls


def test_the_base_adds_nothing_at_run_time() -> None:
    """It sits before the Bus's Motor in the MRO: a member of its own would hide the Bus's."""
    assert set(vars(TypedCalls)) <= {"__module__", "__qualname__", "__doc__", "__slots__"}
    assert TypedCalls.__mro__ == (TypedCalls, object)


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_a_family_s_typed_calls_do_not_subclass_the_bus_s_motor(name: str) -> None:
    calls = get_family(name).motor()
    assert issubclass(calls, TypedCalls)
    assert not issubclass(calls, BusMotor)
    for member in ("request", "stream", "frames", "metrics", "motor_id", "__init__"):
        assert all(member not in vars(cls) for cls in calls.__mro__[:-1]), member


class _Bus:
    """What a composed motor's ``request`` reaches: records the command, answers a sentinel."""

    name = "fake"

    def __init__(self) -> None:
        self.sent: list[Command[Any]] = []

    async def request(
        self, motor: object, command: Command[Any], *, timeout_s: float | None, retries: int
    ) -> Any:
        self.sent.append(command)
        return ("reply", timeout_s, retries)


def test_composed_with_the_bus_s_motor_a_typed_call_goes_through_its_request() -> None:
    family = get_family("myactuator")
    calls = family.motor()
    composed = type(calls.__name__, (calls, BusMotor), {})
    assert composed.__mro__.index(calls) < composed.__mro__.index(BusMotor)
    bus = _Bus()
    motor = composed(bus, family.bind(3))  # type: ignore[arg-type]
    answer = anyio.run(lambda: motor.speed_control(speed_dps=12.5, timeout_s=0.5, retries=1))
    assert answer == ("reply", 0.5, 1)
    assert bus.sent == [ma.SpeedControl(speed_dps=12.5)]
    assert motor.motor_id == 3

"""The bus package's shape (issue 38): one record per motor in one registry, a family's typed calls
class made a Motor once, the engine's per-motor counter."""

from __future__ import annotations

import typing
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import anyio
import pytest

from servobus.bus import Bus, Motor
from servobus.bus.motor import motor_class
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.transports.sim import SimTransport

BUS_PACKAGE = Path(__file__).resolve().parents[2] / "src" / "servobus" / "bus"


@pytest.mark.anyio
async def test_each_motor_has_one_record_keyed_by_its_codec() -> None:
    async with Bus(SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2)])) as bus:
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        assert bus.motor("myactuator", 1) is one  # bound once
        assert bus.registry.of(one).motor is one and bus.registry.of(two).motor is two
        assert bus.registry.records == {
            id(one.codec): bus.registry.of(one),
            id(two.codec): bus.registry.of(two),
        }
        assert bus.motors is bus.registry.named
        assert bus.commanded == ()
        await two.speed_control(speed_dps=10.0)
        await one.read_status2()  # a read commands nothing
        await one.speed_control(speed_dps=10.0)
        await two.speed_control(speed_dps=20.0)
        assert bus.commanded == (two, one)  # in the order they were first commanded


@pytest.mark.anyio
async def test_a_missed_reply_is_counted_on_the_motor_s_record() -> None:
    device = MyActuatorMotor(1)
    async with Bus(SimTransport(devices=[device]), offline_after_misses=2) as bus:
        motor = bus.motor("myactuator", 1)
        await motor.read_status2()
        device.unresponsive = True
        with pytest.raises(Exception, match="no reply"):
            await motor.read_status2(timeout_s=0.01)
        assert bus.registry.of(motor).misses == 1 and motor.online is True
        with pytest.raises(Exception, match="no reply"):
            await motor.read_status2(timeout_s=0.01)
        assert bus.registry.of(motor).misses == 2 and motor.online is False
        device.unresponsive = False
        with anyio.fail_after(2):
            while motor.online is not True:
                await bus.cycle([(motor, ma.ReadStatus2())])
                await anyio.sleep(0.02)
        assert bus.registry.of(motor).misses == 0


@pytest.mark.anyio
async def test_the_engine_counts_through_the_scheduler_s_count() -> None:
    async with Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
        motor = bus.motor("myactuator", 1)
        bus.engine.count(motor.codec, "restarts")
        assert motor.metrics().restarts == 1
        counted: list[tuple[Any, str]] = []
        bus.scheduler.count = lambda codec, counter, n=1: counted.append((codec, counter))  # type: ignore[method-assign]
        bus.engine.count(motor.codec, "restarts")
        assert counted == [(motor.codec, "restarts")]
        assert motor.metrics().restarts == 1


class _Calls:
    """A family's typed calls, not a Motor (what servobus.protocols._calls generates)."""

    async def request(self, command: Any, *, timeout_s: float | None = None, retries: int = 0) -> Any:
        raise NotImplementedError  # (the host's: the Bus's Motor)

    async def read_status2(self, *, timeout_s: float | None = None, retries: int = 0) -> Any:
        return await self.request(ma.ReadStatus2(), timeout_s=timeout_s, retries=retries)


@typing.runtime_checkable
class _ProtocolCalls(typing.Protocol):
    async def read_status2(self, *, timeout_s: float | None = None, retries: int = 0) -> Any:
        return await self.request(ma.ReadStatus2(), timeout_s=timeout_s, retries=retries)  # type: ignore[method-assign]


def _family(calls: type) -> Any:
    return SimpleNamespace(
        name="myactuator", motor=lambda: calls, methods=lambda: {"read_status2": ma.ReadStatus2}
    )


@pytest.mark.anyio
@pytest.mark.parametrize("calls", [_Calls, _ProtocolCalls])
async def test_a_calls_class_that_is_not_a_motor_becomes_one_once_per_family(calls: type) -> None:
    family = _family(calls)
    made = motor_class(family)
    assert made is motor_class(family)  # made once
    assert issubclass(made, Motor) and issubclass(made, calls) and made.__name__ == calls.__name__
    assert (made.__doc__, made.__module__) == (calls.__doc__, calls.__module__)
    assert made.request is Motor.request  # the Bus's, not the calls class's stub
    assert "Send ReadStatus2 and await its reply." in (made.read_status2.__doc__ or "")
    device = MyActuatorMotor(1)
    async with Bus(SimTransport(devices=[device])) as bus:
        codec = ma.FAMILY.bind(1)
        bus.scheduler.add(codec)
        motor = bus.registry.add(("myactuator", 1), made, bus, codec, ma.FAMILY.methods())
        assert isinstance(motor, calls) and isinstance(motor, Motor)
        reply = await motor.read_status2()  # type: ignore[method-assign]
        assert isinstance(reply, ma.ReadStatus2.REPLY)


def test_a_family_motor_that_is_a_motor_is_used_as_it_is() -> None:
    class Typed(Motor):
        async def read_status2(self, *, timeout_s: float | None = None, retries: int = 0) -> Any:
            return await self.request(ma.ReadStatus2(), timeout_s=timeout_s, retries=retries)

    assert motor_class(_family(Typed)) is Typed
    assert "Send ReadStatus2 and await its reply." in (Typed.read_status2.__doc__ or "")

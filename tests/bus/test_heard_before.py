"""A time-out's diagnosis tells a silent motor among answering ones from a silent line: another
motor's reply just before the request (``HEARD_BEFORE_S``: a command asking one motor after the
other) shows the line works; the silent motor's own earlier reply never does (a pulled cable after
it answered is a silent line). In virtual time."""

from __future__ import annotations

import anyio
import pytest

from servobus.bus import Bus
from servobus.bus.engine import HEARD_BEFORE_S
from servobus.errors import MotorTimeout
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.transports.sim import SimTransport

NOTHING_AT_ALL = "no frame at all"


async def _silenced(motors: int, then_asked: int) -> str:
    devices = [MyActuatorMotor(i) for i in range(1, motors + 1)]
    async with Bus(SimTransport(devices=devices)) as bus:
        for i in range(1, motors + 1):
            await bus.motor("myactuator", i).read_status2()  # every motor answered
        for device in devices:
            device.unresponsive = True  # the cable is pulled
        with pytest.raises(MotorTimeout) as caught:
            await bus.motor("myactuator", then_asked).read_status2(timeout_s=0.02)
        return str(caught.value)


def test_the_silent_motor_s_own_earlier_reply_does_not_make_the_line_look_alive() -> None:
    said = virtual.run(_silenced(1, 1))
    assert NOTHING_AT_ALL in said, said


def test_another_motor_heard_just_before_names_the_silent_one() -> None:
    said = virtual.run(_silenced(2, 1))  # motor 2 answered last, just before
    assert "none from motor 1" in said and NOTHING_AT_ALL not in said, said


def test_another_motor_heard_longer_ago_is_not_taken_for_a_live_line() -> None:
    async def scenario() -> str:
        devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
        async with Bus(SimTransport(devices=devices)) as bus:
            await bus.motor("myactuator", 2).read_status2()
            for device in devices:
                device.unresponsive = True
            await anyio.sleep(HEARD_BEFORE_S * 2)  # (the cable was pulled a while ago)
            with pytest.raises(MotorTimeout) as caught:
                await bus.motor("myactuator", 1).read_status2(timeout_s=0.02)
            return str(caught.value)

    said = virtual.run(scenario())
    assert NOTHING_AT_ALL in said, said

"""servobus.sync: the Bus for code that is not async, on the in-process simulated bus (real time)."""

from __future__ import annotations

import pytest

from servobus import sync
from servobus.errors import MotorTimeout
from servobus.protocols import myactuator as ma
from servobus.sim.devices.myactuator import MyActuatorMotor
from servobus.transports.sim import SimTransport
from sim._standins import Sniffer


def _stops(sniffer: Sniffer) -> set[int]:
    return {
        f.arbitration_id - 0x140
        for _, f in sniffer.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == b"\x81"
    }


def test_commands_block_and_return_their_replies() -> None:
    with sync.Bus(SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2)])) as bus:
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        assert isinstance(one.read_status2(), ma.StatusReply)
        results = bus.cycle([(one, ma.ReadMultiTurnAngle()), (two, ma.ReadStatus1())])
        assert isinstance(results[0], ma.MultiTurnAngleReply) and isinstance(results[1], ma.Status1Reply)
        assert isinstance(one.state, ma.Status1Reply | ma.MultiTurnAngleReply | ma.StatusReply)
        assert bus.stats()["replies"] == 3


def test_a_timeout_raises_in_the_caller() -> None:
    silent = MyActuatorMotor(1)
    silent.unresponsive = True
    with sync.Bus(SimTransport(devices=[silent])) as bus, pytest.raises(MotorTimeout, match="motor 1"):
        bus.motor("myactuator", 1).read_status2(timeout_s=0.05)


def test_an_exception_in_the_block_stops_the_commanded_motors() -> None:
    sniffer = Sniffer()
    transport = SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2), sniffer])
    with pytest.raises(RuntimeError, match="script failed"), sync.Bus(transport) as bus:
        bus.motor("myactuator", 1).speed_control(speed_dps=45.0)
        bus.motor("myactuator", 2).read_status2()
        raise RuntimeError("script failed")
    assert _stops(sniffer) == {1}


def test_close_stops_the_motors_too_and_twice_is_harmless() -> None:
    sniffer = Sniffer()
    bus = sync.Bus(SimTransport(devices=[MyActuatorMotor(3), sniffer]))
    bus.motor("myactuator", 3).torque_control(current_a=0.2)
    bus.close()
    bus.close()
    assert _stops(sniffer) == {3}

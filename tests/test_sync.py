"""servobus.sync: the Bus for code that is not async, on the in-process simulated bus (real time)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from _backends import BACKENDS
from servobus import sync
from servobus.errors import MotorTimeout
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.transports.sim import SimTransport
from sim._standins import Sniffer

HERE = Path(__file__).resolve().parent


def _stops(sniffer: Sniffer) -> set[int]:
    return {
        f.arbitration_id - 0x140
        for _, f in sniffer.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == b"\x81"
    }


@pytest.mark.parametrize("backend", BACKENDS)
def test_commands_block_and_return_their_replies(backend: str) -> None:
    transport = SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2)])
    with sync.Bus(transport, backend=backend) as bus:
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


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_exception_in_the_block_stops_the_commanded_motors(backend: str) -> None:
    sniffer = Sniffer()
    transport = SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2), sniffer])
    with pytest.raises(RuntimeError, match="script failed"), sync.Bus(transport, backend=backend) as bus:
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


def _requests(sniffer: Sniffer, motor_id: int) -> list[bytes]:
    return [f.data for _, f in sniffer.seen if f.arbitration_id == 0x140 + motor_id]


def test_motor_commands_take_their_fields_by_position_as_declared() -> None:
    sniffer = Sniffer()
    with sync.Bus(SimTransport(devices=[MyActuatorMotor(1), sniffer])) as bus:
        motor = bus.motor("myactuator", 1)
        assert motor.set_comm_timeout(100) is not None
        motor.speed_control(45.0, 50)
        motor.speed_control(45.0, max_torque_pct=50)
        with pytest.raises(TypeError, match="positional arguments but 4 were given"):
            motor.speed_control(1.0, 2, 3)
        with pytest.raises(TypeError, match="multiple values for argument 'speed_dps'"):
            motor.speed_control(1.0, speed_dps=2.0)
    sent = _requests(sniffer, 1)
    assert sent[0] == ma.SetCommTimeout(timeout_ms=100).encode()
    assert sent[1] == sent[2] == ma.SpeedControl(speed_dps=45.0, max_torque_pct=50).encode()


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_sync_bus_has_metrics_subscriptions_ticks_and_requests(backend: str) -> None:
    heard: list[tuple[int, Any]] = []
    statuses: list[Any] = []
    silent = MyActuatorMotor(2)
    silent.unresponsive = True
    transport = SimTransport(devices=[MyActuatorMotor(1), silent])
    with sync.Bus(transport, backend=backend, offline_after_misses=1) as bus:
        bus.subscribe(lambda motor, traffic, reply: heard.append((motor.motor_id, reply)))
        bus.subscribe_status(statuses.append)
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        ticks = list(bus.ticks(200, count=3))
        assert [t.index for t in ticks] == [0, 1, 2]
        assert ticks[-1].deadline - ticks[0].deadline == pytest.approx(0.01)
        for _ in bus.ticks(500, count=2):
            bus.cycle([(one, ma.ReadStatus1())])
        assert isinstance(bus.request(one, ma.ReadStatus2()), ma.StatusReply)
        with pytest.raises(MotorTimeout):
            two.read_status2(timeout_s=0.02)
        assert two.online is False and one.online is True and one.motor_id == 1
        metrics = bus.metrics()
        assert metrics.replies == 3 == one.metrics().replies and metrics.timeouts == 1
        assert bus.stats()["replies"] == 3
    assert [m for m, _ in heard] == [1, 1, 1]
    assert [(s.motor.motor_id, s.online) for s in statuses] == [(1, True), (2, False)]


def test_an_async_callback_is_refused_not_silently_dropped() -> None:
    async def handler(*args: object) -> None:
        raise AssertionError("never awaited")

    with sync.Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
        with pytest.raises(TypeError, match="async"):
            bus.subscribe(handler)
        with pytest.raises(TypeError, match="async"):
            bus.subscribe_status(handler)


def test_a_sync_bus_left_open_exits_cleanly_and_stops_its_motors() -> None:
    script = textwrap.dedent(
        """
        import atexit  # first: atexit runs last-registered first, so this reports after the close

        def report():
            stops = [f for _, f in sniffer.seen if f.arbitration_id == 0x141 and f.data[:1] == b"\\x81"]
            print("stops:", len(stops))

        atexit.register(report)

        from servobus import sync
        from servobus.protocols import myactuator as ma
        from servobus.protocols.myactuator.sim.device import MyActuatorMotor
        from servobus.transports.sim import SimTransport
        from sim._standins import Sniffer

        sniffer = Sniffer()
        bus = sync.Bus(SimTransport(devices=[MyActuatorMotor(1), sniffer]))
        bus.motor("myactuator", 1).speed_control(30.0)
        """
    )
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-W", "default", "-c", script],
        capture_output=True,
        text=True,
        timeout=20,  # the old background loop hung the exit for good
        env={**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])},
    )
    assert done.returncode == 0, done.stderr
    assert time.monotonic() - started < 30  # no hang on the background loop at exit
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert "closed at exit" in done.stderr  # a ResourceWarning says so (shown with -W default)
    assert "stops: 1" in done.stdout

"""The simulator's brownout (servobus.sim.power): silent while the supply is cut, then the family's
power-on state, the same on the C network and on the Python one."""

from __future__ import annotations

from typing import Any

import anyio
import pytest

from servobus.bus import Bus
from servobus.errors import MotorTimeout
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor, RunState
from servobus.sim import virtual
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import Off
from servobus.transports.sim import SimTransport

PATHS = pytest.mark.parametrize("c_path", [True, False], ids=["C network", "Python network"])


def _link(device: Any, c_path: bool) -> SimTransport:
    return SimTransport(devices=[device]) if c_path else SimTransport(network=SimCanNetwork([device]))


@PATHS
def test_an_lk_motor_comes_back_on_idle_with_its_turn_count_lost(c_path: bool) -> None:
    device = LkMotor(1)

    async def main() -> tuple[Any, ...]:
        async with Bus(_link(device, c_path), safe=None) as bus:
            motor = bus.motor(lk.FAMILY, 1)
            kind = motor.codec.model.motor_type
            await motor.request(lk.SpeedControl(speed_dps=720.0, motor_type=kind, current_limit_a=20.0))
            await anyio.sleep(1.5)
            before = await motor.read_multi_turn_angle()
            device.brownout(anyio.current_time(), 0.3)
            with pytest.raises(MotorTimeout):
                await motor.read_status2(timeout_s=0.05)
            await anyio.sleep(0.3)
            after = await motor.read_multi_turn_angle()
            await anyio.sleep(0.5)  # nothing held: no current, it coasts
            return before, after, await motor.read_status2()

    before, after, status = virtual.run(main())
    assert before.angle_deg > 720.0
    assert 0.0 <= after.angle_deg < 360.0
    assert status.current_a == 0.0 and status.speed_dps < 360.0
    assert device.state is RunState.ON and device.held is None
    assert device.counters["brownouts"] == 1 and device.counters["reboots"] == 1
    assert device.counters["unpowered"] >= 1


@PATHS
def test_a_hollow_motor_comes_back_stopped_with_its_position_folded(c_path: bool) -> None:
    device = HollowMotor(1)

    async def main() -> tuple[Any, ...]:
        async with Bus(_link(device, c_path), safe=None) as bus:
            motor = bus.motor(ho.FAMILY, 1)
            await motor.request(ho.SelectMode(mode=ho.ControlMode.VELOCITY))
            await motor.request(ho.Start())
            setpoint = ho.Setpoint(position_deg=0.0, speed_rad_s=12.0, kp=0, kd=0, current_a=3.0)
            before = await motor.request(setpoint)
            await anyio.sleep(1.0)
            before = await motor.request(setpoint)
            device.brownout(anyio.current_time(), 0.3)
            with pytest.raises(MotorTimeout):
                await motor.request(setpoint, timeout_s=0.05)
            await anyio.sleep(0.3)
            return before, await motor.request(setpoint)

    before, after = virtual.run(main())
    assert before.position_deg >= 180.0
    assert -180.0 <= after.position_deg < 180.0
    assert device.enabled is False and device.ctrl_mode is device.power_up_mode
    assert isinstance(device.plant.control, Off)
    assert device.counters["reboots"] == 1


def test_a_brownout_needs_a_positive_finite_duration() -> None:
    device = LkMotor(1)
    for bad in (0.0, -1.0, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="duration_s"):
            device.brownout(0.0, bad)
    assert device.counters["brownouts"] == 0


def test_a_cut_during_a_cut_ends_at_the_later_return() -> None:
    device = LkMotor(1)
    device.brownout(0.0, 0.3)
    device.brownout(0.1, 0.5)
    assert device.power_back_s == pytest.approx(0.6)
    assert not device.powered(0.5)
    assert device.powered(0.6) and device.counters["reboots"] == 1

"""A bridge's Bus with host-side limits: a remote request beyond them gets LimitExceeded, a remote
set-point beyond them is dropped and counted (refused) or goes out clamped; the motor never sees it."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

import anyio
import pytest

import servobus
from _ports import loopback_endpoint as _endpoint
from servobus import LimitExceeded, Limits
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.remote import Bridge, connect
from servobus.remote.security import bridge_config
from servobus.transports.sim import SimTransport
from sim._standins import Sniffer

pytestmark = pytest.mark.anyio

zenoh = pytest.importorskip("zenoh")


async def _until(predicate: object, timeout_s: float = 3.0) -> None:
    with anyio.fail_after(timeout_s):
        while not predicate():  # type: ignore[operator]
            await anyio.sleep(0.005)


@contextlib.asynccontextmanager
async def _serving(endpoint: str, clamp: bool) -> AsyncIterator[tuple[Bridge, servobus.Bus]]:
    limits = Limits(speed_dps=90, clamp=clamp)
    devices = [MyActuatorMotor(1), MyActuatorMotor(2), SNIFFER]
    SNIFFER.seen.clear()
    async with servobus.Bus(SimTransport(devices=devices), limits=limits) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        async with Bridge("n", {"b": (bus, motors)}, config=bridge_config("n", [endpoint])) as bridge:
            yield bridge, bus


SNIFFER = Sniffer()


def _speeds_sent() -> list[float]:
    """The speed of every 0xA2 that reached the wire, in dps (0.01 dps/LSB)."""
    return [
        int.from_bytes(f.data[4:8], "little", signed=True) / 100
        for _, f in SNIFFER.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[0] == 0xA2
    ]


async def test_a_remote_request_beyond_the_limit_is_refused_with_its_reason() -> None:
    endpoint = _endpoint()
    async with _serving(endpoint, clamp=False) as (bridge, bus):
        async with connect("n/b", endpoints=[endpoint]) as remote:
            motor = remote.motor(ma.FAMILY, 1)
            with pytest.raises(
                LimitExceeded, match=r"SpeedControl\.speed_dps=500 is beyond the host limit speed_dps 90"
            ):
                await motor.speed_control(speed_dps=500.0)
            assert isinstance(await motor.speed_control(speed_dps=90.0), ma.StatusReply)
            # a set-point beyond it is dropped at intake, counted: the tick of the other motor goes on
            await remote.cycle(
                [
                    (motor, ma.SpeedControl(speed_dps=-500.0)),
                    (remote.motor(2), ma.SpeedControl(speed_dps=45.0)),
                ],
                valid_for_s=0.5,
            )
            await _until(lambda: bridge.served["b"].counts["limited"] == 2)
            await _until(lambda: bridge.served["b"].counts["applied"] == 1)
        assert bus.metrics().limit_refused == 2
        assert _speeds_sent() and max(abs(v) for v in _speeds_sent()) <= 90.0


async def test_a_clamping_bridge_sends_remote_set_points_clamped() -> None:
    endpoint = _endpoint()
    async with _serving(endpoint, clamp=True) as (bridge, bus):
        async with connect("n/b", endpoints=[endpoint]) as remote:
            motor = remote.motor(ma.FAMILY, 1)
            await remote.cycle([(motor, ma.SpeedControl(speed_dps=1000.0))], valid_for_s=2.0)
            await _until(lambda: bridge.served["b"].counts["applied"] == 1)
            await anyio.sleep(0.5)
            local = bus.motor(ma.FAMILY, 1)
            await _until(lambda: abs(local.state.speed_dps - 90.0) < 3.0)  # type: ignore[union-attr]
            assert bridge.served["b"].counts["limited"] == 0 and bus.metrics().limit_clamped >= 1
        assert 90.0 in _speeds_sent() and max(_speeds_sent()) == 90.0

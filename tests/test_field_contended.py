"""A second controller on the bus (issue [field], case 3): another host sends its own requests to
our motors at 500 Hz, the motors answer it on the identifier and DATA[0] they answer us on. Its
replies must never be taken as ours: the two hosts command different speeds (ours +100 dps, the
other -50 dps) and a device model that puts the set-point of the request it answers into its reply
tells which request a reply is for. On the project's simulator in virtual time, plus the scheduler's
rules without I/O and one run through python-can's ``virtual`` bus.
"""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any

import pytest

from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import Received
from servobus.sim import virtual
from servobus.sim.device import Emission
from servobus.sim.otherhost import OtherHost
from servobus.transports.sim import SimTransport

OURS_DPS, THEIRS_DPS = 100.0, -50.0
MOTORS = (1, 2, 3)


class _SetpointMotor(MyActuatorMotor):
    """A motor whose 0xA2 reply carries, in its speed field, the set-point of the request it answers
    (whoever sent it), so a test can tell whose request a reply is for."""

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        out = super().receive(frame, now_s)
        if frame.data[:1] != b"\xa2":
            return out
        dps = int.from_bytes(frame.data[4:8], "little", signed=True) // 100
        tagged = []
        for emission in out:
            data = emission.frame.data
            if data[:1] == b"\xa2":
                data = data[:4] + dps.to_bytes(2, "little", signed=True) + data[6:]
                emission = Emission(emission.ready_s, dataclasses.replace(emission.frame, data=data))
            tagged.append(emission)
        return tagged


def _run(
    *, other: bool, hz: float = 200.0, seconds: float = 2.0, seed: int = 1
) -> tuple[float, int, int, Any]:
    """Our loop of SpeedControl(+100) at ``hz`` on three motors, with (or without) another host
    commanding -50 dps at 500 Hz: (ticks per second, replies taken, of which another host's, bus)."""
    devices: list[Any] = [_SetpointMotor(i) for i in MOTORS]
    if other:
        codecs = [ma.FAMILY.bind(i) for i in MOTORS]
        devices.append(
            OtherHost.commanding(codecs, ma.SpeedControl(speed_dps=THEIRS_DPS), rate_hz=500, seed=seed)
        )
    checked = [0, 0]

    async def main() -> tuple[float, Any]:
        async with Bus(SimTransport(devices=devices), safe=None) as bus:
            receive = bus.scheduler.receive

            def watch(frame: Frame, now: float) -> Received:
                got = receive(frame, now)
                if got.request is not None and isinstance(got.reply, ma.StatusReply):
                    checked[0] += 1
                    if got.reply.speed_dps != OURS_DPS:
                        checked[1] += 1
                return got

            bus.scheduler.receive = watch  # type: ignore[method-assign]
            batch = [(bus.motor("myactuator", i), ma.SpeedControl(speed_dps=OURS_DPS)) for i in MOTORS]
            loop = asyncio.get_running_loop()
            start = loop.time()
            ticks = 0
            async for _ in bus.ticks(hz, spin_s=0.0):
                if loop.time() - start >= seconds:
                    break
                await bus.cycle(batch)
                ticks += 1
            return ticks / (loop.time() - start), bus

    rate, bus = virtual.run(main())
    return rate, checked[0], checked[1], bus


@pytest.mark.parametrize("seed", [1, 2])
def test_a_second_controller_s_replies_are_never_taken_as_ours(
    seed: int, caplog: pytest.LogCaptureFixture
) -> None:
    clean_rate, _, _, _ = _run(other=False)
    with caplog.at_level("WARNING", logger="servobus.bus"):
        rate, taken, wrong, bus = _run(other=True, seed=seed)
    assert wrong == 0, f"{wrong} of {taken} replies taken were the other host's"
    assert taken >= 0.9 * 2.0 * 200 * len(MOTORS), taken
    assert rate >= 0.95 * clean_rate, (rate, clean_rate)
    for i in MOTORS:
        metrics = bus.motor("myactuator", i).metrics()
        assert metrics.contended > 0 and metrics.foreign_requests >= metrics.contended, metrics
    warnings = [r.getMessage() for r in caplog.records if "another host" in r.getMessage()]
    assert len(warnings) == len(MOTORS), warnings  # once per motor
    assert "0x141" in " ".join(warnings) and "per second" in warnings[0]

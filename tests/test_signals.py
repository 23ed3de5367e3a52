"""servobus.signals.stop_on: SIGTERM to a real process running a Bus still sends the safe stop.

The parent runs the simulator (an SLCAN adapter on a pty, one MyActuator motor); a child process
opens it with SlcanTransport, drives the motor at 100 Hz inside ``with stop_on(SIGTERM)`` and gets
SIGTERM. The simulated motor must see the stop frame, and the child exit with status 143.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import textwrap

import pytest

from _serving import serving
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_slcan
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from sim._standins import Sniffer

CHILD = textwrap.dedent(
    """
    import asyncio, signal, sys
    from servobus import Bus
    from servobus.signals import stop_on
    from servobus.transports import SlcanTransport

    async def main(port: str, protect: bool) -> None:
        transport = SlcanTransport(port, bitrate=1_000_000)
        async with transport:
            if protect:
                with stop_on(signal.SIGTERM):
                    await drive(transport)
            else:
                await drive(transport)

    async def drive(transport) -> None:
        async with Bus(transport) as bus:
            motor = bus.motor("myactuator", 1)
            await motor.speed_control(speed_dps=90, timeout_s=0.5)
            print("ready", flush=True)
            while True:
                await motor.speed_control(speed_dps=90, timeout_s=0.5)
                await asyncio.sleep(0.01)

    asyncio.run(main(sys.argv[1], sys.argv[2] == "1"))
    """
)


async def _run_child(protect: bool) -> tuple[int, list[int]]:
    port = PtyPort()
    motor = MyActuatorMotor(1)
    sniffer = Sniffer()
    network = SimCanNetwork([motor, sniffer])
    try:
        async with serving(serve_slcan(network, port)):
            child = await asyncio.create_subprocess_exec(
                sys.executable,
                "-c",
                CHILD,
                port.path,
                "1" if protect else "0",
                stdout=asyncio.subprocess.PIPE,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
            assert child.stdout is not None
            line = await asyncio.wait_for(child.stdout.readline(), 20)
            assert line.strip() == b"ready", line
            await asyncio.sleep(0.1)
            child.send_signal(signal.SIGTERM)
            code = await asyncio.wait_for(child.wait(), 10)
            await asyncio.sleep(0.1)  # the last frames reach the simulated bus
    finally:
        port.close()
    codes = [frame.data[0] for _, frame in sniffer.seen if frame.arbitration_id == 0x141]
    return code, codes


@pytest.mark.asyncio
async def test_sigterm_with_stop_on_sends_the_safe_stop_and_exits_143() -> None:
    code, codes = await _run_child(protect=True)
    assert code == 128 + signal.SIGTERM, code
    assert ma.SpeedControl.CODE in codes
    assert codes[-1] == ma.MotorStop.CODE, [hex(c) for c in codes[-5:]]


@pytest.mark.asyncio
async def test_sigterm_without_it_kills_the_process_and_no_stop_is_sent() -> None:
    """The reason the helper exists: the Bus alone takes no signals, so the default action ends the
    process where it stands."""
    code, codes = await _run_child(protect=False)
    assert code == -signal.SIGTERM
    assert ma.MotorStop.CODE not in codes


def test_stop_on_needs_a_signal() -> None:
    from servobus.signals import stop_on

    with pytest.raises(ValueError, match="at least one signal"):
        stop_on()

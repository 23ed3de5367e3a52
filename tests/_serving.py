"""Run a simulator attachment in the background for the length of a ``with`` block."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Coroutine
from typing import Any


@contextlib.asynccontextmanager
async def serving(coro: Coroutine[Any, Any, None]) -> AsyncIterator[asyncio.Task[None]]:
    """Start ``coro`` as a task, cancel it on exit; an exception it died of is re-raised there."""
    task = asyncio.ensure_future(coro)
    try:
        yield task
    finally:
        if not task.done():
            task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def sigterm_a_child(script: str, *args: str) -> tuple[int, list[int], Any]:
    """Run ``script`` (``python -c``) with the pty of a simulated SLCAN adapter and ``args``; once it
    prints ``ready`` (it drives motor 1), send it SIGTERM: (its exit status, the command bytes motor 1
    was sent, in order, the simulated motor)."""
    import os
    import signal
    import sys

    from servobus.protocols.myactuator.sim.device import MyActuatorMotor
    from servobus.sim.attach import serve_slcan
    from servobus.sim.network import SimCanNetwork
    from servobus.sim.pty import PtyPort
    from sim._standins import Sniffer

    port = PtyPort()
    motor = MyActuatorMotor(1)
    sniffer = Sniffer()
    network = SimCanNetwork([motor, sniffer])
    try:
        async with serving(serve_slcan(network, port)):
            child = await asyncio.create_subprocess_exec(
                sys.executable,
                "-c",
                script,
                port.path,
                *args,
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
    return code, codes, motor

"""servobus.signals.stop_on: SIGTERM to a real process running a Bus still sends the safe stop, on
asyncio and on trio.

The parent runs the simulator (an SLCAN adapter on a pty, one MyActuator motor); a child process
opens it with SlcanTransport, drives the motor at 100 Hz inside ``async with stop_on(SIGTERM)`` under
``anyio.run(..., backend=...)`` and gets SIGTERM. The simulated motor must see the stop frame, and the
child exit with status 143. The block's own behaviour (cancelled, shielded clean-up run, a second
signal ignored, exceptions unwrapped, handlers put back) is checked without a Bus, on both backends.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import anyio
import pytest

from _backends import BACKENDS
from _serving import sigterm_a_child
from servobus.protocols import myactuator as ma
from servobus.signals import stop_on

CHILD = textwrap.dedent(
    """
    import signal, sys
    import anyio
    from servobus import Bus
    from servobus.signals import stop_on
    from servobus.transports import SlcanTransport

    async def main(port: str, protect: bool) -> None:
        transport = SlcanTransport(port, bitrate=1_000_000)
        async with transport:
            if protect:
                async with stop_on(signal.SIGTERM):
                    await drive(transport, True)
            else:
                await drive(transport, False)

    async def drive(transport, sigterm: bool) -> None:
        async with Bus(transport, sigterm=sigterm) as bus:
            motor = bus.motor("myactuator", 1)
            await motor.speed_control(speed_dps=90, timeout_s=0.5)
            print("ready", flush=True)
            while True:
                await motor.speed_control(speed_dps=90, timeout_s=0.5)
                await anyio.sleep(0.01)

    anyio.run(main, sys.argv[1], sys.argv[2] == "1", backend=sys.argv[3])
    """
)


async def _run_child(protect: bool, backend: str) -> tuple[int, list[int]]:
    code, codes, _ = await sigterm_a_child(CHILD, "1" if protect else "0", backend)
    return code, codes


@pytest.mark.asyncio
@pytest.mark.parametrize("backend", BACKENDS)
async def test_sigterm_with_stop_on_sends_the_safe_stop_and_exits_143(backend: str) -> None:
    """A Bus left by SIGTERM stops its motors, the child on asyncio and on trio."""
    code, codes = await _run_child(protect=True, backend=backend)
    assert code == 128 + signal.SIGTERM, code
    assert ma.SpeedControl.CODE in codes
    assert codes[-1] == ma.MotorStop.CODE, [hex(c) for c in codes[-5:]]


@pytest.mark.asyncio
async def test_sigterm_without_it_kills_the_process_and_no_stop_is_sent() -> None:
    """Neither the helper nor the Bus's own default (``sigterm=False``): the default action ends
    the process where it stands."""
    code, codes = await _run_child(protect=False, backend="asyncio")
    assert code == -signal.SIGTERM
    assert ma.MotorStop.CODE not in codes


BLOCK = textwrap.dedent(
    """
    import os, signal, sys
    import anyio
    from servobus.signals import stop_on

    async def main() -> None:
        before = signal.getsignal(signal.SIGTERM)
        try:
            async with stop_on(signal.SIGTERM, signal.SIGINT) as stop:
                assert stop.taking_signals
                try:
                    await anyio.sleep(0.05)
                    os.kill(os.getpid(), signal.SIGTERM)
                    await anyio.sleep(5)
                    print("not cancelled")
                finally:
                    with anyio.CancelScope(shield=True):  # a safe stop, as the Bus's
                        os.kill(os.getpid(), signal.SIGTERM)  # a second signal: ignored
                        await anyio.sleep(0.1)
                        print("clean-up ran", stop.received.name, flush=True)
        finally:
            print("handler put back", signal.getsignal(signal.SIGTERM) == before, flush=True)

    anyio.run(main, backend=sys.argv[1])
    """
)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_signal_cancels_the_block_runs_its_clean_up_and_exits_143(backend: str) -> None:
    done = subprocess.run([sys.executable, "-c", BLOCK, backend], capture_output=True, text=True, timeout=60)
    assert done.returncode == 143, done.stderr
    assert done.stdout.splitlines() == ["clean-up ran SIGTERM", "handler put back True"], done.stdout


@pytest.mark.anyio
async def test_an_exception_from_the_block_comes_out_as_raised() -> None:
    with pytest.raises(KeyError):
        async with stop_on(signal.SIGTERM):
            raise KeyError("not wrapped in a group")


@pytest.mark.anyio
async def test_an_outer_cancellation_passes_through_and_the_handler_is_put_back() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with anyio.move_on_after(0.05) as outer:
        async with stop_on(signal.SIGTERM) as stop:
            await anyio.sleep(5)
    assert outer.cancelled_caught and stop.received is None
    assert signal.getsignal(signal.SIGTERM) == before


@pytest.mark.anyio
async def test_without_exit_the_block_ends_quietly_and_a_scope_narrows_what_is_cancelled() -> None:
    after: list[str] = []
    async with stop_on(signal.SIGUSR1, exit=False) as stop:
        with stop.scope() as loop:
            os.kill(os.getpid(), signal.SIGUSR1)
            await anyio.sleep(5)
        after.append("the code after the loop ran")
    assert loop.cancelled_caught and stop.received == signal.SIGUSR1 and stop.stopped
    assert after == ["the code after the loop ran"]


def test_stop_on_needs_a_signal_and_async_with() -> None:
    with pytest.raises(ValueError, match="at least one signal"):
        stop_on()
    with pytest.raises(TypeError, match="async with"), stop_on(signal.SIGTERM):
        pass

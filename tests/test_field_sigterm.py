"""[field] case 6: a plain script killed by SIGTERM (systemd, ``docker stop``, ``timeout``) stops its
motor. While a Bus is open in the main thread and SIGTERM has Python's default disposition, SIGTERM
does what Ctrl-C does: the block is left, the safe stop goes out, the process exits 143.

A real child process drives a simulated MyActuator motor at 100 Hz through SLCAN on a pty, in a plain
``async with Bus(...)`` (no :func:`~servobus.signals.stop_on`), on asyncio and on trio; the parent,
which runs the simulator, sends it SIGTERM and looks at the motor. The handler's bookkeeping (taken
once, put back when the last Bus closes, a program's own handler left alone, the opt-out) is checked
in this process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading

import anyio
import pytest

from _backends import BACKENDS
from _serving import sigterm_a_child
from servobus import Bus
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.plant import PositionControl
from servobus.transports.sim import SimTransport

SCRIPT = textwrap.dedent(
    """
    import sys
    import anyio
    from servobus import Bus
    from servobus.transports import SlcanTransport

    async def main(port: str, sigterm: bool) -> None:
        options = {} if sigterm else {"sigterm": False}  # (the default: a plain script)
        async with Bus(SlcanTransport(port, bitrate=1_000_000), **options) as bus:
            motor = bus.motor("myactuator", 1)
            await motor.speed_control(speed_dps=120, timeout_s=0.5)
            print("ready", flush=True)
            while True:
                await motor.speed_control(speed_dps=120, timeout_s=0.5)
                await anyio.sleep(0.01)

    anyio.run(main, sys.argv[1], sys.argv[2] == "1", backend=sys.argv[3])
    """
)


async def _terminated(backend: str, *, sigterm: bool = True) -> tuple[int, list[int], MyActuatorMotor]:
    """The script run against a simulated motor on a pty, sent SIGTERM once it drives the motor:
    (its exit status, the command bytes the motor was sent, the motor)."""
    return await sigterm_a_child(SCRIPT, "1" if sigterm else "0", backend)


@pytest.mark.asyncio
@pytest.mark.parametrize("backend", BACKENDS)
async def test_a_plain_bus_script_sent_sigterm_stops_its_motor_and_exits_143(backend: str) -> None:
    code, codes, motor = await _terminated(backend)
    assert code == 143, code  # (on main: -15, killed where it stood)
    assert ma.SpeedControl.CODE in codes
    assert codes[-1] == ma.MotorStop.CODE, [hex(c) for c in codes[-5:]]
    assert isinstance(motor.plant.control, PositionControl)  # stopped: holding, no longer at 120 dps


SYNC_SCRIPT = textwrap.dedent(
    """
    import sys
    from servobus import sync
    from servobus.transports import SlcanTransport

    options = {} if sys.argv[2] == "1" else {"sigterm": False}
    with sync.Bus(SlcanTransport(sys.argv[1], bitrate=1_000_000), **options) as bus:
        motor = bus.motor("myactuator", 1)
        motor.speed_control(speed_dps=120, timeout_s=0.5)
        print("ready", flush=True)
        for tick in bus.ticks(100):
            motor.speed_control(speed_dps=120, timeout_s=0.5)
    """
)


@pytest.mark.asyncio
async def test_a_plain_sync_bus_script_sent_sigterm_stops_its_motor_and_exits_143() -> None:
    """servobus.sync.Bus runs its loop in a thread of its own: the signal is raised in the main
    thread as SystemExit(143), which leaves the ``with`` block through the safe stop."""
    code, codes, motor = await sigterm_a_child(SYNC_SCRIPT, "1")
    assert code == 143, code
    assert codes[-1] == ma.MotorStop.CODE, [hex(c) for c in codes[-5:]]
    assert isinstance(motor.plant.control, PositionControl)
    code, codes, _ = await sigterm_a_child(SYNC_SCRIPT, "0")  # the opt-out
    assert code == -signal.SIGTERM and ma.MotorStop.CODE not in codes


@pytest.mark.asyncio
async def test_with_sigterm_false_the_bus_takes_no_signal() -> None:
    """The opt-out: Python's default stays, SIGTERM kills the process where it stands."""
    code, codes, _ = await _terminated("asyncio", sigterm=False)
    assert code == -signal.SIGTERM
    assert ma.MotorStop.CODE not in codes


def _transport() -> SimTransport:
    return SimTransport(devices=[MyActuatorMotor(1)], name="sim")


@pytest.mark.anyio
async def test_taken_once_for_nested_buses_and_put_back_when_the_last_closes() -> None:
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    async with Bus(_transport()):
        handler = signal.getsignal(signal.SIGTERM)
        assert callable(handler)
        async with Bus(_transport()):
            assert signal.getsignal(signal.SIGTERM) == handler  # one handler for both
        assert signal.getsignal(signal.SIGTERM) == handler  # the outer one is still open
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


@pytest.mark.anyio
async def test_a_handler_of_the_program_is_left_alone() -> None:
    seen: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        mine = signal.getsignal(signal.SIGTERM)
        async with Bus(_transport()) as bus:
            bus.motor("myactuator", 1)
            assert signal.getsignal(signal.SIGTERM) is mine
            os.kill(os.getpid(), signal.SIGTERM)
            await anyio.sleep(0.05)  # not cancelled: the program's handler took it
        assert seen == [signal.SIGTERM] and signal.getsignal(signal.SIGTERM) is mine
    finally:
        signal.signal(signal.SIGTERM, previous)


@pytest.mark.anyio
async def test_sigterm_false_and_other_threads_take_nothing() -> None:
    async with Bus(_transport(), sigterm=False):
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    seen: list[object] = []

    def in_a_thread() -> None:
        async def opened() -> None:
            async with Bus(_transport()):
                seen.append(signal.getsignal(signal.SIGTERM))

        anyio.run(opened)

    thread = threading.Thread(target=in_a_thread)
    thread.start()
    thread.join()
    assert seen == [signal.SIG_DFL]


@pytest.mark.anyio
async def test_sigterm_in_process_leaves_both_nested_blocks_through_their_stops_and_exits_once() -> None:
    """Both blocks are cancelled (nothing after the inner one runs), each leaves through its safe
    stop, and only the outer Bus (the oldest) raises SystemExit(143); the default is back."""
    outer_motor, inner_motor = MyActuatorMotor(1), MyActuatorMotor(2)
    after_inner: list[str] = []
    with pytest.raises(SystemExit) as exited:
        async with Bus(SimTransport(devices=[outer_motor], name="outer")) as outer:
            await outer.motor("myactuator", 1).speed_control(speed_dps=120)
            async with Bus(SimTransport(devices=[inner_motor], name="inner")) as inner:
                await inner.motor("myactuator", 2).speed_control(speed_dps=120)
                os.kill(os.getpid(), signal.SIGTERM)
                await anyio.sleep(5)
            after_inner.append("ran")  # (not: the outer block is cancelled too)
    assert exited.value.code == 143
    assert after_inner == []
    assert isinstance(outer_motor.plant.control, PositionControl)
    assert isinstance(inner_motor.plant.control, PositionControl)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_the_script_exits_143_with_no_bus_left_running() -> None:
    """The same without a pty, the signal sent by the script itself: it exits 143, its motor stopped."""
    script = textwrap.dedent(
        """
        import os, signal, anyio
        from servobus import Bus
        from servobus.protocols.myactuator.sim.device import MyActuatorMotor
        from servobus.transports.sim import SimTransport

        async def main() -> None:
            device = MyActuatorMotor(1)
            try:
                async with Bus(SimTransport(devices=[device], name="sim")) as bus:
                    motor = bus.motor("myactuator", 1)
                    for tick in range(1000):
                        await motor.speed_control(speed_dps=120)
                        if tick == 3:
                            os.kill(os.getpid(), signal.SIGTERM)
                        await anyio.sleep(0.01)
            finally:
                print(type(device.plant.control).__name__, flush=True)

        anyio.run(main)
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 143, done.stderr
    assert done.stdout.split() == ["PositionControl"]


@pytest.mark.anyio
async def test_tasks_inside_the_block_are_cancelled_and_both_motors_stop() -> None:
    """The usual shape: the Bus in the main task, a task per motor inside its block."""
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    with pytest.raises(SystemExit) as exited:
        async with Bus(SimTransport(devices=devices, name="sim")) as bus:

            async def drive(motor_id: int) -> None:
                motor = bus.motor("myactuator", motor_id)
                while True:
                    await motor.speed_control(speed_dps=120)
                    await anyio.sleep(0.01)

            async with anyio.create_task_group() as group:
                group.start_soon(drive, 1)
                group.start_soon(drive, 2)
                await anyio.sleep(0.05)
                os.kill(os.getpid(), signal.SIGTERM)
    assert exited.value.code == 143
    assert all(isinstance(d.plant.control, PositionControl) for d in devices)


@pytest.mark.anyio
async def test_a_second_sigterm_during_the_safe_stop_is_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    """The handler is let go only after the safe stop: a second SIGTERM (an impatient operator, a
    script that sends two) does not kill the process before the stop went out."""
    import servobus.bus.core as bus_module

    safe_stop = bus_module.safe_stop

    async def signalled_again(bus: Bus) -> None:
        os.kill(os.getpid(), signal.SIGTERM)
        await safe_stop(bus)

    monkeypatch.setattr(bus_module, "safe_stop", signalled_again)
    device = MyActuatorMotor(1)
    with pytest.raises(SystemExit) as exited:
        async with Bus(SimTransport(devices=[device], name="sim")) as bus:
            await bus.motor("myactuator", 1).speed_control(speed_dps=120)
            os.kill(os.getpid(), signal.SIGTERM)
            await anyio.sleep(5)
    assert exited.value.code == 143
    assert isinstance(device.plant.control, PositionControl)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL

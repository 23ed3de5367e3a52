"""SIGTERM (systemd, ``docker stop``, ``timeout``) ends a command that drives motors as Ctrl-C does:
the Bus's safe stop goes out, the line names the motors it went to, and the exit code is 143
(128 + SIGTERM) where Ctrl-C's is 130. The handler is the loop's, only while the command runs."""

from __future__ import annotations

import os
import select
import signal
import subprocess
from collections.abc import Callable
from typing import IO, Any

import pytest

from cli._bus_cli import SERVOBUS, Devices, keep_devices, run
from servobus.bus import Bus
from servobus.sim.plant import PositionControl


def _line(stream: IO[str], timeout_s: float) -> str:
    """The next line of ``stream``, or "" when none came within ``timeout_s``."""
    ready, _, _ = select.select([stream], [], [], timeout_s)
    return stream.readline() if ready else ""


def _signalled(args: list[str], signum: signal.Signals) -> tuple[int, str, list[str]]:
    """``servobus ARGS`` in its own process, sent ``signum`` once it says (on stderr) that the motors
    are being driven (or after 5 s without that line): (exit code, that line, the stderr lines after
    it)."""
    process = subprocess.Popen(
        [*SERVOBUS, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # (not ignored in a background job)
    )
    try:
        assert process.stderr is not None
        running = _line(process.stderr, timeout_s=5)
        process.send_signal(signum)
        _, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return process.returncode, running, err.strip().splitlines()


@pytest.mark.parametrize(
    ("signum", "code", "said"),
    [(signal.SIGTERM, 143, "interrupted by SIGTERM"), (signal.SIGINT, 130, "interrupted")],
)
def test_a_signal_during_a_set_point_stops_both_motors_and_says_so(
    signum: signal.Signals, code: int, said: str
) -> None:
    got, running, err = _signalled(["speed", "--sim", "2", "--speed-dps", "45", "--json"], signum)
    assert got == code and err[-1] == f"servobus: {said}; stop sent to myactuator motors 1, 2 on sim", err
    assert running.startswith("speed: myactuator motors 1, 2 driven at 50 Hz"), running


@pytest.mark.parametrize(
    "args",
    [
        ["move", "--sim", "2", "--angle-deg", "3000", "--max-speed-dps", "10"],
        ["torque", "--sim", "2", "--current-a", "0.2"],
        ["mit", "--sim", "2", "--position-rad", "1", "--kp", "5", "--kd", "1"],
        ["move", "--family", "lk", "--sim", "2", "--angle-deg", "3000", "--max-speed-dps", "10"],
    ],
    ids=["move", "torque", "mit", "lk move"],
)
def test_sigterm_stops_every_set_point_command(args: list[str]) -> None:
    got, running, err = _signalled([*args, "--json"], signal.SIGTERM)
    family = "lk" if "lk" in args else "myactuator"
    assert got == 143, err
    assert err[-1] == f"servobus: interrupted by SIGTERM; stop sent to {family} motors 1, 2 on sim", err
    assert "motors 1, 2 driven" in running, running


def test_sigterm_in_process_stops_the_motors_and_gives_the_handler_back(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM while the set-points go out (on the third tick): the simulated motors end stopped
    (holding, 0x81), the command ends with 143, and the process's own handler is back afterwards,
    never called while the command ran."""
    devices: Devices = keep_devices(monkeypatch)
    cycle: Callable[..., Any] = Bus.cycle
    ticks = 0

    async def cycle_then_terminate(self: Bus, *args: Any, **kwargs: Any) -> Any:
        nonlocal ticks
        ticks += 1
        if ticks == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return await cycle(self, *args, **kwargs)

    monkeypatch.setattr(Bus, "cycle", cycle_then_terminate)
    seen: list[int] = []

    def mine(signum: int, frame: Any) -> None:
        seen.append(signum)

    previous = signal.signal(signal.SIGTERM, mine)
    try:
        _, err = run(capsys, ["speed", "--sim", "2", "--speed-dps", "45", "--duration", "2"], code=143)
        handler = signal.getsignal(signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert err.strip().splitlines()[-1] == (
        "servobus: interrupted by SIGTERM; stop sent to myactuator motors 1, 2 on sim"
    )
    assert all(isinstance(m.plant.control, PositionControl) for m in devices.last)  # stopped, holding
    assert seen == [] and handler is mine


def test_sigterm_during_reads_claims_no_stop() -> None:
    """monitor commands no motor: SIGTERM ends it with 143 and a line that claims no stop."""
    args = [*SERVOBUS, "monitor", "--sim", "1", "--json"]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None
    assert _line(process.stdout, timeout_s=5).startswith("{")  # a sample: the loop runs
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=20)
    assert process.returncode == 143 and err.strip().splitlines()[-1] == "servobus: interrupted by SIGTERM"

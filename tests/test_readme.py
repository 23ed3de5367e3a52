"""The README's Bus examples run as written: the quick start on simulated motors, and the service."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import anyio

from servobus.sim.devices.myactuator import MyActuatorMotor
from servobus.sim.plant import PositionControl
from servobus.transports.sim import SimTransport

README = Path(__file__).resolve().parents[1] / "README.md"


def _block(marker: str) -> str:
    """The ```python block that follows the ``<!-- marker: ... -->`` comment."""
    match = re.search(rf"<!-- {marker}:[^\n]*-->\n```python\n(.*?)```", README.read_text(), re.S)
    assert match, f"README has no python block after a <!-- {marker}: ... --> comment"
    return match.group(1)


def test_the_quick_start_drives_simulated_motors_through_bus_and_motor() -> None:
    code = _block("quickstart")
    assert not re.search(r"0x[0-9A-Fa-f]{3}\b", code), "the quick start names a raw CAN id"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("motor 1: ") and lines[1] == "last tick: 32/32 replies", done.stdout
    assert re.fullmatch(r"broadcast: 32 replies; latency p50 \d+\.\d\d ms", lines[2]), done.stdout


def test_the_service_example_runs_in_a_task_group_and_stops_its_motors() -> None:
    namespace: dict[str, Any] = {}
    exec(compile(_block("service"), "README service", "exec"), namespace)
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]

    async def main() -> None:
        with anyio.move_on_after(1.3):  # the service runs until its host cancels it
            await namespace["serve"](SimTransport(devices=devices))

    anyio.run(main)
    for device in devices:  # they ran at 30 dps; cancelled, the safe stop (0x81) made each hold
        assert isinstance(device.control, PositionControl), device.control

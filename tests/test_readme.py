"""The README runs as written: every ```python block as a script (those that need hardware on simulated
devices behind ptys, their device paths swapped), every ```pycon block as a doctest; the quick start,
the service and the signal example also for what they do, on asyncio and on trio; the CLI section shows
every command and the Dependencies section names every runtime dependency."""

from __future__ import annotations

import contextlib
import doctest
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

import anyio
import click
import pytest

from _adapters import HARDWARE
from _adapters import simulated as _simulated
from _backends import BACKENDS
from servobus.cli import cli
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.plant import PositionControl, SpeedControl
from servobus.transports.sim import SimTransport

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text(encoding="utf-8")


def _fenced(language: str) -> list[tuple[int, str]]:
    """Every ```LANGUAGE block of the README: (the line its code starts on, its code)."""
    return [
        (TEXT.count("\n", 0, match.start(1)) + 1, match.group(1))
        for match in re.finditer(rf"^```{language}\n(.*?)^```$", TEXT, re.S | re.M)
    ]


PYTHON = _fenced("python")
PYCON = _fenced("pycon")


def _block(marker: str) -> str:
    """The ```python block that follows the ``<!-- marker: ... -->`` comment."""
    match = re.search(rf"<!-- {marker}:[^\n]*-->\n```python\n(.*?)```", TEXT, re.S)
    assert match, f"README has no python block after a <!-- {marker}: ... --> comment"
    return match.group(1)


def _section(title: str) -> str:
    """The README's ``## TITLE`` section, up to the next ``## ``."""
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", TEXT, re.S | re.M)
    assert match, f"README has no '## {title}' section"
    return match.group(1)


def test_the_readme_has_its_blocks() -> None:
    assert len(PYTHON) >= 5 and len(PYCON) >= 2, (len(PYTHON), len(PYCON))


def test_a_block_that_names_a_device_says_it_needs_hardware_in_its_first_line() -> None:
    for line, code in PYTHON:
        if "/dev/" in code:
            assert code.startswith(HARDWARE), f"README.md:{line} names a device but not '{HARDWARE}'"


@pytest.mark.parametrize(("line", "code"), PYTHON, ids=[f"README.md:{line}" for line, _ in PYTHON])
def test_every_python_block_runs_as_written(line: int, code: str, tmp_path: Path) -> None:
    """As a user would: the block alone, as a script, in a fresh interpreter (in an empty folder)."""
    script = tmp_path / "block.py"
    hardware = code.startswith(HARDWARE)
    with _simulated(code, tmp_path) if hardware else contextlib.nullcontext(code) as runnable:
        script.write_text(runnable, encoding="utf-8")
        done = subprocess.run(
            [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=120
        )
    assert done.returncode == 0, f"README.md:{line}\n{done.stderr}"


@pytest.mark.parametrize(("line", "text"), PYCON, ids=[f"README.md:{line}" for line, _ in PYCON])
def test_every_pycon_block_passes_as_a_doctest(line: int, text: str) -> None:
    test = doctest.DocTestParser().get_doctest(text, {}, f"README.md:{line}", str(README), line - 1)
    assert test.examples
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    runner.run(test, out=report.append, clear_globs=True)
    assert runner.failures == 0, "".join(report)


def _on(backend: str, code: str) -> str:
    """``code`` with its ``anyio.run(main)`` line (at the start of a line) run on ``backend``."""
    run = re.compile(r"^anyio\.run\(main\)", re.M)
    assert len(run.findall(code)) == 1, "the block ends with one anyio.run(main)"
    return run.sub(f"anyio.run(main, backend={backend!r})", code)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_quick_start_drives_simulated_motors_through_bus_and_motor(backend: str) -> None:
    code = _block("quickstart")
    assert not re.search(r"0x[0-9A-Fa-f]{3}\b", code), "the quick start names a raw CAN id"
    done = subprocess.run(
        [sys.executable, "-c", _on(backend, code)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("motor 1: ") and lines[1] == "cycle: 32/32 replies", done.stdout
    assert re.fullmatch(r"broadcast: 32 replies; latency p50 \d+\.\d\d ms", lines[2]), done.stdout
    # the Loop's last state: motor 1 turned back, the reply to a command of the last ticks
    assert re.fullmatch(r"loop: motor 1 at -90\.0 dps, the reply to tick 4[5-8] of 49", lines[3]), done.stdout


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_service_example_runs_in_a_task_group_and_stops_its_motors(backend: str) -> None:
    namespace: dict[str, Any] = {}
    exec(compile(_block("service"), "README service", "exec"), namespace)
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]

    async def main() -> None:
        with anyio.move_on_after(1.3):  # the service runs until its host cancels it
            await namespace["serve"](SimTransport(devices=devices))

    anyio.run(main, backend=backend)
    for device in devices:  # they ran at 30 dps; cancelled, the safe stop (0x81) made each hold
        assert isinstance(device.control, PositionControl), device.control


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_signal_example_stops_its_motor_and_exits_143_on_sigterm(backend: str) -> None:
    namespace: dict[str, Any] = {}
    exec(compile(_block("signals"), "README signals", "exec"), namespace)
    device = MyActuatorMotor(1)

    ended = threading.Event()

    def terminate_once_it_turns() -> None:  # (a thread: the signal comes once the block drives the motor)
        until = time.monotonic() + 30
        while not isinstance(device.control, SpeedControl) and time.monotonic() < until:
            if ended.wait(0.01):
                return  # the block ended on its own (an error): no signal for pytest itself
        time.sleep(0.2)
        if not ended.is_set():
            os.kill(os.getpid(), signal.SIGTERM)

    killer = threading.Thread(target=terminate_once_it_turns, daemon=True)
    killer.start()
    try:
        with pytest.raises(SystemExit) as stopped:
            anyio.run(namespace["main"], SimTransport(devices=[device]), backend=backend)
    finally:
        ended.set()
        killer.join()
    assert stopped.value.code == 143
    assert isinstance(device.control, PositionControl), device.control  # it turned; the stop made it hold


def test_the_command_line_section_shows_every_command() -> None:
    commands = cli.list_commands(click.Context(cli))
    shown = set(re.findall(r"^servobus ([\w-]+)", _section("Command line"), re.M))
    assert len(commands) >= 22 and not set(commands) - shown, sorted(set(commands) - shown)


def test_the_dependencies_section_names_every_runtime_dependency() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    names = [re.split(r"[\s<>=!~;\[]", spec)[0] for spec in project["dependencies"]]
    section = _section("Dependencies").lower()
    assert len(names) >= 6 and not [n for n in names if n.lower() not in section], names

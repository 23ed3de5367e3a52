"""Simulated adapters for the examples that name a device (the README's and the docs pages'): MyActuator
motors served by ``python -m servobus.sim`` behind a pty linked in the example's folder, and the
example's device paths swapped for those links."""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from pathlib import Path

from cli._bus_cli import pty_simulators

#: how a block that needs hardware starts (its first line), naming each adapter and its path
HARDWARE = "# needs hardware:"
#: "an SLCAN adapter on /dev/ttyACM0", "an RS485 adapter on /dev/ttyUSB0" in that first line
ADAPTER = re.compile(r"\b(SLCAN|RS485) adapter on (/dev/\S+?)(?=[\s,;]|$)")


@contextlib.contextmanager
def simulated(
    code: str, folder: Path, adapters: list[tuple[str, str]] | None = None, motors: int = 1
) -> Iterator[str]:
    """The adapters ``adapters`` names (default: those a hardware block's first line names) simulated,
    ``motors`` MyActuator motors (ids 1..) behind each, on a pty linked in ``folder``; the code with
    their device paths swapped for those links."""
    if adapters is None:
        adapters = ADAPTER.findall(code.splitlines()[0])
        assert adapters, f"{code.splitlines()[0]!r} names no 'SLCAN|RS485 adapter on /dev/...'"
    with pty_simulators() as start:
        for kind, device in adapters:
            link = folder / Path(device).name
            mode = "--slcan" if kind == "SLCAN" else "--rs485"
            start("--family", "myactuator", mode, "--motors", str(motors), "--link", str(link))
            code = code.replace(device, str(link))
        yield code

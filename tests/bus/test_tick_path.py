"""The path of one control tick (issue 38): the modules one ``Bus.cycle`` of 32 motors visits,
traced with ``sys.setprofile`` on the benchmark's zero-latency link, so that a new hop on the hot
path fails here.

The servobus.bus package's docstring walks this path module by module; these tests keep it true.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import FrameType

import pytest

from servobus.bus import Bus
from servobus.protocols import myactuator as ma

BENCH = Path(__file__).resolve().parents[2] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

# The link the benchmark measures the tick on (bench_bus.Reflector: it reports each send when
# handed the frame and answers with a prebuilt reply), so the path traced is the one measured.
from bench_bus import MOTORS, Reflector, prebuilt_replies  # noqa: E402

#: the bus package's share of the tick: the Bus, its engine, the tick's waiter and the intake
BUS_SIDE = {"servobus.bus.core", "servobus.bus.engine", "servobus.bus.tick", "servobus.bus.delivery"}
#: the whole tick, the family's codec and the frame type aside (issue 38: at most 8)
BUDGET = 8


async def _visited() -> dict[str, int]:
    """servobus module -> calls into it during one warm cycle of 32 ReadStatus2, codec aside."""
    seen: dict[str, int] = {}

    def profile(frame: FrameType, event: str, arg: object) -> None:
        if event == "call":
            module = frame.f_globals.get("__name__", "")
            if module.startswith("servobus") and not module.startswith("servobus.protocols.myactuator"):
                seen[module] = seen.get(module, 0) + 1

    command = ma.ReadStatus2()
    async with Bus(Reflector(prebuilt_replies(command))) as bus:
        items = [(bus.motor("myactuator", i), command) for i in range(1, MOTORS + 1)]
        for _ in range(3):  # warm: every round trip measured, every cache filled
            await bus.cycle(items)
        sys.setprofile(profile)
        try:
            results = await bus.cycle(items)
        finally:
            sys.setprofile(None)
    assert all(isinstance(r, ma.ReadStatus2.REPLY) for r in results), results
    seen.pop("servobus.frame", None)  # (the frame type: the codec's and the link's currency)
    return seen


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_the_bus_side_of_a_tick_is_the_bus_its_engine_the_tick_and_the_intake() -> None:
    """No other module of the bus package, and no call into servobus.runtime (the loop check of a
    cycle is one C call on asyncio): a new hop fails here."""
    visited = await _visited()
    bus_side = {m for m in visited if m.startswith("servobus.bus")}
    assert bus_side == BUS_SIDE, sorted(visited)
    assert "servobus.runtime" not in visited, sorted(visited)


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_one_tick_visits_at_most_eight_modules_between_the_bus_and_the_link() -> None:
    visited = await _visited()
    assert len(visited) <= BUDGET, f"{len(visited)} modules: {sorted(visited)}"

"""The path of one control tick (issue 38): the modules one ``Bus.cycle`` of 32 motors visits,
traced with ``sys.setprofile`` on a zero-latency link, so that a new hop on the hot path fails here.

The servobus.bus package's docstring walks this path module by module; these tests keep it true.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from types import FrameType
from typing import Any

import pytest

from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.runtime import current
from servobus.transports.contract import LineRules
from servobus.transports.stats import TransportStats

MOTORS = 32
#: the bus package's share of the tick: the Bus, its engine, the tick's waiter and the intake
BUS_SIDE = {"servobus.bus.core", "servobus.bus.engine", "servobus.bus.tick", "servobus.bus.delivery"}
#: the whole tick, the family's codec and the frame type aside (issue 38: at most 8)
BUDGET = 8


class ZeroLatencyLink:
    """A FrameLink that answers each frame at once with the reply a motor at rest gives: it reports
    the send when handed the frame, and hands the replies of one loop turn over in one call."""

    name = "zero-latency"
    rules = LineRules()

    def __init__(self, replies: dict[int, Frame]) -> None:
        self.replies = replies
        self.is_open = False
        self._out: list[Frame] = []
        self._consumer: Callable[[list[Frame]], object] | None = None
        self._reporter: Callable[[object, float | None, str | None], object] | None = None

    async def open(self) -> None:
        runtime = current()
        self._time, self._call_soon = runtime.time, runtime.call_soon
        self.is_open = True

    async def close(self) -> None:
        self.is_open = False

    def set_consumer(self, consumer: Callable[[list[Frame]], object] | None) -> None:
        self._consumer = consumer

    def set_send_reporter(
        self, reporter: Callable[[object, float | None, str | None], object] | None
    ) -> None:
        self._reporter = reporter

    def add_listener(self, listener: Callable[[Any], object]) -> None:
        pass

    def remove_listener(self, listener: Callable[[Any], object]) -> None:
        pass

    def stats(self) -> TransportStats:
        return TransportStats()

    def send(self, frame: Frame, handle: object = None) -> None:
        if self._reporter is not None:
            self._reporter(frame if handle is None else handle, self._time(), None)
        if not self._out:
            self._call_soon(self._flush)
        self._out.append(self.replies[frame.arbitration_id])

    def _flush(self) -> None:
        out, self._out = self._out, []
        if self._consumer is not None:
            self._consumer(out)


def _replies(command: ma.ReadStatus2) -> dict[int, Frame]:
    family = get_family("myactuator")
    out = {}
    for motor_id in range(1, MOTORS + 1):
        request = family.bind(motor_id).encode(command)
        (emission,) = MyActuatorMotor(motor_id).receive(request, 0.0)
        out[request.arbitration_id] = emission.frame
    return out


async def _visited() -> dict[str, int]:
    """servobus module -> calls into it during one warm cycle of 32 ReadStatus2, codec aside."""
    seen: dict[str, int] = {}

    def profile(frame: FrameType, event: str, arg: object) -> None:
        if event == "call":
            module = frame.f_globals.get("__name__", "")
            if module.startswith("servobus") and not module.startswith("servobus.protocols.myactuator"):
                seen[module] = seen.get(module, 0) + 1

    command = ma.ReadStatus2()
    async with Bus(ZeroLatencyLink(_replies(command))) as bus:
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

"""Send errors that keep the loop (issue [field], case 4), on the project's simulator.

A full send queue (python-can's ENOBUFS) fails THAT frame fast, counted and reported
``not_sent_queue_full``, and the tick goes on; bus-off (ENETDOWN, BUS_OFF / RESTARTED error frames)
is a state of the link, not a lost device: no reopen, events ``BusOff`` and ``BusRestarted``, requests
fail fast while it lasts (``not_sent_bus_off``), every error frame counted, and the bus answers again
soon after the controller restarts. In virtual time on the in-process bus, and in real time through
python-can's ``virtual`` interface (a controller wrapper that refuses sends during the episode).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import anyio
import pytest

from servobus.bus import Bus
from servobus.errors import TransportError
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.episodes import ControllerEpisodes, Episode
from servobus.transports import (
    BusOff,
    BusOffError,
    BusRestarted,
    CanErrorClass,
    ErrorFrame,
    SendQueueFull,
    TransportEvent,
)
from servobus.transports.sim import SimTransport

HZ = 200.0
MOTORS = range(1, 9)
START_S, EPISODE_S = 0.5, 0.5  # the episode: from 0.5 s into the run, for 0.5 s


@dataclasses.dataclass
class Run:
    """What a loop saw: each tick's start time (from the loop's start) and results, the bus's
    counters, the transport's, and its events."""

    ticks: list[tuple[float, list[object]]]
    counts: dict[str, int]
    stats: Any
    events: list[TransportEvent]

    def rate_hz(self, lo_s: float, hi_s: float) -> float:
        return sum(lo_s <= at < hi_s for at, _ in self.ticks) / (hi_s - lo_s)

    def results(self, lo_s: float, hi_s: float) -> list[object]:
        return [r for at, results in self.ticks if lo_s <= at < hi_s for r in results]


async def _loop(bus: Bus, link: Any, seconds: float) -> Run:
    events: list[TransportEvent] = []
    link.add_listener(events.append)
    batch = [(bus.motor("myactuator", i), ma.SpeedControl(speed_dps=10.0)) for i in MOTORS]
    start = anyio.current_time()
    ticks: list[tuple[float, list[object]]] = []
    async for _ in bus.ticks(HZ, spin_s=0.0):
        now = anyio.current_time() - start
        if now >= seconds:
            break
        ticks.append((now, await bus.cycle(batch)))
    return Run(ticks, bus.stats(), link.stats(), events)


def _sim_run(
    kind: str, *, seed: int = 0, refuse: float = 1.0, seconds: float = 2.0, backend: str = "asyncio"
) -> Run:
    devices = [MyActuatorMotor(i) for i in MOTORS]
    episodes = ControllerEpisodes(
        [Episode(kind=kind, start_s=START_S, duration_s=EPISODE_S, refuse=refuse)],  # type: ignore[arg-type]
        seed=seed,
    )

    async def main() -> Run:
        link = SimTransport(devices=devices, episodes=episodes)
        async with Bus(link, safe=None) as bus:
            return await _loop(bus, link, seconds)

    return virtual.run(main(), backend=backend)


# ---- a full send queue ----


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@pytest.mark.parametrize("refuse", [1.0, 0.5])
def test_a_full_send_queue_fails_those_frames_fast_and_the_loop_keeps_its_rate(
    refuse: float, backend: str
) -> None:
    run = _sim_run("queue_full", refuse=refuse, seed=3, backend=backend)
    clean = run.rate_hz(0.0, START_S)
    during = run.rate_hz(START_S, START_S + EPISODE_S)
    assert clean >= 0.99 * HZ
    assert during >= 0.8 * clean, (during, clean)  # the figure: >= 80 % (it was 2 ticks/s)
    refused = [r for r in run.results(START_S, START_S + EPISODE_S) if isinstance(r, SendQueueFull)]
    assert refused  # each failed with the error of its own, as a value of the tick
    assert run.stats.enobufs_dropped == run.counts["not_sent_queue_full"] == len(refused)
    assert run.stats.losses == run.stats.reopens == 0
    after = run.results(START_S + EPISODE_S + 0.1, 2.0)
    assert all(isinstance(r, ma.StatusReply) for r in after)  # and the motors answer after it
    if refuse < 1.0:  # a queue that drains takes some frames: those are answered
        assert any(isinstance(r, ma.StatusReply) for r in run.results(START_S, START_S + EPISODE_S))


def test_a_full_send_queue_episode_is_seeded() -> None:
    one = _sim_run("queue_full", refuse=0.5, seed=7, seconds=1.2)
    two = _sim_run("queue_full", refuse=0.5, seed=7, seconds=1.2)
    names = [[type(r).__name__ for r in results] for _, results in one.ticks]
    assert names == [[type(r).__name__ for r in results] for _, results in two.ticks]


# ---- bus-off ----


def _bus_off_checks(run: Run, *, restart_s: float) -> None:
    """No reopen, both error frames counted and heard, requests failed fast meanwhile, and the bus
    answers again within 0.5 s of the restart."""
    assert run.stats.losses == run.stats.reopens == 0  # a state of the link, not a lost device
    errors = [e for e in run.events if isinstance(e, ErrorFrame)]
    assert [e.classes for e in errors] == [CanErrorClass.BUS_OFF, CanErrorClass.RESTARTED]
    assert run.stats.error_frames == 2
    assert (run.stats.bus_off, run.stats.restarted) == (1, 1)
    assert [type(e) for e in run.events if isinstance(e, BusOff | BusRestarted)] == [BusOff, BusRestarted]
    during = run.results(START_S + 0.05, START_S + EPISODE_S - 0.05)
    assert during and all(isinstance(r, TransportError) for r in during), {type(r) for r in during}
    assert any(isinstance(r, BusOffError) for r in during)
    assert run.counts["not_sent_bus_off"] >= 1
    back = [
        at
        for at, results in run.ticks
        if at >= restart_s and all(isinstance(r, ma.StatusReply) for r in results)
    ]
    assert back and back[0] - restart_s <= 0.5, back[:1]
    assert all(isinstance(r, ma.StatusReply) for _, results in run.ticks if _ >= back[0] for r in results)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_bus_off_is_a_state_of_the_link_and_the_bus_answers_again_after_the_restart(backend: str) -> None:
    run = _sim_run("bus_off", backend=backend)
    _bus_off_checks(run, restart_s=START_S + EPISODE_S)
    assert run.rate_hz(START_S, START_S + EPISODE_S) >= 0.8 * run.rate_hz(0.0, START_S)  # no stall

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
import itertools
import math
import time
from collections.abc import Iterator
from typing import Any

import anyio
import can
import pytest

from servobus.bus import Bus
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.attach import serve_python_can
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.episodes import ControllerEpisodes, Episode
from servobus.transports import (
    BusOff,
    BusOffError,
    BusRestarted,
    CanErrorClass,
    CanTransport,
    ErrorFrame,
    SendQueueFull,
    TransportEvent,
)
from servobus.transports.sim import SimTransport

HZ = 200.0
MOTORS = range(1, 9)
START_S, EPISODE_S = 0.5, 0.5  # the episode: from 0.5 s into the run, for 0.5 s


class _Origin:
    """A real-time controller's clock: its episodes' time 0 is when the loop starts (shared by every
    bus a transport opens)."""

    def __init__(self) -> None:
        self.origin_s = time.monotonic()

    def start(self) -> None:
        self.origin_s = time.monotonic()

    def __call__(self) -> float:
        return time.monotonic() - self.origin_s


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


async def _loop(
    bus: Bus, link: Any, seconds: float, motors: range = MOTORS, origin: _Origin | None = None
) -> Run:
    events: list[TransportEvent] = []
    link.add_listener(events.append)
    batch = [(bus.motor("myactuator", i), ma.SpeedControl(speed_dps=10.0)) for i in motors]
    start = anyio.current_time()
    if origin is not None:  # (a real-time controller: its episodes start with the loop)
        origin.start()
    ticks: list[tuple[float, list[object]]] = []
    async for _ in bus.ticks(HZ, spin_s=0.0):
        now = anyio.current_time() - start
        if now >= seconds:
            break
        ticks.append((now, list(await bus.cycle(batch))))
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


def _answered(results: list[object]) -> float:
    return sum(isinstance(r, ma.StatusReply) for r in results) / max(1, len(results))


def _bus_off_checks(run: Run, *, restart_s: float, real_time: bool = False) -> None:
    """No reopen, both error frames counted and heard, requests failed fast meanwhile, and the bus
    answers again within 0.5 s of the restart (in real time on a shared machine, a reply now and
    then misses its 5 ms floor before and after the episode alike: not all of them after it)."""
    assert run.stats.losses == run.stats.reopens == 0  # a state of the link, not a lost device
    errors = [e for e in run.events if isinstance(e, ErrorFrame)]
    assert [e.classes for e in errors] == [CanErrorClass.BUS_OFF, CanErrorClass.RESTARTED]
    assert run.stats.error_frames == 2
    assert (run.stats.bus_off, run.stats.restarted) == (1, 1)
    assert [type(e) for e in run.events if isinstance(e, BusOff | BusRestarted)] == [BusOff, BusRestarted]
    during = run.results(START_S + 0.05, START_S + EPISODE_S - 0.05)
    refused = [r for r in during if isinstance(r, BusOffError)]
    assert len(refused) >= 0.9 * len(during) > 0, {type(r) for r in during}  # (or MotorBusy: not sent)
    assert not any(isinstance(r, ma.StatusReply) for r in during)
    assert run.counts["not_sent_bus_off"] == run.stats.bus_off_dropped >= len(refused)
    back = [at for at, results in run.ticks if at >= restart_s and _answered(results) == 1.0]
    assert back and back[0] - restart_s <= 0.5, back[:1]
    after = run.results(back[0], math.inf)
    assert _answered(after) >= (0.5 if real_time else 1.0), _answered(after)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_bus_off_is_a_state_of_the_link_and_the_bus_answers_again_after_the_restart(backend: str) -> None:
    run = _sim_run("bus_off", backend=backend)
    _bus_off_checks(run, restart_s=START_S + EPISODE_S)
    assert run.rate_hz(START_S, START_S + EPISODE_S) >= 0.8 * run.rate_hz(0.0, START_S)  # no stall


# ---- through python-can: its virtual interface behind a controller that refuses sends ----


@pytest.fixture
def faulty_interface(monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """python-can's name for :class:`servobus.sim.canfaults.FaultyCanBus` (opened by CanTransport as
    any interface, so a transport that reopens would get a fresh one on the same episodes)."""
    monkeypatch.setitem(
        can.interfaces.BACKENDS, "servobus-faulty", ("servobus.sim.canfaults", "FaultyCanBus")
    )
    yield "servobus-faulty"


PY_MOTORS = range(1, 5)
_channels = itertools.count()


async def _python_can_run(kind: str, interface: str, channel: str) -> Run:
    episodes = ControllerEpisodes([Episode(kind=kind, start_s=START_S, duration_s=EPISODE_S)])  # type: ignore[arg-type]
    origin = _Origin()
    network = CoreCanNetwork([MyActuatorMotor(i) for i in PY_MOTORS])
    sim_side = can.Bus(interface="virtual", channel=channel)
    link = CanTransport(
        interface,
        channel,
        ignore_config=True,
        episodes=episodes,
        clock=origin,
        origin_s=0.0,
        reopen_backoff_s=(0.01, 0.1),
    )
    try:
        async with anyio.create_task_group() as group:
            group.start_soon(serve_python_can, network, sim_side)
            async with Bus(link, safe=None) as bus:
                run = await _loop(bus, link, 2.0, PY_MOTORS, origin)
            group.cancel_scope.cancel()
    finally:
        sim_side.shutdown()
    return run


@pytest.mark.anyio
async def test_through_python_can_a_full_send_queue_keeps_the_loop(faulty_interface: str) -> None:
    run = await _python_can_run("queue_full", faulty_interface, f"sendq-{next(_channels)}")
    clean = run.rate_hz(0.1, START_S)
    during = run.rate_hz(START_S, START_S + EPISODE_S)
    assert during >= 0.8 * clean, (during, clean)  # (on main: 2 ticks/s, each frame retried 0.1 s)
    refused = [r for r in run.results(START_S, START_S + EPISODE_S) if isinstance(r, SendQueueFull)]
    # (every refusal of the run: on the wall clock a tick begun just before the episode may have its
    # frames refused just after it began)
    everyone = [r for r in run.results(0.0, math.inf) if isinstance(r, SendQueueFull)]
    assert refused and run.counts["not_sent_queue_full"] == run.stats.enobufs_dropped == len(everyone)
    assert run.stats.losses == run.stats.reopens == 0
    restart_s = START_S + EPISODE_S
    back = [at for at, results in run.ticks if at >= restart_s and _answered(results) == 1.0]
    assert back and back[0] - restart_s <= 0.5, back[:1]  # answered again (no motor lost)
    # (in real time on a shared machine, replies miss their floor now and then, before and after alike)
    assert _answered(run.results(back[0], math.inf)) >= 0.5


@pytest.mark.anyio
async def test_through_python_can_bus_off_is_no_lost_device(faulty_interface: str) -> None:
    run = await _python_can_run("bus_off", faulty_interface, f"sendq-{next(_channels)}")
    _bus_off_checks(run, restart_s=START_S + EPISODE_S, real_time=True)

"""The fault soak: 32 simulated MyActuator motors on 4 in-process buses, driven through servobus.Bus on
virtual time with seeded faults of every kind, and the Bus's promises checked throughout.

tests/test_soak.py runs it for a few virtual seconds in every test run; ``python bench/reliability.py
soak`` runs it for 10 virtual minutes and records the figures. One run (:func:`run`):

* **Traffic.** Each bus (8 motors, 1 Mbit/s, :class:`~servobus.transports.sim.SimTransport`) runs a
  100 Hz control tick, ``bus.cycle`` over its 8 motors with a 10 ms timeout: ReadStatus2,
  SpeedControl (the motors move) and WriteEncoderZero with a token. Beside it a requester task
  makes single requests (ReadStatus1, ReadMultiTurnAngle and token writes, some with a retry, some
  given up on by their caller after a random wait: cancelled).
* **Faults.** Both directions of every bus's link get a seeded
  :class:`~servobus.sim.faults.FaultInjector` (drops, corruption, which CAN turns into a
  retransmission one frame later, duplicates, delayed frames; and towards the host every reply
  0.5..3 ms late, each motor's in order: latency jitter); a random motor is power-cycled every
  few seconds (``reboot``); one motor stops answering for the middle third of the run
  (``unresponsive``) and answers again after; and one bus's adapter is unplugged for 0.3..1 s and
  plugged back (:meth:`SimTransport.unplug` / :meth:`~SimTransport.replug`) every
  ``unplug_every_s``. (The stalled serial port is a real pty, so it is a test of its own in
  tests/test_soak.py.) Issue [field] adds two: a **second controller** on bus 2
  (:class:`~servobus.sim.otherhost.OtherHost` at ``other_host_hz``) writes its own tokens to motors
  1 and 2 and reads motor 3's status, so its replies come on the ids ours come on; and on bus 3 every
  motor has 0xB3 protection at ``comm_timeout_ms`` and, every ``trip_every_s``, one of them is left
  out of the traffic long enough to **trip**: it sends 0xF1 frames and echoes the first command after
  the pause unexecuted (the request fails ``MotorNotExecuted``, counted ``not_executed``).
* **Wrong deliveries.** A WriteEncoderZero is echoed by the motor, so its ``offset_counts``, unique
  per request, comes back: a token reply whose token is not its request's is a mismatched reply.
  Every other reply must be of the reply class its command gets, and no set-point's reply may be
  its own bytes (an echo reads as 0 °C: the simulated motors are never that cold). The second
  controller writes positive tokens, ours are negative: its replies are mismatched replies if they
  ever answer ours.
* **Every request ends, once.** Each request the Bus makes (the scheduler's ``request`` is wrapped,
  nothing else changes) is followed to its end: replied, timed out, cancelled or failed (transport
  lost or frame not sent). The counters add up: made = replied + timed out + cancelled + failed,
  and the scheduler's own ``requests``, ``replies`` and ``timeouts`` say the same.
* **Bounded.** ``scheduler.pending`` and the scheduler's tables (pending keys, deadline heap, held
  keys, late and duplicate windows) stay below fixed bounds at every checkpoint; traced memory
  (``tracemalloc``, started after a warm-up; or, where that is too slow, the resident memory and the
  count of live objects) stops growing: its high-water mark over the second half of the
  checkpoints after the warm-up is at most ``memory_limit_bytes`` above that of the first half (the
  simulator's caches, bounded, fill and are cleared meanwhile).
  At the end nothing is pending (``leaked_pending``).
* **Freshness.** A passive node on each bus sees every frame when its transmission ends; a request
  frame that reaches the motors more than ``fresh_s`` (the transport's ``stale_after_s``) after its
  request was made is a stale command.
* **Safe stop.** Leaving ``async with Bus`` sends the stop command to every motor the Bus commanded
  (the link's faults are switched off first, so every stop frame gets through); each such motor must
  have seen its stop frame go by on its bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import os
import random
import time
import tracemalloc
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from servobus.bus import Bus, Motor, MotorStatus
from servobus.errors import (
    MotorBusy,
    MotorNotExecuted,
    MotorOffline,
    MotorTimeout,
    ProtocolError,
    TransportError,
)
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import Request
from servobus.sim import virtual
from servobus.sim.device import Emission
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.sim.network import SimCanNetwork
from servobus.sim.otherhost import OtherHost
from servobus.transports.sim import SimTransport

__all__ = ["SoakPlan", "SoakResult", "run"]

# Every reply also comes 0.5..3 ms late, each motor's in order (a USB adapter, a busy host): the
# latency jitter of issue [control].
TO_HOST = FaultPlan(
    drop=0.01,
    corrupt=0.005,
    duplicate=0.005,
    delay=0.005,
    delay_s=(0.001, 0.008),
    latency_s=(0.0005, 0.003),
    latency_order="sender",
)
TO_DEVICES = FaultPlan(drop=0.005, corrupt=0.002, duplicate=0.002, delay=0.002, delay_s=(0.001, 0.008))
TIMEOUT_S = 0.01
OTHER_HOST_BUS = 2  # the bus with a second controller
OTHER_TOKEN = 700_000  # its tokens (ours are negative)
TRIP_BUS = 3  # the bus whose motors have 0xB3 protection and are left out to trip


@dataclass(frozen=True)
class SoakPlan:
    minutes: float = 10.0
    seed: int = 2024
    buses: int = 4
    motors_per_bus: int = 8
    tick_hz: float = 100.0
    reboot_every_s: float = 3.0
    unplug_every_s: float = 60.0
    fresh_s: float = 0.5  # the transports' stale_after_s
    warmup_s: float = 2.0
    checkpoint_s: float = 5.0
    memory_limit_bytes: int = 8_000_000
    # "tracemalloc": traced Python memory (every allocation traced: about 5x slower); "rss": the
    # process's resident memory and its count of live objects (what the 10-minute run uses).
    memory: str = "tracemalloc"
    objects_limit: int = 20_000
    other_host_hz: float = 500.0  # the second controller on bus 2 (0: none)
    comm_timeout_ms: int = 50  # bus 3's motors' 0xB3 protection
    trip_every_s: float = 2.0  # one of bus 3's motors is left out long enough to trip (0: never)


@dataclass
class Tracked:
    request: Request
    bus: int
    made_at: float
    token: int | None = None
    outcome: str | None = None


@dataclass
class SoakResult:
    plan: SoakPlan
    virtual_s: float = 0.0
    wall_s: float = 0.0
    outcomes: Counter[str] = field(default_factory=Counter)
    made: int = 0
    faults: Counter[str] = field(default_factory=Counter)
    mismatched: list[str] = field(default_factory=list)
    wrong: list[str] = field(default_factory=list)
    stale: list[str] = field(default_factory=list)
    leaked_pending: int = 0
    max_pending: int = 0
    max_tables: dict[str, int] = field(default_factory=dict)
    memory: list[tuple[float, int]] = field(default_factory=list)
    objects: list[tuple[float, int]] = field(default_factory=list)
    unplug_recovery_s: list[float] = field(default_factory=list)
    offline_events: list[tuple[str, float, bool, str]] = field(default_factory=list)
    safe_stops_missing: list[str] = field(default_factory=list)
    bus_counts: Counter[str] = field(default_factory=Counter)

    @property
    def memory_growth_bytes(self) -> int:
        """How much the memory's high-water mark rose from the first half of the checkpoints after
        the warm-up to the second half: a leak raises it with the run's length, while the bounded
        caches (the simulator's, the latency windows) and the allocator's own swings do not."""
        return _growth(self.memory)

    @property
    def objects_growth(self) -> int:
        return _growth(self.objects)

    def summary(self) -> dict[str, Any]:
        return {
            "virtual_s": round(self.virtual_s, 3),
            "wall_s": round(self.wall_s, 1),
            "seed": self.plan.seed,
            "buses": self.plan.buses,
            "motors": self.plan.buses * self.plan.motors_per_bus,
            "tick_hz": self.plan.tick_hz,
            "requests": self.made,
            "outcomes": dict(self.outcomes),
            "faults": dict(self.faults),
            "mismatched_replies": len(self.mismatched),
            "wrong_results": len(self.wrong),
            "leaked_pending": self.leaked_pending,
            "stale_commands_sent": len(self.stale),
            "max_pending": self.max_pending,
            "max_tables": self.max_tables,
            "memory_measure": self.plan.memory,
            "memory_growth_bytes": self.memory_growth_bytes,
            "memory_samples": len(self.memory),
            "memory_first_last": [self.memory[0], self.memory[-1]] if self.memory else [],
            "memory_min_max": [min(m for _, m in self.memory), max(m for _, m in self.memory)]
            if self.memory
            else [],
            "live_objects_first_last": [self.objects[0], self.objects[-1]] if self.objects else [],
            "live_objects_growth": self.objects_growth,
            "unplug_recovery_s": [round(x, 4) for x in self.unplug_recovery_s],
            "offline_events": len(self.offline_events),
            "safe_stops_missing": len(self.safe_stops_missing),
            "bus_counts": dict(self.bus_counts),
        }

    def problems(self) -> list[str]:
        """Every broken promise, in words (empty: the run kept them all)."""
        out = []
        if self.mismatched:
            out.append(f"{len(self.mismatched)} mismatched replies, first: {self.mismatched[:3]}")
        if self.wrong:
            out.append(f"{len(self.wrong)} wrong results, first: {self.wrong[:3]}")
        if self.stale:
            out.append(f"{len(self.stale)} stale commands reached a motor, first: {self.stale[:3]}")
        if self.leaked_pending:
            out.append(f"{self.leaked_pending} requests still pending at the end")
        total = sum(self.outcomes.values())
        if total != self.made or self.outcomes.get("open", 0):
            out.append(f"made {self.made} requests, {total} ended: {dict(self.outcomes)}")
        if self.memory_growth_bytes > self.plan.memory_limit_bytes:
            out.append(f"memory grew {self.memory_growth_bytes} bytes: {self.memory}")
        if self.objects and self.objects_growth > self.plan.objects_limit:
            out.append(f"live objects grew by {self.objects_growth}: {self.objects}")
        if self.safe_stops_missing:
            out.append(f"no safe stop seen for {self.safe_stops_missing}")
        return out


class Watch:
    """A passive node: checks every host frame's age when its transmission ends (it reached the
    motors then) and records the stop frames."""

    def __init__(self, name: str, soak: _Soak, bus_index: int) -> None:
        self.name = name
        self._soak = soak
        self._bus = bus_index
        self.stops: set[int] = set()

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        if 0x141 <= frame.arbitration_id <= 0x160:
            self._soak.reached(self._bus, frame, now_s)
            if frame.data[:1] == bytes([ma.MotorStop.CODE]):
                self.stops.add(frame.arbitration_id - 0x140)
        return []

    def poll(self, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


class _Soak:
    def __init__(self, plan: SoakPlan) -> None:
        self.plan = plan
        self.result = SoakResult(plan)
        self.rng = random.Random(plan.seed)
        self.records: dict[int, Tracked] = {}  # id(request.frame) -> record, until it reached the wire
        self.open: dict[int, Tracked] = {}  # id(record) -> record, until its request ended
        self.next_token = 1
        self.transports: list[SimTransport] = []
        self.networks: list[SimCanNetwork] = []
        self.watches: list[Watch] = []
        self.devices: list[list[MyActuatorMotor]] = []
        self.injectors: list[FaultInjector] = []
        self.buses: list[Bus] = []
        self.stopping = False
        self.replugged_at: dict[int, float] = {}
        self.paused: set[tuple[int, int]] = set()  # (bus, motor id): left out of the traffic, to trip
        self.other_hosts: list[OtherHost] = []
        self.loop: asyncio.AbstractEventLoop | None = None

    # ---- following every request ----

    def wrap(self, bus: Bus, index: int) -> None:
        make = bus.scheduler.request

        def request(*args: Any, **kwargs: Any) -> Request:
            made = make(*args, **kwargs)
            assert self.loop is not None
            record = Tracked(made, index, self.loop.time())
            command = made.command
            if isinstance(command, ma.WriteEncoderZero):
                record.token = command.offset_counts
            self.records[id(made.frame)] = record
            self.open[id(record)] = record
            self.result.made += 1
            made.context.add_done_callback(functools.partial(self.ended, record))
            return made

        bus.scheduler.request = request  # type: ignore[method-assign]

    def ended(self, record: Tracked, future: asyncio.Future[Any]) -> None:
        self.open.pop(id(record), None)
        if future.cancelled():
            record.outcome = "cancelled"
        elif isinstance(error := future.exception(), MotorOffline | MotorBusy):
            record.outcome = "skipped"  # cycle() did not wait for it (an offline motor's may be a probe)
        elif isinstance(error, MotorTimeout):
            record.outcome = "timed_out"
        elif isinstance(error, MotorNotExecuted):
            record.outcome = "not_executed"  # echoed after a 0xB3 trip: failed, and said so
        elif isinstance(error, TransportError | ProtocolError):
            record.outcome = "failed"
        elif error is not None:
            record.outcome = "error"
            self.result.wrong.append(f"{record.request.describe()}: {error!r}")
        else:
            record.outcome = "replied"
            self.check_reply(record, future.result())
            if record.bus in self.replugged_at:
                assert self.loop is not None
                self.result.unplug_recovery_s.append(self.loop.time() - self.replugged_at.pop(record.bus))
        self.result.outcomes[record.outcome] += 1

    def check_reply(self, record: Tracked, reply: Any) -> None:
        what = record.request.describe()
        if record.token is not None:
            got = reply.command.offset_counts if isinstance(reply, ma.Echo) else None
            if got != record.token:
                self.result.mismatched.append(f"{what} with token {record.token} got {reply!r}")
            return
        expected = _REPLY_TYPES.get(type(record.request.command))
        if expected is not None and not isinstance(reply, expected):
            self.result.mismatched.append(f"{what} got {type(reply).__name__}")
        elif (
            record.request.command.NEVER_ECHOED
            and isinstance(reply, ma.StatusReply)
            and reply.temperature_c == 0
        ):
            # (a set-point's echo reads as 0 °C; a read's echo after a trip whose 0xF1 was lost is
            # all zeros and cannot be told from a reply: docs/explanation/faults.md, "What these wires
            # cannot tell apart")
            self.result.mismatched.append(f"{what} got its own bytes back as a reply: {reply!r}")

    def reached(self, bus: int, frame: Frame, now_s: float) -> None:
        record = self.records.pop(id(frame), None)
        if record is None:
            return
        at = self.transports[bus].loop_time(now_s)
        if at - record.made_at > self.plan.fresh_s + 1e-9:
            self.result.stale.append(
                f"bus {bus} {record.request.describe()} made at {record.made_at:.6f} reached the motor at "
                f"{at:.6f} ({(at - record.made_at) * 1e3:.1f} ms)"
            )

    # ---- checkpoints ----

    def checkpoint(self, now: float) -> None:
        result = self.result
        for bus in self.buses:
            scheduler = bus.scheduler
            result.max_pending = max(result.max_pending, scheduler.pending)
            tables = {
                "pending_keys": len(scheduler.table.pending),
                "deadlines": len(scheduler.table.deadlines),
                "held": len(scheduler.keys.held),
                "late_keys": len(scheduler.keys.late),
                "replied_keys": len(scheduler.keys.replied),
                "in_flight": len(scheduler.table.in_flight),
            }
            for name, size in tables.items():
                result.max_tables[name] = max(result.max_tables.get(name, 0), size)
        # Frames that never reached the wire (dropped towards the motors, purged, failed): forgotten
        # once their request is long over.
        horizon = now - 2.0
        for key in [k for k, r in self.records.items() if r.outcome is not None and r.made_at < horizon]:
            del self.records[key]
        if self.plan.memory == "tracemalloc" and tracemalloc.is_tracing():
            gc.collect()
            result.memory.append((round(now, 3), tracemalloc.get_traced_memory()[0]))
        elif self.plan.memory == "rss":
            gc.collect()
            with open("/proc/self/statm") as statm:
                rss = int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
            result.memory.append((round(now, 3), rss))
            result.objects.append((round(now, 3), len(gc.get_objects())))

    # ---- the run ----

    async def main(self) -> None:
        plan = self.plan
        self.loop = asyncio.get_running_loop()
        end = plan.minutes * 60.0
        async with contextlib.AsyncExitStack() as stack:
            for b in range(plan.buses):
                devices = [MyActuatorMotor(m) for m in range(1, plan.motors_per_bus + 1)]
                watch = Watch(f"watch{b}", self, b)
                nodes: list[Any] = [*devices, watch]
                if b == OTHER_HOST_BUS and plan.other_host_hz > 0:
                    nodes.append(self.other_host(plan))
                to_host = FaultInjector(TO_HOST, seed=plan.seed * 10 + b)
                to_devices = FaultInjector(TO_DEVICES, seed=plan.seed * 10 + 5 + b)
                network = SimCanNetwork(nodes, to_devices=to_devices, to_host=to_host)
                transport = SimTransport(
                    network, name=f"sim{b}", stale_after_s=plan.fresh_s, reopen_backoff_s=(0.05, 0.4)
                )
                # (how long a timed-out key is held for its late reply: the Bus's own, from the
                # round trips it measured, late ones included)
                bus = Bus(transport, offline_after_misses=3, name=f"bus{b}")
                self.wrap(bus, b)
                await stack.enter_async_context(transport)
                await stack.enter_async_context(bus)
                bus.subscribe_status(functools.partial(self.status, b))
                self.transports.append(transport)
                self.networks.append(network)
                self.watches.append(watch)
                self.devices.append(devices)
                self.injectors += [to_host, to_devices]
                self.buses.append(bus)
            motors = [
                [bus.motor("myactuator", m) for m in range(1, plan.motors_per_bus + 1)] for bus in self.buses
            ]
            if plan.trip_every_s > 0:
                await self.protect(motors[TRIP_BUS])
            stack.push_async_callback(self.switch_faults_off)  # runs first on the way out: before the stops
            async with asyncio.TaskGroup() as group:
                for b in range(plan.buses):
                    group.create_task(self.ticker(b, motors[b], end))
                    group.create_task(self.requester(b, motors[b], end))
                group.create_task(self.chaos(end))
                group.create_task(self.checkpoints(end))
            await asyncio.sleep(0.2)  # the last delayed frames arrive (counted late)
            self.result.virtual_s = self.loop.time()
            self.commanded = {b: {m.motor_id for m in bus.commanded} for b, bus in enumerate(self.buses)}
        # The Buses have left: each sent its safe stop.
        for b, watch in enumerate(self.watches):
            for motor_id in sorted(self.commanded[b] - watch.stops):
                self.result.safe_stops_missing.append(f"bus {b} motor {motor_id}")
        self.result.leaked_pending = sum(bus.scheduler.pending for bus in self.buses) + len(self.open)
        self.result.outcomes["open"] += len(self.open)
        for injector_index, injector in enumerate(self.injectors):
            direction = "to_host" if injector_index % 2 == 0 else "to_devices"
            for kind, n in injector.counts.items():
                if kind != "pass":
                    self.result.faults[f"{direction}_{kind}"] += n
        for bus in self.buses:
            self.result.bus_counts.update(bus.stats())
        for devices in self.devices:
            for device in devices:
                for name in ("comm_timeouts", "comm_trip_frames", "comm_echoed"):
                    self.result.faults[f"motor_{name}"] += device.counters.get(name, 0)

    def other_host(self, plan: SoakPlan) -> OtherHost:
        """The second controller: its own token writes to motors 1 and 2 (positive: ours are
        negative) and a status read of motor 3, ``other_host_hz`` times a second."""
        frames = [
            ma.FAMILY.bind(1).encode(ma.WriteEncoderZero(offset_counts=OTHER_TOKEN)),
            ma.FAMILY.bind(2).encode(ma.WriteEncoderZero(offset_counts=OTHER_TOKEN + 1)),
            ma.FAMILY.bind(3).encode(ma.ReadStatus2()),
        ]
        host = OtherHost(frames, rate_hz=plan.other_host_hz, seed=plan.seed * 7)
        self.other_hosts.append(host)
        return host

    async def protect(self, motors: list[Motor]) -> None:
        """0xB3 protection on ``motors`` (through the faulty link: sent until acknowledged)."""
        for motor in motors:
            for _ in range(20):
                with contextlib.suppress(MotorTimeout, TransportError, ProtocolError, MotorNotExecuted):
                    await motor.request(
                        ma.SetCommTimeout(timeout_ms=self.plan.comm_timeout_ms), timeout_s=0.05
                    )
                    break
            else:
                raise RuntimeError(f"0xB3 protection never acknowledged by {motor!r}")

    async def switch_faults_off(self) -> None:
        self.stopping = True
        self.paused.clear()
        for host in self.other_hosts:
            host.rate_hz = 1e-6  # (quiet from its next period on)
        for injector in self.injectors:
            injector.plan = FaultPlan()
        for devices in self.devices:
            for device in devices:
                device.unresponsive = False

    def status(self, bus: int, status: MotorStatus) -> None:
        self.result.offline_events.append(
            (f"bus {bus} motor {status.motor.motor_id}", status.at, status.online, status.reason)
        )

    async def ticker(self, b: int, motors: list[Motor], end: float) -> None:
        assert self.loop is not None
        rng = random.Random(self.plan.seed * 1000 + b)
        period = 1.0 / self.plan.tick_hz
        next_tick = self.loop.time()
        while self.loop.time() < end:
            items: list[tuple[Motor, Any]] = []
            for motor in motors:
                x = rng.random()
                if (b, motor.motor_id) in self.paused:
                    continue
                if x < 0.6:
                    items.append((motor, ma.ReadStatus2()))
                elif x < 0.85:
                    items.append((motor, ma.SpeedControl(speed_dps=rng.uniform(-90, 90))))
                else:
                    items.append((motor, ma.WriteEncoderZero(offset_counts=self.token())))
            results = await self.buses[b].cycle(items, timeout_s=TIMEOUT_S) if items else []
            assert len(results) == len(items)
            next_tick += period
            delay = next_tick - self.loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            else:
                next_tick = self.loop.time()

    def token(self) -> int:
        self.next_token += 1
        return -self.next_token  # negative: never a motor's own encoder value

    async def requester(self, b: int, motors: list[Motor], end: float) -> None:
        assert self.loop is not None
        rng = random.Random(self.plan.seed * 2000 + b)
        while self.loop.time() < end:
            motor = rng.choice(motors)
            x = rng.random()
            if (b, motor.motor_id) in self.paused:
                await asyncio.sleep(0.005)
                continue
            if x < 0.4:
                coro = motor.request(ma.ReadStatus1(), timeout_s=TIMEOUT_S, retries=rng.choice((0, 1)))
            elif x < 0.7:
                coro = motor.request(ma.ReadMultiTurnAngle())  # its timeout from the round trips
            else:
                coro = motor.request(ma.WriteEncoderZero(offset_counts=self.token()), timeout_s=TIMEOUT_S)
            task = asyncio.ensure_future(coro)
            if rng.random() < 0.1:  # the caller gives up after a random wait
                await asyncio.sleep(rng.uniform(0, 0.004))
                task.cancel()
            with contextlib.suppress(MotorTimeout, TransportError, MotorNotExecuted, asyncio.CancelledError):
                await task
            await asyncio.sleep(rng.uniform(0.001, 0.02))

    async def chaos(self, end: float) -> None:
        """Reboots, the silent motor, the unplugged adapter, the motor left out until it trips."""
        assert self.loop is not None
        plan, rng = self.plan, random.Random(self.plan.seed * 3000)
        silent = self.devices[1][4]  # bus 1, motor 5
        silent_from, silent_to = end / 3, 2 * end / 3
        next_reboot = plan.reboot_every_s * rng.uniform(0.5, 1.5)
        next_unplug = min(plan.unplug_every_s, end / 2) * rng.uniform(0.5, 1.0)
        unplugged: tuple[int, float] | None = None
        next_trip = plan.trip_every_s * rng.uniform(0.5, 1.0) if plan.trip_every_s > 0 else end
        trip: tuple[tuple[int, int], float] | None = None
        while (now := self.loop.time()) < end:
            if trip is None and now >= next_trip:
                key = (TRIP_BUS, rng.randrange(1, plan.motors_per_bus + 1))
                self.paused.add(key)
                self.result.faults["motor_left_to_trip"] += 1
                # long enough for its 0xB3 protection, and now and then for its second 0xF1 frame
                trip = (key, now + plan.comm_timeout_ms / 1000 + rng.choice((0.1, 0.3, 1.2)))
            elif trip is not None and now >= trip[1]:
                self.paused.discard(trip[0])
                trip = None
                next_trip = now + plan.trip_every_s * rng.uniform(0.5, 1.5)
            if not silent.unresponsive and silent_from <= now < silent_to:
                silent.unresponsive = True
                self.result.faults["motor_silent"] += 1
            elif silent.unresponsive and now >= silent_to:
                silent.unresponsive = False
            if now >= next_reboot:
                b = rng.randrange(plan.buses)
                device = rng.choice(self.devices[b])
                device.reboot(self.transports[b].network_time(now))
                self.result.faults["motor_reboot"] += 1
                next_reboot = now + plan.reboot_every_s * rng.uniform(0.5, 1.5)
            if unplugged is None and now >= next_unplug:
                b = rng.randrange(plan.buses)
                self.transports[b].unplug()
                self.result.faults["adapter_unplug"] += 1
                unplugged = (b, now + rng.uniform(0.3, 1.0))
            elif unplugged is not None and now >= unplugged[1]:
                b = unplugged[0]
                self.transports[b].replug()
                self.replugged_at[b] = now
                unplugged = None
                next_unplug = now + plan.unplug_every_s * rng.uniform(0.5, 1.5)
            await asyncio.sleep(0.05)
        if unplugged is not None:
            self.transports[unplugged[0]].replug()
            self.replugged_at[unplugged[0]] = self.loop.time()
        with contextlib.suppress(TimeoutError):
            for transport in self.transports:
                await transport.wait_open(timeout=3.0)

    async def checkpoints(self, end: float) -> None:
        assert self.loop is not None
        await asyncio.sleep(min(self.plan.warmup_s, end / 4))
        if self.plan.memory == "tracemalloc":
            tracemalloc.start()
        try:
            while self.loop.time() < end:
                self.checkpoint(self.loop.time())
                await asyncio.sleep(min(self.plan.checkpoint_s, end / 8))
            self.checkpoint(self.loop.time())
        finally:
            if self.plan.memory == "tracemalloc":
                tracemalloc.stop()


def _growth(samples: list[tuple[float, int]]) -> int:
    if len(samples) < 2:
        return 0
    half = len(samples) // 2
    return max(v for _, v in samples[half:]) - max(v for _, v in samples[:half])


_REPLY_TYPES: dict[type, type | tuple[type, ...]] = {
    ma.ReadStatus1: ma.Status1Reply,
    ma.ReadStatus2: ma.StatusReply,
    ma.SpeedControl: ma.StatusReply,
    ma.ReadMultiTurnAngle: ma.MultiTurnAngleReply,
}


def run(minutes: float = 10.0, seed: int = 2024, **options: Any) -> SoakResult:
    """One soak run on a virtual-time loop (see the module docstring)."""
    soak = _Soak(SoakPlan(minutes=minutes, seed=seed, **options))
    started = time.perf_counter()
    virtual.run(soak.main())
    soak.result.wall_s = time.perf_counter() - started
    return soak.result

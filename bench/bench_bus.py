"""Bus benchmark: ``Bus.cycle()`` over 32 MyActuator motors, against baselines measured in the same run.

Two questions, each answered against a baseline in the same run:

1. **Efficiency on the simulated 1 Mbit/s bus (virtual time).** ``SimTransport`` with 32 simulated
   ``MyActuatorMotor``\\ s on ``servobus.sim.virtual``'s clock; N cycles of ``ReadStatus2`` to all 32
   (and, as extra information, of ``SpeedControl``, a typical control tick). The theoretical bound is
   1 / (wire time of one cycle's 64 frames): every request and reply frame is recorded by a passive
   sniffer device on the simulated bus and timed with the bus model's own ``frame_time_s`` (bit-exact,
   stuff bits, CRC, ACK, EOF and the 3-bit intermission included), so bound and simulation agree by
   construction (the bus model's ``busy_s`` is checked against the sum). The simulated motors answer
   ``turnaround_s`` (200 µs) after a request; the bound does not include it, because with all 32
   requests in flight a motor's turnaround overlaps the other frames on the wire (requests 0x141..
   win arbitration over replies 0x241..; 200 µs is less than one cycle's other 31 replies), so the
   wire-only bound is reachable. ``efficiency_can1m_32`` = achieved cycles/s / bound. The baseline is
   sequential send-then-wait (``await motor.request(ReadStatus2())`` 32 times per cycle); it pays the
   turnaround once per request, so its own bound, 1 / (wire time + 32 x turnaround), is given too.
   Virtual time means host CPU costs nothing here: this measures how well the Bus keeps the wire busy
   (pipelining, no idle gaps), not how fast the host computes; the second part measures that.

2. **Transactions per second on one core, zero-latency reflector.** A FrameLink in this file
   (:class:`Reflector`) answers every frame with a prebuilt reply frame looked up by arbitration id:
   the replies of one loop iteration are delivered in one consumer call (the runtime lane's
   ``call_soon``), each send is reported to the send reporter at once with the loop's time, echoing
   its handle (the FrameLink contract). Nothing is decoded, built or
   simulated on that side, so the figure is servobus: ``bus.cycle([(motor, ReadStatus2()), ...])`` over
   32 motors, encode, schedule, match, decode to a typed ``StatusReply``, futures. The items list is
   built once and reused (a ReadStatus2 tick needs no new commands). Baselines on the same prebuilt
   replies:

   * **naive python-can** (the ratio's basis, ``cycle32_vs_naive``): a minimal ``can.BusABC`` whose
     ``send`` puts the prebuilt reply into its receive queue; ``can.Notifier`` + ``can.AsyncBufferedReader``
     (python-can's asyncio recipe; a bus without a file descriptor gets the Notifier's reader thread,
     as python-can's ``virtual`` and most vendor interfaces do); one transaction at a time: encode the
     command with the same bound codec, ``bus.send(can.Message(...))``, ``await
     reader.get_message()``, check the id, decode the typed reply with the same codec.
   * **on trio** (recorded beside, no target): the same ``cycle()`` over 32 motors on trio
     (``trio_cycle32_transactions_s``) against a bare trio floor (``trio_cycle32_vs_floor``, CPU µs
     per transaction): the asyncio floor's loop with trio's primitives, ONE task per cycle parked
     with ``trio.lowlevel.wait_task_rescheduled`` and rescheduled by the ``run_sync_soon`` callback
     that delivers the cycle's last reply (trio has no future; one ``trio.Event`` per request would
     cost a checkpoint each).
   * as information, the same naive loop on a reflector bus with a file descriptor (an ``os.eventfd``
     the Notifier watches with ``loop.add_reader``: no thread hop, python-can's socketcan path), and a
     pipelined naive loop (32 sends, then 32 awaits) on the thread reflector.

3. **The same through python-can's ``virtual`` interface**: ``Bus(CanTransport("virtual", ch))`` with a
   peer thread on a second virtual bus object answering every request with its prebuilt reply
   (``cycle32_python_can_virtual_transactions_s``), and the naive python-can loop (as above, virtual
   bus + Notifier + AsyncBufferedReader) against the same peer.

Method: wall clock ``time.perf_counter`` around whole cycles (or N sequential transactions), after one
warm-up cycle; each repeat in a fresh event loop (``asyncio.run``); servobus and the baselines
alternated repeat by repeat; the MEDIAN repeat is reported (min-max spread in results.json). The
garbage collector stays on (it is part of what a control loop pays). The machine is shared and noisy:
rerun before reading much into a 10 % change. Part 1 runs on virtual time and is deterministic.

Targets (the issue): ``efficiency_can1m_32`` >= 0.95; ``cycle32_transactions_s`` >= 100,000 and
``cycle32_vs_naive`` >= 5. Missed targets are printed; the exit status is 0 unless ``--check``.

Usage (from the repository root, with servobus installed: ``pip install -e .``)::

    python bench/bench_bus.py            # full run (~1 min): writes bench/RESULTS.md, bench/results.json
    python bench/bench_bus.py --quick    # CI smoke run (a few s): small, writes nothing
    python bench/bench_bus.py --quick --output /tmp/out   # ... and writes there
    python bench/bench_bus.py --check    # exit 1 when a target is missed

Outputs: the ``bus`` key of results.json (other keys are kept) and the ``bus`` section of RESULTS.md
(other sections are kept), through bench/_results.py.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import queue
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
if str(BENCH_DIR) not in sys.path:  # so `_results` imports however this script is started
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _profile  # noqa: E402
import _results  # noqa: E402
import _virtual  # noqa: E402
import servobus  # noqa: E402
from servobus.bus import Bus  # noqa: E402
from servobus.frame import Frame  # noqa: E402
from servobus.protocols import (  # noqa: E402
    BoundCodec,
    Command,
    get_family,
)
from servobus.protocols import myactuator as ma  # noqa: E402
from servobus.protocols.myactuator.sim.device import MyActuatorMotor  # noqa: E402
from servobus.runtime import current  # noqa: E402
from servobus.sim import virtual  # noqa: E402
from servobus.sim.device import Emission  # noqa: E402
from servobus.transports import CanTransport  # noqa: E402
from servobus.transports.contract import Consumer, LineRules, SendReporter  # noqa: E402
from servobus.transports.sim import SimTransport  # noqa: E402
from servobus.transports.stats import TransportStats  # noqa: E402

KEY = "bus"
MOTORS = 32
FAMILY = "myactuator"
EFFICIENCY_TARGET = 0.95
TRANSACTIONS_TARGET = 100_000
VS_NAIVE_TARGET = 5.0
VS_FLOOR_TARGET = 4.0


@dataclass(frozen=True)
class Config:
    mode: str
    efficiency_cycles: int  # virtual-time cycles per efficiency run (deterministic: one run)
    cycles: int  # Bus.cycle() calls per repeat on the reflector
    naive: int  # sequential naive transactions per repeat on the reflector
    virtual_cycles: int  # Bus.cycle() calls per repeat on python-can's virtual interface
    virtual_naive: int  # naive transactions per repeat on python-can's virtual interface
    repeats: int


FULL = Config("full", 200, 1_000, 8_000, 150, 3_000, 7)
QUICK = Config("quick", 8, 60, 500, 10, 200, 2)


def _motor_ids() -> range:
    return range(1, MOTORS + 1)


def prebuilt_replies(command: Command) -> dict[int, Frame]:
    """Request arbitration id -> the reply a simulated motor at rest gives to ``command`` (built once)."""
    family = get_family(FAMILY)
    out: dict[int, Frame] = {}
    for motor_id in _motor_ids():
        request = family.bind(motor_id).encode(command)
        emissions = MyActuatorMotor(motor_id).receive(request, 0.0)
        if len(emissions) != 1:
            raise RuntimeError(f"motor {motor_id} gave {len(emissions)} replies to {request!r}")
        out[request.arbitration_id] = emissions[0].frame
    return out


# ================================================================ 1. efficiency, virtual time


class _Sniffer:
    """A passive node on the simulated bus: records every frame (it sees all but its own; it sends none)."""

    name = "bench-sniffer"

    def __init__(self) -> None:
        self.frames: list[Frame] = []
        self.recording = False

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        if self.recording:
            self.frames.append(frame)
        return []

    def poll(self, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


async def efficiency_run(cycles: int, build: Callable[[], Command], sequential: bool) -> dict[str, Any]:
    sniffer = _Sniffer()
    devices = [MyActuatorMotor(i) for i in _motor_ids()]
    transport = SimTransport(devices=[*devices, sniffer])
    model = transport.network.bus
    loop = asyncio.get_running_loop()
    async with Bus(transport) as bus:
        motors = [bus.motor(FAMILY, i) for i in _motor_ids()]
        await bus.cycle([(m, build()) for m in motors])  # warm-up: every motor answered once
        sniffer.recording = True
        busy0, frames0 = model.busy_s, model.frames
        start = loop.time()
        bad = 0
        for _ in range(cycles):
            if sequential:
                for m in motors:
                    reply = await m.request(build())
                    bad += not isinstance(reply, ma.StatusReply)
            else:
                results = await bus.cycle([(m, build()) for m in motors])
                bad += sum(not isinstance(r, ma.StatusReply) for r in results)
        elapsed = loop.time() - start
        sniffer.recording = False
        busy, frames = model.busy_s - busy0, model.frames - frames0
    if bad or len(sniffer.frames) != 2 * MOTORS * cycles or frames != len(sniffer.frames):
        raise RuntimeError(
            f"efficiency run invalid: {bad} results not a StatusReply, {len(sniffer.frames)} frames "
            f"sniffed and {frames} on the bus model for {cycles} cycles of {MOTORS} exchanges"
        )
    wire_s = sum(model.frame_time_s(frame) for frame in sniffer.frames)
    if abs(wire_s - busy) > 1e-9 * max(1.0, busy):
        raise RuntimeError(f"sniffed wire time {wire_s} s disagrees with the bus model's busy time {busy} s")
    requests = [f for f in sniffer.frames if f.arbitration_id < 0x240]
    reply_bits = [model.frame_time_s(f) * model.bitrate for f in sniffer.frames if f.arbitration_id >= 0x240]
    request_bits = [model.frame_time_s(f) * model.bitrate for f in requests]
    return {
        "cycles": cycles,
        "virtual_s": elapsed,
        "wire_s": wire_s,
        "achieved_cycles_s": cycles / elapsed,
        "bound_cycles_s": cycles / wire_s,
        "wire_us_per_cycle": wire_s / cycles * 1e6,
        "request_bits": [min(request_bits), max(request_bits)],
        "reply_bits": [min(reply_bits), max(reply_bits)],
        "turnaround_s": devices[0].turnaround_s,
        "bitrate": model.bitrate,
    }


def efficiency(cfg: Config, log: Callable[[str], None]) -> dict[str, Any]:
    """Part 1: cycle() and sequential send-then-wait, ReadStatus2 and SpeedControl, on virtual time."""
    out: dict[str, Any] = {}
    commands: dict[str, Callable[[], Command]] = {
        "read_status2": ma.ReadStatus2,
        "speed_control": lambda: ma.SpeedControl(speed_dps=90.0),
    }
    for name, build in commands.items():
        for mode in ("cycle", "sequential"):
            run = virtual.run(efficiency_run(cfg.efficiency_cycles, build, mode == "sequential"))
            ratio = run["achieved_cycles_s"] / run["bound_cycles_s"]
            run["vs_bound"] = ratio
            if mode == "sequential":
                own = 1 / (run["wire_s"] / run["cycles"] + MOTORS * run["turnaround_s"])
                run["sequential_bound_cycles_s"] = own
                run["vs_sequential_bound"] = run["achieved_cycles_s"] / own
            out[f"{name}_{mode}"] = run
            log(
                f"  {name:<13} {mode:<10} {run['achieved_cycles_s']:8.2f} cycles/s (virtual), bound "
                f"{run['bound_cycles_s']:.2f} (wire {run['wire_us_per_cycle']:.0f} µs/cycle): {ratio:.4f}"
            )
    return out


# ================================================================ 2. zero-latency reflector


class Reflector:
    """A FrameLink (the contract of servobus.transports.contract) answering every frame with a
    prebuilt reply: all the cost measured is the Bus's. It runs on asyncio and on trio.

    ``send(frame, handle)`` reports the send (with the loop's time) to the send reporter at once,
    echoing ``handle``, and puts the reply found by the request's arbitration id on a list; the
    replies of one loop iteration are delivered to the consumer in one call, scheduled with the
    runtime lane's ``call_soon`` (asyncio's ``loop.call_soon``, trio's ``run_sync_soon``).
    """

    name = "reflector"
    rules = LineRules()

    def __init__(self, replies: dict[int, Frame]) -> None:
        self.replies = replies
        self._out: list[Frame] = []
        self._consumer: Consumer | None = None
        self._reporter: SendReporter | None = None
        self._open = False
        self.sent = 0

    @property
    def is_open(self) -> bool:
        return self._open

    async def open(self) -> None:
        runtime = current()
        self._time, self._call_soon = runtime.time, runtime.call_soon
        self._open = True

    async def close(self) -> None:
        self._open = False

    def set_consumer(self, consumer: Consumer | None) -> None:
        self._consumer = consumer

    def set_send_reporter(self, reporter: SendReporter | None) -> None:
        self._reporter = reporter

    def add_listener(self, listener: Callable[[Any], object]) -> None:
        pass

    def remove_listener(self, listener: Callable[[Any], object]) -> None:
        pass

    def stats(self) -> TransportStats:
        return TransportStats()

    def send(self, frame: Frame, handle: object = None) -> None:
        self.sent += 1
        reporter = self._reporter
        if reporter is not None:
            reporter(frame if handle is None else handle, self._time(), None)
        out = self._out
        if not out:
            self._call_soon(self._flush)
        out.append(self.replies[frame.arbitration_id])

    def _flush(self) -> None:
        out, self._out = self._out, []
        if self._consumer is not None:
            self._consumer(out)


def _message(frame: Frame) -> can.Message:
    return can.Message(arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=False)


class ReflectorBus(can.BusABC):
    """A python-can bus whose ``send`` puts the prebuilt reply into its own receive queue.

    With ``fd=True`` it also has a file descriptor (an eventfd, one count per queued reply), so a
    ``can.Notifier`` given a loop watches it with ``add_reader`` instead of starting a reader thread.
    """

    def __init__(self, replies: dict[int, Frame], *, fd: bool = False) -> None:
        super().__init__(channel="bench-reflector")
        self.replies = {ident: _message(frame) for ident, frame in replies.items()}
        self._rx: queue.SimpleQueue[can.Message] = queue.SimpleQueue()
        self._fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_SEMAPHORE) if fd else -1
        self.channel_info = "bench reflector" + (" (fd)" if fd else "")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._rx.put(self.replies[msg.arbitration_id])
        if self._fd >= 0:
            os.eventfd_write(self._fd, 1)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            if self._fd >= 0:
                message = self._rx.get_nowait()
                os.eventfd_read(self._fd)
                return message, False
            return self._rx.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def fileno(self) -> int:
        if self._fd < 0:
            raise NotImplementedError
        return self._fd

    def shutdown(self) -> None:
        super().shutdown()
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


@dataclass(frozen=True)
class Sample:
    """One repeat: transactions per second (wall clock) and process CPU µs per transaction."""

    rate: float
    cpu_us: float


async def _cycles(bus: Bus, cycles: int, motors: int = MOTORS) -> Sample:
    """Transactions/s of ``cycles`` cycles of ReadStatus2 over the bus's motors 1..n (after a warm-up)."""
    items = [(bus.motor(FAMILY, i), ma.ReadStatus2()) for i in range(1, motors + 1)]
    sample, last = await _timed(lambda: bus.cycle(items), cycles, motors)
    check(last, "last cycle", motors)
    return sample


async def _timed(
    cycle: Callable[[], Awaitable[Sequence[object]]], cycles: int, motors: int
) -> tuple[Sample, Sequence[object]]:
    """``cycles`` runs of ``cycle()`` after one warm-up: the rate and CPU per transaction, and the
    last run's results (for the caller to check)."""
    await cycle()  # warm-up
    cpu = time.process_time()
    start = time.perf_counter()
    for _ in range(cycles - 1):
        await cycle()
    last = await cycle()
    elapsed = time.perf_counter() - start
    cpu = time.process_time() - cpu
    return Sample(cycles * motors / elapsed, cpu / (cycles * motors) * 1e6), last


def check(results: Sequence[object], what: str, motors: int = MOTORS) -> None:
    bad = [r for r in results if not isinstance(r, ma.StatusReply)]
    if bad or len(results) != motors:
        raise RuntimeError(f"{what}: {len(bad)} of {len(results)} results are not a StatusReply: {bad[:1]}")


async def ours_reflector(cycles: int, replies: dict[int, Frame], motors: int = MOTORS) -> Sample:
    transport = Reflector(replies)
    async with Bus(transport) as bus:
        sample = await _cycles(bus, cycles, motors)
        stats = bus.stats()
    if stats.get("replies") != stats.get("requests") or len(stats) != 2:
        raise RuntimeError(f"reflector run: unexpected scheduler counts {stats}")
    return sample


async def floor_reflector(cycles: int, replies: dict[int, Frame], motors: int = MOTORS) -> Sample:
    """The bare asyncio floor: what a cycle costs with no codec, no scheduler, no Bus.

    Per cycle and motor: one future, kept in a dict by the request's arbitration id, and a "send" that
    appends the id to a list (the first one of a loop iteration schedules one ``call_soon`` callback, as
    the Reflector does); the callback resolves each future with the prebuilt reply frame; the cycle
    awaits ``asyncio.gather`` of the futures, as ``Bus.cycle()`` does. Everything the Bus adds on top of
    this (encoding, the scheduler's bookkeeping, matching, typed decoding, send reports, counters) is
    the difference between the two.
    """
    loop = asyncio.get_running_loop()
    family = get_family(FAMILY)
    request_ids = [family.bind(i).encode(ma.ReadStatus2()).arbitration_id for i in range(1, motors + 1)]
    pending: dict[int, asyncio.Future[Frame]] = {}
    out: list[int] = []

    def flush() -> None:
        batch = out[:]
        out.clear()
        for ident in batch:
            pending.pop(ident).set_result(replies[ident])

    async def cycle() -> list[Frame]:
        futures = []
        for ident in request_ids:
            future: asyncio.Future[Frame] = loop.create_future()
            pending[ident] = future
            futures.append(future)
            if not out:
                loop.call_soon(flush)
            out.append(ident)
        return await asyncio.gather(*futures)

    sample, last = await _timed(cycle, cycles, motors)
    if len(last) != motors or any(not isinstance(f, Frame) for f in last):
        raise RuntimeError(f"floor: {last[:1]}")
    return sample


async def floor_reflector_trio(cycles: int, replies: dict[int, Frame], motors: int = MOTORS) -> Sample:
    """The bare trio floor: the asyncio floor's loop with trio's primitives, and no anyio.

    Per cycle: ONE task parked with ``trio.lowlevel.wait_task_rescheduled`` (what a cycle awaits:
    trio has no future, and awaiting one ``trio.Event`` per request costs a checkpoint each); per
    motor, a "send" that appends the request's id to a list (the first of a loop iteration schedules
    one ``run_sync_soon`` callback, as the Reflector does on trio); the callback puts each prebuilt
    reply in its slot and reschedules the cycle's task when the last one came.
    """
    import trio

    family = get_family(FAMILY)
    request_ids = [family.bind(i).encode(ma.ReadStatus2()).arbitration_id for i in range(1, motors + 1)]
    run_soon = trio.lowlevel.current_trio_token().run_sync_soon
    reschedule, park = trio.lowlevel.reschedule, trio.lowlevel.wait_task_rescheduled
    pending: dict[int, int] = {}
    out: list[int] = []
    state: dict[str, Any] = {}

    def flush() -> None:
        batch = out[:]
        out.clear()
        results = state["results"]
        for ident in batch:
            results[pending.pop(ident)] = replies[ident]
        state["left"] -= len(batch)
        if not state["left"]:
            reschedule(state["task"])

    def abort(_: object) -> Any:
        return trio.lowlevel.Abort.SUCCEEDED

    async def cycle() -> list[Frame]:
        state["results"] = results = [None] * motors
        state["left"] = motors
        state["task"] = trio.lowlevel.current_task()
        for i, ident in enumerate(request_ids):
            pending[ident] = i
            if not out:
                run_soon(flush)
            out.append(ident)
        await park(abort)
        return results  # type: ignore[return-value]

    sample, last = await _timed(cycle, cycles, motors)
    if len(last) != motors or any(not isinstance(f, Frame) for f in last):
        raise RuntimeError(f"trio floor: {last[:1]}")
    return sample


async def _naive_loop(
    bus: can.BusABC, n: int, *, pipelined: bool = False, notifier_timeout: float = 0.05
) -> Sample:
    """python-can's asyncio recipe, one transaction at a time (or 32 sends, then 32 awaits)."""
    codecs: list[BoundCodec] = [get_family(FAMILY).bind(i) for i in _motor_ids()]
    reply_ids = [0x240 + i for i in _motor_ids()]
    reader = can.AsyncBufferedReader()
    notifier = can.Notifier(bus, [reader], timeout=notifier_timeout, loop=asyncio.get_running_loop())
    command = ma.ReadStatus2()

    async def transaction(k: int) -> None:
        codec = codecs[k]
        bus.send(_message(codec.encode(command)))
        message = await reader.get_message()
        take(message, k)

    def take(message: can.Message, k: int) -> None:
        if message.arbitration_id != reply_ids[k]:
            raise RuntimeError(f"naive: reply {message.arbitration_id:#x} for motor {k + 1}")
        reply = codecs[k].decode(Frame(arbitration_id=message.arbitration_id, data=bytes(message.data)))
        if not isinstance(reply, ma.StatusReply):
            raise RuntimeError(f"naive: {reply!r}")

    try:
        await transaction(0)  # warm-up (starts the Notifier's thread, if any)
        cpu = time.process_time()
        start = time.perf_counter()
        if pipelined:
            rounds = max(1, n // MOTORS)
            for _ in range(rounds):
                for k in range(MOTORS):
                    bus.send(_message(codecs[k].encode(command)))
                for k in range(MOTORS):
                    take(await reader.get_message(), k)
            done = rounds * MOTORS
        else:
            for i in range(n):
                await transaction(i % MOTORS)
            done = n
        elapsed = time.perf_counter() - start
        cpu = time.process_time() - cpu  # the whole process: the Notifier's thread included
    finally:
        notifier.stop()
    return Sample(done / elapsed, cpu / done * 1e6)


async def naive_reflector(
    n: int, replies: dict[int, Frame], *, fd: bool = False, pipelined: bool = False
) -> Sample:
    bus = ReflectorBus(replies, fd=fd)
    try:
        return await _naive_loop(bus, n, pipelined=pipelined)
    finally:
        bus.shutdown()


# ================================================================ 3. python-can's virtual interface


class VirtualReflector:
    """A peer thread on a second virtual bus object: every request gets its prebuilt reply."""

    def __init__(self, channel: str, replies: dict[int, Frame]) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.replies = {ident: _message(frame) for ident, frame in replies.items()}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="bench virtual reflector")
        self._thread.start()

    def _run(self) -> None:
        bus, replies = self.bus, self.replies
        while not self._stop.is_set():
            message = bus.recv(0.05)
            if message is not None:
                reply = replies.get(message.arbitration_id)
                if reply is not None:
                    bus.send(reply)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()


async def ours_virtual(cycles: int, replies: dict[int, Frame]) -> Sample:
    channel = _virtual._channel()
    peer = VirtualReflector(channel, replies)
    try:
        async with Bus(CanTransport("virtual", channel, ignore_config=True)) as bus:
            return await _cycles(bus, cycles)
    finally:
        peer.close()


async def naive_virtual(n: int, replies: dict[int, Frame]) -> Sample:
    channel = _virtual._channel()
    peer = VirtualReflector(channel, replies)
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        return await _naive_loop(bus, n)
    finally:
        bus.shutdown()
        peer.close()


# ================================================================ running, reporting


def alternate(
    runners: dict[str, Callable[[], Coroutine[Any, Any, Sample]]], repeats: int, log: Callable[[str], None]
) -> dict[str, list[Sample]]:
    """Every runner once per repeat, in turn, each in a fresh event loop."""
    samples: dict[str, list[Sample]] = {name: [] for name in runners}
    for repeat in range(repeats):
        for name, runner in runners.items():
            if name.startswith("trio_"):
                import trio

                sample = trio.run(runner)
            else:
                sample = asyncio.run(runner())
            samples[name].append(sample)
            log(
                f"  repeat {repeat + 1}/{repeats} {name:<22} {sample.rate:12,.0f} transactions/s "
                f"{sample.cpu_us:7.2f} CPU µs/transaction"
            )
    return samples


CYCLE_SIZES = (1, 4, 32)


def transactions(cfg: Config, log: Callable[[str], None]) -> dict[str, Any]:
    """Parts 2 and 3: the reflector (cycle() over 1, 4, 32 motors, the floor, the naive loops) and
    python-can's virtual interface."""
    replies = prebuilt_replies(ma.ReadStatus2())
    runners: dict[str, Callable[[], Coroutine[Any, Any, Sample]]] = {}
    for n in CYCLE_SIZES:
        # the same number of transactions per repeat for every size
        cycles = max(2, cfg.cycles * MOTORS // n)
        runners[f"cycle{n}"] = lambda n=n, c=cycles: ours_reflector(c, replies, n)  # type: ignore[misc]
        runners[f"floor{n}"] = lambda n=n, c=cycles: floor_reflector(c, replies, n)  # type: ignore[misc]
    cycles32 = max(2, cfg.cycles)
    runners |= {
        "trio_cycle32": lambda: ours_reflector(cycles32, replies, MOTORS),
        "trio_floor32": lambda: floor_reflector_trio(cycles32, replies, MOTORS),
        "naive": lambda: naive_reflector(cfg.naive, replies),
        "naive_fd": lambda: naive_reflector(cfg.naive, replies, fd=True),
        "naive_pipelined32": lambda: naive_reflector(cfg.naive, replies, pipelined=True),
    }
    print("zero-latency reflector, one core:", flush=True)
    samples = alternate(runners, cfg.repeats, log)
    print("python-can's virtual interface, a reflector thread on a second bus object:", flush=True)
    samples |= alternate(
        {
            "cycle32_virtual": lambda: ours_virtual(cfg.virtual_cycles, replies),
            "naive_virtual": lambda: naive_virtual(cfg.virtual_naive, replies),
        },
        cfg.repeats,
        log,
    )
    rates = {name: [s.rate for s in values] for name, values in samples.items()}
    cpu_runs = {name: [s.cpu_us for s in values] for name, values in samples.items()}
    cpu = {name: statistics.median(values) for name, values in cpu_runs.items()}
    med = {name: statistics.median(values) for name, values in rates.items()}
    spread = {name: [round(min(values)), round(max(values))] for name, values in rates.items()}
    return {"median": med, "spread": spread, "rates": rates, "cpu_us": cpu, "cpu_runs": cpu_runs}


PROFILED = {"cycle32": ours_reflector, "floor32": floor_reflector}


def spin(name: str, seconds: float) -> None:
    """Run ``name`` (cycle32 or floor32) on the reflector for ``seconds``: the profiled process."""
    replies = prebuilt_replies(ma.ReadStatus2())
    run = PROFILED[name]
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        asyncio.run(run(1000, replies, MOTORS))


def profiles(cfg: Config, seconds: float = 6.0) -> dict[str, Any]:
    """Where the time of cycle() over 32 motors and of the floor goes, on the reflector: py-spy (a
    sampling profiler, no distortion of small calls) over ``seconds`` of repeats in a child process,
    or cProfile of one repeat when py-spy is missing or fails."""
    replies = prebuilt_replies(ma.ReadStatus2())
    out: dict[str, Any] = {}
    for name, run in PROFILED.items():
        if _profile.pyspy_available():
            with tempfile.TemporaryDirectory(prefix="bench-bus-") as tmp:
                stacks = Path(tmp) / "stacks.txt"
                command = [sys.executable, str(Path(__file__).resolve()), "--spin", name, str(seconds)]
                done = _profile.pyspy_record(command, stacks, rate=500)
                if done.returncode == 0 and stacks.exists():
                    out[name] = _profile.collapsed(stacks, top=16)
                    continue
        out[name] = _profile.cprofile(lambda run=run: asyncio.run(run(cfg.cycles, replies, MOTORS)), top=16)
    return out


def summarise(eff: dict[str, Any], tx: dict[str, Any], cfg: Config) -> dict[str, Any]:
    med, spread, rates, cpu = tx["median"], tx["spread"], tx["rates"], tx["cpu_us"]
    cycle, seq = eff["read_status2_cycle"], eff["read_status2_sequential"]

    def paired(ours: str, theirs: str, cpu_time: bool = False) -> list[float]:
        """The ratio repeat by repeat (each pair ran back to back): how much the median ratio can move.
        Rates: ours / theirs; CPU µs per transaction: ours / theirs (a cost, so the other way round)."""
        source = tx["cpu_runs"] if cpu_time else rates
        ratios = [a / b for a, b in zip(source[ours], source[theirs], strict=True)]
        return [round(min(ratios), 2), round(max(ratios), 2)]

    sizes: dict[str, Any] = {}
    for n in CYCLE_SIZES:
        ours, floor = f"cycle{n}", f"floor{n}"
        sizes[str(n)] = {
            "transactions_s": round(med[ours]),
            "us_per_transaction": round(1e6 / med[ours], 2),
            "cpu_us_per_transaction": round(cpu[ours], 2),
            "floor_transactions_s": round(med[floor]),
            "floor_us_per_transaction": round(1e6 / med[floor], 2),
            "floor_cpu_us_per_transaction": round(cpu[floor], 2),
            "vs_floor": round(cpu[ours] / cpu[floor], 2),
            "vs_floor_per_repeat": paired(ours, floor, cpu_time=True),
            "vs_floor_wall": round(med[floor] / med[ours], 2),
            "vs_naive": round(med[ours] / med["naive"], 2),
            "vs_naive_per_repeat": paired(ours, "naive"),
            "spread_transactions_s": spread[ours],
            "floor_spread_transactions_s": spread[floor],
        }

    figures: dict[str, Any] = {
        "efficiency_can1m_32": round(cycle["vs_bound"], 4),
        "efficiency_can1m_32_command": "ReadStatus2",
        "efficiency_can1m_32_sequential": round(seq["vs_bound"], 4),
        "efficiency_can1m_32_speed_control": round(eff["speed_control_cycle"]["vs_bound"], 4),
        "efficiency_can1m_32_speed_control_sequential": round(eff["speed_control_sequential"]["vs_bound"], 4),
        "cycle32_transactions_s": round(med["cycle32"]),
        "cycle32_us_per_transaction": round(1e6 / med["cycle32"], 2),
        "cycle32_cpu_us_per_transaction": round(cpu["cycle32"], 2),
        "cycle32_vs_floor": sizes["32"]["vs_floor"],
        "cycle32_vs_floor_per_repeat": sizes["32"]["vs_floor_per_repeat"],
        "cycle32_vs_floor_basis": "CPU µs per transaction, ours / the floor's (median of repeats)",
        "cycle32_vs_floor_wall": sizes["32"]["vs_floor_wall"],
        "floor32_transactions_s": sizes["32"]["floor_transactions_s"],
        "trio_cycle32_transactions_s": round(med["trio_cycle32"]),
        "trio_cycle32_cpu_us_per_transaction": round(cpu["trio_cycle32"], 2),
        "trio_floor32_transactions_s": round(med["trio_floor32"]),
        "trio_cycle32_vs_floor": round(cpu["trio_cycle32"] / cpu["trio_floor32"], 2),
        "trio_cycle32_vs_floor_per_repeat": paired("trio_cycle32", "trio_floor32", cpu_time=True),
        "trio_floor": "one task per cycle parked with trio.lowlevel.wait_task_rescheduled, "
        "callbacks through run_sync_soon (floor_reflector_trio)",
        "trio_cycle32_vs_asyncio_cycle32": round(med["trio_cycle32"] / med["cycle32"], 2),
        "cycle_sizes": sizes,
        "naive_cpu_us_per_transaction": round(cpu["naive"], 2),
        "cycle32_vs_naive": round(med["cycle32"] / med["naive"], 2),
        "cycle32_vs_naive_per_repeat": paired("cycle32", "naive"),
        "naive_transactions_s": round(med["naive"]),
        "naive_fd_transactions_s": round(med["naive_fd"]),
        "cycle32_vs_naive_fd": round(med["cycle32"] / med["naive_fd"], 2),
        "naive_pipelined32_transactions_s": round(med["naive_pipelined32"]),
        "cycle32_vs_naive_pipelined32": round(med["cycle32"] / med["naive_pipelined32"], 2),
        "cycle32_python_can_virtual_transactions_s": round(med["cycle32_virtual"]),
        "naive_python_can_virtual_transactions_s": round(med["naive_virtual"]),
        "cycle32_python_can_virtual_vs_naive": round(med["cycle32_virtual"] / med["naive_virtual"], 2),
        "cycle32_python_can_virtual_vs_naive_per_repeat": paired("cycle32_virtual", "naive_virtual"),
        "spread_transactions_s": spread,
        "efficiency_detail": {
            name: {
                key: (round(value, 6) if isinstance(value, float) else value) for key, value in run.items()
            }
            for name, run in eff.items()
        },
        "sizes": {
            "efficiency_cycles": cfg.efficiency_cycles,
            "reflector_cycles": cfg.cycles,
            "naive_transactions": cfg.naive,
            "virtual_cycles": cfg.virtual_cycles,
            "virtual_naive_transactions": cfg.virtual_naive,
            "repeats": cfg.repeats,
        },
    }
    targets: dict[str, dict[str, Any]] = {
        "efficiency_can1m_32": {"min": EFFICIENCY_TARGET},
        "cycle32_transactions_s": {"min": TRANSACTIONS_TARGET},
        "cycle32_vs_naive": {"min": VS_NAIVE_TARGET},
        "cycle32_vs_floor": {"max": VS_FLOOR_TARGET},
    }
    for name, target in targets.items():
        target["met"] = figures[name] >= target["min"] if "min" in target else figures[name] <= target["max"]
    figures["targets"] = targets
    figures["targets_missed"] = [
        f"{name} = {figures[name]:,} (target {'>=' if 'min' in t else '<='} {t.get('min', t.get('max')):,})"
        for name, t in targets.items()
        if not t["met"]
    ]
    return figures


def render_markdown(figures: dict[str, Any], meta: dict[str, Any]) -> str:
    machine = meta["machine"]
    eff = figures["efficiency_detail"]
    cycle, seq = eff["read_status2_cycle"], eff["read_status2_sequential"]
    source = meta["source"]
    changed = (
        f"; uncommitted changes under src/ at run time: {', '.join(source['src_changes'])}"
        if source["src_changes"]
        else "; src/ clean"
    )

    def eff_row(label: str, run: dict[str, Any], extra: str = "") -> tuple[str, ...]:
        return (
            label,
            f"{run['achieved_cycles_s']:.2f}",
            f"{run['bound_cycles_s']:.2f}",
            f"{run['vs_bound']:.4f}",
            extra,
        )

    eff_rows = [
        eff_row("`cycle()`, ReadStatus2 (`efficiency_can1m_32`)", cycle, ">= 0.95"),
        eff_row(
            "sequential `await motor.request()`, ReadStatus2",
            seq,
            f"(baseline; {seq['vs_sequential_bound']:.4f} of its own bound "
            f"{seq['sequential_bound_cycles_s']:.2f})",
        ),
        eff_row("`cycle()`, SpeedControl(90 dps)", eff["speed_control_cycle"], "(info)"),
        eff_row(
            "sequential, SpeedControl(90 dps)",
            eff["speed_control_sequential"],
            "(info)",
        ),
    ]
    t = figures
    tx_rows = [
        (
            "`bus.cycle()` over 32 motors, ReadStatus2 -> StatusReply (`cycle32_transactions_s`)",
            f"{t['cycle32_transactions_s']:,}",
            f"{t['cycle32_us_per_transaction']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["cycle32"]),
            ">= 100,000",
        ),
        (
            "`bus.cycle()` over 32 motors on trio (`trio_cycle32_transactions_s`; CPU vs the trio "
            f"floor: `trio_cycle32_vs_floor` {t['trio_cycle32_vs_floor']:.2f})",
            f"{t['trio_cycle32_transactions_s']:,}",
            f"{1e6 / t['trio_cycle32_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["trio_cycle32"]),
            "(reported)",
        ),
        (
            "the bare trio floor (one parked task per cycle, `run_sync_soon`)",
            f"{t['trio_floor32_transactions_s']:,}",
            f"{1e6 / t['trio_floor32_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["trio_floor32"]),
            "(info)",
        ),
        (
            "naive python-can: send, await `AsyncBufferedReader` (Notifier thread), decode",
            f"{t['naive_transactions_s']:,}",
            f"{1e6 / t['naive_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["naive"]),
            "baseline",
        ),
        (
            "naive python-can, reflector with a file descriptor (Notifier on `add_reader`)",
            f"{t['naive_fd_transactions_s']:,}",
            f"{1e6 / t['naive_fd_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["naive_fd"]),
            "(info)",
        ),
        (
            "naive python-can pipelined: 32 sends, then 32 awaits (Notifier thread)",
            f"{t['naive_pipelined32_transactions_s']:,}",
            f"{1e6 / t['naive_pipelined32_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["naive_pipelined32"]),
            "(info)",
        ),
        (
            "`bus.cycle()` through `CanTransport` on python-can `virtual` "
            "(`cycle32_python_can_virtual_transactions_s`)",
            f"{t['cycle32_python_can_virtual_transactions_s']:,}",
            f"{1e6 / t['cycle32_python_can_virtual_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["cycle32_virtual"]),
            "(reported)",
        ),
        (
            "naive python-can on `virtual`, same peer",
            f"{t['naive_python_can_virtual_transactions_s']:,}",
            f"{1e6 / t['naive_python_can_virtual_transactions_s']:.2f}",
            "{:,} to {:,}".format(*t["spread_transactions_s"]["naive_virtual"]),
            "(info)",
        ),
    ]
    missed = figures["targets_missed"]
    sizes = figures["sizes"]
    lines = [
        "## Bus: `cycle()` over 32 MyActuator motors (`bench/bench_bus.py`)",
        "",
        f"- Command: `{meta['command']}` (from the repository root; {meta['runtime_s']:.0f} s)",
        f"- Date: {machine['date_utc']}; servobus {meta['servobus']} from `{meta['servobus_path']}`, "
        f"commit {source['commit']}{changed}",
        f"- Machine: {machine['platform']}; CPU {machine['cpu_model']}, {machine['cpu_count']} cores "
        "(shared, noisy)",
        f"- Python: {machine['python']}; python-can {can.__version__}; load average (1, 5, 15 min) at "
        "start: {}".format(", ".join(f"{x:.2f}" for x in meta["load_average_at_start"])),
        "",
        "### Efficiency on the simulated 1 Mbit/s CAN bus (virtual time, deterministic)",
        "",
        "`SimTransport` with 32 simulated `MyActuatorMotor`s "
        f"(turnaround {cycle['turnaround_s'] * 1e6:.0f} µs), "
        f"{sizes['efficiency_cycles']} cycles after one warm-up. Bound = 1 / (wire time of one cycle's 64 "
        "frames), each frame timed with the bus model's own `frame_time_s` (bit-exact: stuff bits, CRC, "
        f"ACK, EOF, 3-bit intermission): ReadStatus2 is {cycle['wire_us_per_cycle']:.0f} µs of wire per "
        f"cycle (requests {cycle['request_bits'][0]:.0f}-{cycle['request_bits'][1]:.0f} bits, replies "
        f"{cycle['reply_bits'][0]:.0f}-{cycle['reply_bits'][1]:.0f} bits). The bound leaves out the "
        "motors' turnaround: with 32 requests in flight it overlaps the other frames (requests win "
        "arbitration over replies, and 200 µs is shorter than the other 31 replies), so the wire-only "
        "bound is reachable. The sequential baseline pays the turnaround 32 times per cycle; its own "
        "bound, 1 / (wire + 32 x turnaround), is shown beside it. Virtual time: host CPU costs nothing "
        "here, so this is the Bus's scheduling (no idle wire), not its speed.",
        "",
        _results.markdown_table(
            ["run", "cycles/s (virtual)", "bound cycles/s", "achieved / bound", "target"], eff_rows, "lrrrl"
        ),
        "### Transactions per second, one core, zero-latency reflector",
        "",
        "A FrameLink (`Reflector` in bench_bus.py) answers each frame with a prebuilt reply by arbitration "
        "id, one consumer call per loop iteration, sends reported at once; so the time is servobus's: "
        "encode, scheduler, match, typed decode, futures. The naive baselines run on a `can.BusABC` that "
        "reflects the same prebuilt replies into its receive queue, one transaction at a time, and "
        "encode and decode with the same bound codec. Median of "
        f"{sizes['repeats']} repeats, alternated ({sizes['reflector_cycles']:,} cycles per repeat for "
        f"`cycle()`, {sizes['naive_transactions']:,} transactions for the naive loops; on `virtual`: "
        f"{sizes['virtual_cycles']:,} cycles and {sizes['virtual_naive_transactions']:,} transactions), "
        "GC on.",
        "",
        _results.markdown_table(
            ["path", "transactions/s", "µs/transaction", "spread", "target"], tx_rows, "lrrrl"
        ),
        f"- `bus.cycle32_vs_naive` = **{t['cycle32_vs_naive']:.2f}** (target >= {VS_NAIVE_TARGET:g}; "
        "repeat by repeat {:.2f} to {:.2f}); ".format(*t["cycle32_vs_naive_per_repeat"])
        + f"against the naive loop on a file descriptor: {t['cycle32_vs_naive_fd']:.2f}; against the "
        f"pipelined naive loop: {t['cycle32_vs_naive_pipelined32']:.2f}.",
        f"- On python-can's `virtual` interface: `cycle()` {t['cycle32_python_can_virtual_transactions_s']:,}"
        f"/s, {t['cycle32_python_can_virtual_vs_naive']:.2f}x the naive loop against the same peer thread "
        "(repeat by repeat {:.2f} to {:.2f}).".format(*t["cycle32_python_can_virtual_vs_naive_per_repeat"]),
        "",
        "### Orchestrator cost: `cycle()` over 1, 4 and 32 motors against the bare asyncio floor",
        "",
        "Same reflector, same repeats (alternated), the same number of transactions per repeat for every "
        "size. The **floor** (`floor_reflector` in bench_bus.py) is what a cycle costs in asyncio alone: one "
        "future per motor in a dict by arbitration id, a send that appends the id to a list (one "
        "`call_soon` per loop iteration, as the Reflector), a callback that resolves each future with the "
        "prebuilt reply frame, `asyncio.gather` of the futures. No codec, no scheduler. Our cost over it is "
        "encoding, the scheduler's bookkeeping (states, deadlines, keys), matching, typed decoding, send "
        "reports and counters. CPU µs = process CPU time per transaction (`time.process_time`; for the naive "
        "loop it includes python-can's Notifier thread).",
        "",
        _results.markdown_table(
            [
                "motors",
                "`cycle()` transactions/s",
                "µs (wall / CPU)",
                "floor transactions/s",
                "floor µs (wall / CPU)",
                "ours / floor (CPU µs)",
                "vs naive",
            ],
            [
                (
                    n,
                    f"{d['transactions_s']:,}",
                    f"{d['us_per_transaction']:.2f} / {d['cpu_us_per_transaction']:.2f}",
                    f"{d['floor_transactions_s']:,}",
                    f"{d['floor_us_per_transaction']:.2f} / {d['floor_cpu_us_per_transaction']:.2f}",
                    "**{:.2f}** ({:.2f} to {:.2f}; wall {:.2f})".format(
                        d["vs_floor"], *d["vs_floor_per_repeat"], d["vs_floor_wall"]
                    ),
                    "{:.2f} ({:.2f} to {:.2f})".format(d["vs_naive"], *d["vs_naive_per_repeat"]),
                )
                for n, d in t["cycle_sizes"].items()
            ],
            "rrrrrrr",
        ),
        f"The naive baseline (one transaction at a time, so the same loop for any motor count): "
        f"{t['naive_transactions_s']:,}/s, {1e6 / t['naive_transactions_s']:.2f} µs wall, "
        f"{t['naive_cpu_us_per_transaction']:.2f} CPU µs per transaction. "
        f"`bus.cycle32_vs_floor` = **{t['cycle32_vs_floor']:.2f}** (our CPU µs per transaction / the "
        f"floor's, medians; repeat by repeat as shown; by wall-clock rates {t['cycle32_vs_floor_wall']:.2f}; "
        f"target <= {VS_FLOOR_TARGET:g}). CPU time is the basis because it is the cost itself and does not "
        "count the time this shared machine gave to other processes.",
        "",
        "Missed: " + ("; ".join(missed) if missed else "none: every target met."),
    ]
    titles = (("cycle32", "`cycle()` over 32 motors on the reflector"), ("floor32", "the floor, 32 motors"))
    for name, title in titles:
        profile = t.get("profiles", {}).get(name)
        if profile:
            unit_us = t["cycle_sizes"]["32"][
                "cpu_us_per_transaction" if name == "cycle32" else "floor_cpu_us_per_transaction"
            ]
            lines += [
                "",
                f"### Where the time goes: {title} ({profile['tool']})",
                "",
                "Shares of the profiled process's samples; µs = share x the measured CPU µs per transaction "
                f"({unit_us:.2f})."
                + (
                    " `Bus.cycle` (the send side) and the Reflector's flush into `Delivery.on_frames` (the "
                    "receive side) are the two halves."
                    if name == "cycle32"
                    else ""
                ),
                "",
            ]
            lines += _profile.markdown(profile, 16, unit_us=unit_us, unit="transaction")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, 2 repeats (CI smoke run)")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--spin", nargs=2, metavar=("NAME", "SECONDS"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.spin:
        spin(args.spin[0], float(args.spin[1]))
        return 0
    started = time.perf_counter()
    load_at_start = [round(x, 2) for x in os.getloadavg()]  # others' work on this machine skews a run
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    log = lambda line: print(line, flush=True)  # noqa: E731
    print(f"bench_bus ({cfg.mode}): {MOTORS} MyActuator motors", flush=True)
    print("efficiency on the simulated 1 Mbit/s bus, virtual time:", flush=True)
    eff = efficiency(cfg, log)
    tx = transactions(cfg, log)
    figures = summarise(eff, tx, cfg)
    if not args.quick:
        print("profiles (py-spy) of cycle() over 32 motors and of the floor:", flush=True)
        figures["profiles"] = profiles(cfg)
    arguments = sys.argv[1:] if argv is None else list(argv)
    meta = {
        "command": _meta.command_line("bench/bench_bus.py", arguments),
        "servobus_path": str(Path(servobus.__file__).resolve().parent),
        "machine": _results.machine_info(),
        "servobus": servobus.__version__,
        "python_can": can.__version__,
        "source": _meta.source_state(),
        "load_average_at_start": load_at_start,
        "mode": cfg.mode,
        "statistic": "median",
        "runtime_s": round(time.perf_counter() - started, 1),
    }
    print()
    print(
        f"efficiency_can1m_32 {figures['efficiency_can1m_32']:.4f} (sequential "
        f"{figures['efficiency_can1m_32_sequential']:.4f}); cycle32 {figures['cycle32_transactions_s']:,} "
        f"transactions/s ({figures['cycle32_us_per_transaction']:.2f} µs), naive "
        f"{figures['naive_transactions_s']:,}/s, ratio {figures['cycle32_vs_naive']:.2f}, vs floor "
        f"{figures['cycle32_vs_floor']:.2f}; trio {figures['trio_cycle32_transactions_s']:,}/s, vs its "
        f"floor {figures['trio_cycle32_vs_floor']:.2f}; on virtual "
        f"{figures['cycle32_python_can_virtual_transactions_s']:,}/s"
    )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All targets met.")
    if out_dir is not None:
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, meta))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": meta})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Bus efficiency on virtual time: achieved cycles/s over the theoretical bound, on every bus servobus drives.

Every run puts simulated motors on a simulated bus and runs the Bus on a virtual-time loop
(:func:`servobus.sim.virtual.run`), so host CPU costs nothing and the figure is the Bus's scheduling
alone: does it keep the wire as busy as the protocol allows? Deterministic: one run per figure.

Buses (``efficiency.<bus>_<motors>``, 1, 4, 8, 16 and 32 motors):

* ``can1m``: classic CAN at 1 Mbit/s, MyActuator motors, ``bus.cycle()`` of ``ReadStatus2`` to each
  (``SimTransport``: the simulator's bit-exact bus model, 200 µs motor turnaround).
* ``canfd1m5m``: CAN FD, 1 Mbit/s nominal and 5 Mbit/s data (bit-rate switch), hollow motors in CAN FD
  mode, ``bus.cycle()`` of the 16-byte status poll (``FdCommand()``; 500 µs turnaround, the hollow
  manual's bound and the simulator's default).
* ``rs485_115200``, ``rs485_1m``, ``rs485_2500k``: one half-duplex RS485 line, MyActuator motors' RS485
  front, ``bus.cycle()`` of ``ReadStatus2``. The simulator has no in-process serial path, so
  :class:`_serial_line.SerialLine` joins the Bus to the simulator's serial devices on the loop's clock;
  it declares the rules :class:`~servobus.transports.rs485.SerialTransport` declares for the same framing
  and baud rate (half duplex, one request outstanding, a 3.5-character gap).

Patterns on classic CAN at 1 Mbit/s (same key form, ``<bus>_<pattern>_<motors>``):

* ``can1m_bcast_<n>``: ``bus.broadcast(ReadStatus2(), motors)``: one 0x280 frame, n replies.
* ``can1m_lkmulti_<n>``: LK V2.35's multi-motor torque frame (0x280, motors 1..4 only, so n = 1 and 4)
  through ``bus.broadcast(MultiMotorTorque(...))``: one frame, n status-2 replies.
* ``can1m_stream_<n>``: every motor streams ``ReadStatus2`` by 0xB6 at 10 ms (its shortest interval)
  through ``motor.stream()``; a cycle is one stream frame from every motor.

**The bound.** From the frames actually on the wire in each cycle (a passive sniffer on the simulated
bus records them; each timed with the bus model's own bit-exact ``frame_time_s``, and their sum checked
against the model's busy time) and the devices' turnaround ``ta``:

* CAN (request/reply): a cycle cannot be shorter than its wire time W (every request and reply frame),
  nor than ``R1 + .. + Rj + ta + (the replies still owed after request j)`` for any j: the requests go
  back to back at best, the reply to request j is ready ``ta`` after it, and every reply owed from then
  on still has to cross the wire (the smallest ones are counted, so no reply matching is assumed). The
  bound is the larger; with many motors it is W (the turnaround hides behind other frames), with one
  motor it is request + ta + reply. For a broadcast: request + ta + all replies.
* RS485 (half duplex, one exchange at a time): per exchange, request bytes + ``ta`` + reply bytes on the
  line (10 bits per byte, 8N1: ``servobus.timing.uart_time_s``) + the ``gap_s`` rest the transport
  declares after each exchange (3.5 characters: 304 µs at 115200 baud, 35 µs at 1 Mbaud, 14 µs at
  2.5 Mbaud). The bound without the gap is given too.
* streams: ``min(1 / interval, 1 / (n x one stream frame's wire time))`` cycles/s.

Efficiency = sum of the cycles' bounds / the virtual time the cycles took (1.0: no idle wire the
protocol did not force). Target: >= 0.95 for every ``<bus>_<motors>``.

Usage (from the repository root)::

    python bench/bench_efficiency.py            # full (~1 min): writes bench/RESULTS.md, results.json
    python bench/bench_efficiency.py --quick    # a few cycles per run, writes nothing
    python -m bench --only efficiency           # the same through the suite's runner
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _profile  # noqa: E402
import _results  # noqa: E402
from _serial_line import SerialLine  # noqa: E402
from servobus.bus import Bus  # noqa: E402
from servobus.frame import Frame  # noqa: E402
from servobus.protocols import Command, Reply, get_family, hollow, lk  # noqa: E402  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402
from servobus.protocols.hollow.sim.device import HollowMotor  # noqa: E402
from servobus.protocols.lk.sim.device import LkMotor  # noqa: E402
from servobus.protocols.myactuator.sim.device import MyActuatorMotor  # noqa: E402
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor  # noqa: E402
from servobus.scheduler import Traffic  # noqa: E402
from servobus.sim import virtual  # noqa: E402
from servobus.sim.canbus import CanBusModel  # noqa: E402
from servobus.sim.device import Device, Emission  # noqa: E402
from servobus.transports.sim import SimTransport  # noqa: E402

KEY = "efficiency"
TARGET = 0.95
MOTOR_COUNTS = (1, 4, 8, 16, 32)
STREAM_INTERVAL_MS = 10


@dataclass(frozen=True)
class Config:
    mode: str
    cycles: int  # cycles measured per run, after one warm-up cycle
    stream_s: float  # virtual seconds of stream frames counted


FULL = Config("full", 200, 10.0)
QUICK = Config("quick", 4, 0.2)


# ---------------------------------------------------------------------------------------------- CAN


@dataclass(frozen=True)
class CanSpec:
    """One kind of CAN bus and the motors on it."""

    key: str
    label: str
    bitrate: int
    data_bitrate: int | None
    family: str
    device: Callable[[int], Device]
    command: Callable[[], Command]
    reply: type[Reply]
    bind: dict[str, Any] = field(default_factory=dict)


CAN = CanSpec(
    "can1m",
    "classic CAN 1 Mbit/s",
    1_000_000,
    None,
    "myactuator",
    MyActuatorMotor,
    ma.ReadStatus2,
    ma.StatusReply,
)
CANFD = CanSpec(
    "canfd1m5m",
    "CAN FD 1/5 Mbit/s (BRS)",
    1_000_000,
    5_000_000,
    "hollow",
    lambda i: HollowMotor(i, fd_enabled=True),
    hollow.FdCommand,
    hollow.FdReply,
    {"link": "canfd"},
)
_LK_MODEL = lk.LkModel(revision=lk.Revision.V2_35)
LK = CanSpec(
    "can1m",
    "classic CAN 1 Mbit/s, LK V2.35",
    1_000_000,
    None,
    "lk",
    lambda i: LkMotor(i, model=_LK_MODEL),
    lambda: lk.MultiMotorTorque(motor_type=_LK_MODEL.motor_type, currents_a=(0.0, 0.0, 0.0, 0.0)),
    lk.Status2Reply,
    {"revision": "V2_35"},
)


class Sniffer:
    """A passive node on the simulated bus: records every frame and when it ended (it sends none)."""

    name = "bench-sniffer"

    def __init__(self) -> None:
        self.frames: list[tuple[float, Frame]] = []
        self.recording = False

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        if self.recording:
            self.frames.append((now_s, frame))
        return []

    def poll(self, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


def can_cycle_bound(requests: Sequence[float], replies: Sequence[float], turnaround_s: float) -> float:
    """The least time a cycle of these frames (wire times, requests in the order sent) can take.

    The larger of the total wire time and, for every request j, the time its requests take back to back,
    the turnaround, and the replies still owed from then on (the smallest ones, so no matching is needed).
    """
    if not requests:
        raise ValueError("a cycle without requests")
    wire = sum(requests) + sum(replies)
    per_request = len(replies) // len(requests)
    smallest = sorted(replies)
    best = wire
    sent = 0.0
    for j, request in enumerate(requests):
        sent += request
        owed = len(replies) - j * per_request
        best = max(best, sent + turnaround_s + sum(smallest[:owed]))
    return best


async def can_run(spec: CanSpec, motors_n: int, cycles: int, pattern: str = "cycle") -> dict[str, Any]:
    """``cycles`` cycles of ``pattern`` ("cycle" or "broadcast") over motors 1..n on virtual time."""
    sniffer = Sniffer()
    devices = [spec.device(i) for i in range(1, motors_n + 1)]
    model = CanBusModel(bitrate=spec.bitrate, data_bitrate=spec.data_bitrate)
    transport = SimTransport(devices=[*devices, sniffer], bus=model)
    loop = asyncio.get_running_loop()
    async with Bus(transport) as bus:
        motors = [bus.motor(spec.family, i, **spec.bind) for i in range(1, motors_n + 1)]

        async def one() -> None:
            if pattern == "cycle":
                results = await bus.cycle([(m, spec.command()) for m in motors])
            else:
                results = list((await bus.broadcast(spec.command(), motors)).values())
            bad = [r for r in results if not isinstance(r, spec.reply)]
            if bad or len(results) != motors_n:
                raise RuntimeError(f"{spec.key} {pattern} x{motors_n}: {len(bad)} bad results: {bad[:1]}")

        await one()  # warm-up: every motor answered once
        sniffer.recording = True
        busy0, frames0 = model.busy_s, model.frames
        marks = [transport.network_time(loop.time())]
        for _ in range(cycles):
            await one()
            marks.append(transport.network_time(loop.time()))
        sniffer.recording = False
        busy, n_frames = model.busy_s - busy0, model.frames - frames0
    frames = sniffer.frames
    expected = cycles * (2 * motors_n if pattern == "cycle" else motors_n + 1)
    if len(frames) != expected or n_frames != expected:
        raise RuntimeError(
            f"{spec.key} {pattern} x{motors_n}: {len(frames)} frames sniffed, {expected} expected"
        )
    wire = sum(model.frame_time_s(f) for _, f in frames)
    if abs(wire - busy) > 1e-9 * max(1.0, busy):
        raise RuntimeError(f"sniffed wire time {wire} s disagrees with the bus model's busy time {busy} s")
    turnaround = min(float(getattr(d, "turnaround_s", 0.0)) for d in devices)
    bounds = []
    k = 0
    for end in marks[1:]:
        requests: list[float] = []
        replies: list[float] = []
        while k < len(frames) and frames[k][0] <= end + 1e-12:
            frame = frames[k][1]
            (replies if frame.is_rx else requests).append(model.frame_time_s(frame))
            k += 1
        bounds.append(can_cycle_bound(requests, replies, turnaround))
    if k != len(frames):
        raise RuntimeError(f"{len(frames) - k} frames ended after the last cycle")
    elapsed = marks[-1] - marks[0]
    bound = sum(bounds)
    return {
        "bus": spec.label,
        "pattern": pattern,
        "motors": motors_n,
        "cycles": cycles,
        "virtual_s": elapsed,
        "achieved_cycles_s": cycles / elapsed,
        "bound_cycles_s": cycles / bound,
        "efficiency": bound / elapsed,
        "wire_us_per_cycle": wire / cycles * 1e6,
        "bound_us_per_cycle": bound / cycles * 1e6,
        "turnaround_us": turnaround * 1e6,
        "bus_load": wire / elapsed,
    }


async def stream_run(motors_n: int, seconds: float) -> dict[str, Any]:
    """Every motor streams ReadStatus2 at 10 ms through ``motor.stream()``; frames counted for ``seconds``."""
    sniffer = Sniffer()
    devices = [MyActuatorMotor(i) for i in range(1, motors_n + 1)]
    transport = SimTransport(devices=[*devices, sniffer])
    model = transport.network.bus
    loop = asyncio.get_running_loop()
    arrivals: list[float] = []

    def note(motor: object, traffic: Traffic, reply: Reply) -> None:
        if traffic is Traffic.STREAM and isinstance(reply, ma.StatusReply):
            arrivals.append(loop.time())

    interval = STREAM_INTERVAL_MS / 1000
    async with Bus(transport) as bus:
        bus.subscribe(note)
        motors = [bus.motor("myactuator", i) for i in range(1, motors_n + 1)]
        async with contextlib.AsyncExitStack() as stack:
            for motor in motors:
                await stack.enter_async_context(motor.stream(ma.ReadStatus2, interval_ms=STREAM_INTERVAL_MS))
            start = loop.time() + interval / 2  # every stream is on; half a period off every frame's time
            sniffer.recording = True
            await asyncio.sleep(seconds + interval)
            sniffer.recording = False
    counted = sum(1 for t in arrivals if start <= t < start + seconds)
    stream_frames = [f for _, f in sniffer.frames if f.is_rx and f.data[:1] == b"\x9c"]
    frame_s = sum(model.frame_time_s(f) for f in stream_frames) / max(1, len(stream_frames))
    bound = min(1 / interval, 1 / (motors_n * frame_s))
    achieved = counted / motors_n / seconds
    return {
        "bus": CAN.label,
        "pattern": "stream",
        "motors": motors_n,
        "seconds": seconds,
        "frames": counted,
        "achieved_cycles_s": achieved,
        "bound_cycles_s": bound,
        "efficiency": achieved / bound,
        "wire_us_per_cycle": frame_s * motors_n * 1e6,
        "interval_ms": STREAM_INTERVAL_MS,
        "bus_load": frame_s * motors_n * achieved,
    }


# -------------------------------------------------------------------------------------------- RS485


RS485_BAUDS = {"rs485_115200": 115_200, "rs485_1m": 1_000_000, "rs485_2500k": 2_500_000}


async def rs485_run(baud: int, motors_n: int, cycles: int) -> dict[str, Any]:
    """``cycles`` cycles of ReadStatus2 over motors 1..n on one simulated RS485 line, virtual time."""
    devices = [MyActuatorRs485Motor(MyActuatorMotor(i)) for i in range(1, motors_n + 1)]
    line = SerialLine(devices, get_family("myactuator").bind(1, link="rs485").framing, baud)
    loop = asyncio.get_running_loop()
    async with Bus(line) as bus:
        motors = [bus.motor("myactuator", i, link="rs485") for i in range(1, motors_n + 1)]
        items = [(m, ma.ReadStatus2()) for m in motors]
        await bus.cycle(items)  # warm-up
        first = len(line.log)
        start = loop.time()
        for _ in range(cycles):
            results = await bus.cycle(items)
            bad = [r for r in results if not isinstance(r, ma.StatusReply)]
            if bad:
                raise RuntimeError(f"rs485 {baud} x{motors_n}: {len(bad)} bad results: {bad[:1]}")
        elapsed = loop.time() - start
    uses = line.log[first:]
    exchanges = cycles * motors_n
    if len(uses) != 2 * exchanges or sum(u.who == "host" for u in uses) != exchanges:
        raise RuntimeError(f"rs485 {baud} x{motors_n}: {len(uses)} transmissions for {exchanges} exchanges")
    wire = sum(u.end_s - u.start_s for u in uses)
    turnaround = devices[0].motor.turnaround_s
    bound = wire + exchanges * (turnaround + line.rules.gap_s)
    no_gap = wire + exchanges * turnaround
    return {
        "bus": f"RS485 {baud:,} baud (8N1, half duplex)",
        "pattern": "cycle",
        "motors": motors_n,
        "cycles": cycles,
        "virtual_s": elapsed,
        "achieved_cycles_s": cycles / elapsed,
        "bound_cycles_s": cycles / bound,
        "efficiency": bound / elapsed,
        "vs_bound_without_gap": no_gap / elapsed,
        "wire_us_per_cycle": wire / cycles * 1e6,
        "bound_us_per_cycle": bound / cycles * 1e6,
        "turnaround_us": turnaround * 1e6,
        "gap_us": line.rules.gap_s * 1e6,
        "declared_turnaround_us": line.rules.turnaround_s * 1e6,
        "bus_load": wire / elapsed,
    }


# ------------------------------------------------------------------------------------------ running


def runs(cfg: Config) -> dict[str, Callable[[], dict[str, Any]]]:
    """Every figure's name and how to measure it (each on a fresh virtual-time loop)."""
    out: dict[str, Callable[[], dict[str, Any]]] = {}
    for n in MOTOR_COUNTS:
        out[f"can1m_{n}"] = lambda n=n: virtual.run(can_run(CAN, n, cfg.cycles))
    for n in MOTOR_COUNTS:
        out[f"canfd1m5m_{n}"] = lambda n=n: virtual.run(can_run(CANFD, n, cfg.cycles))
    for name, baud in RS485_BAUDS.items():
        for n in MOTOR_COUNTS:
            out[f"{name}_{n}"] = lambda n=n, baud=baud: virtual.run(rs485_run(baud, n, cfg.cycles))
    for n in MOTOR_COUNTS:
        out[f"can1m_bcast_{n}"] = lambda n=n: virtual.run(can_run(CAN, n, cfg.cycles, "broadcast"))
    for n in (1, 4):
        out[f"can1m_lkmulti_{n}"] = lambda n=n: virtual.run(can_run(LK, n, cfg.cycles, "broadcast"))
    for n in MOTOR_COUNTS:
        out[f"can1m_stream_{n}"] = lambda n=n: virtual.run(stream_run(n, cfg.stream_s))
    return out


def measure(cfg: Config, log: Callable[[str], None], only: Sequence[str] = ()) -> dict[str, dict[str, Any]]:
    detail: dict[str, dict[str, Any]] = {}
    for name, run in runs(cfg).items():
        if only and not any(name.startswith(prefix) for prefix in only):
            continue
        started = time.perf_counter()
        result = run()
        result["wall_s"] = round(time.perf_counter() - started, 3)
        detail[name] = result
        log(
            f"  {name:<20} {result['achieved_cycles_s']:10.2f} cycles/s, "
            f"bound {result['bound_cycles_s']:10.2f}: {result['efficiency']:.4f}  ({result['wall_s']:.2f} s)"
        )
    return detail


def is_grid(name: str) -> bool:
    """``<bus>_<motors>`` (the issue's keys), as opposed to ``<bus>_<pattern>_<motors>``."""
    return name.rsplit("_", 1)[0] in ("can1m", "canfd1m5m", *RS485_BAUDS)


def summarise(detail: dict[str, dict[str, Any]]) -> dict[str, Any]:
    figures: dict[str, Any] = {name: round(d["efficiency"], 4) for name, d in detail.items()}
    grid = [name for name in detail if is_grid(name)]
    missed = [f"{name} = {figures[name]:.4f} (target >= {TARGET})" for name in grid if figures[name] < TARGET]
    figures["targets"] = {"min": TARGET, "applies_to": "every <bus>_<motors>", "met": not missed}
    figures["targets_missed"] = missed
    figures["detail"] = {
        name: {k: (round(v, 6) if isinstance(v, float) else v) for k, v in d.items()}
        for name, d in detail.items()
    }
    return figures


def render_markdown(figures: dict[str, Any], info: dict[str, Any]) -> str:
    detail = figures["detail"]
    lines = _meta.header_lines("## Bus efficiency on virtual time (`bench/bench_efficiency.py`)", info)
    lines += [
        "",
        "Simulated motors on a simulated bus, the Bus on a virtual-time loop: host CPU costs nothing, so "
        "this is the Bus's scheduling alone. Deterministic (one run per figure; the same numbers every run). "
        f"{info['cycles']} cycles per run after a warm-up cycle; streams counted over {info['stream_s']:g} "
        "virtual seconds. Efficiency = the cycles' theoretical bound / the time they took.",
        "",
        "**Bounds.** CAN: a cycle takes at least its wire time (every frame timed bit-exactly, stuff bits "
        "included, as the bus model times it; the sum is checked against the model's busy time), and at "
        "least requests 1..j back to back + the motor's turnaround + every reply still owed after request "
        "j, for each j (so one motor's bound is request + turnaround + reply; with many, the turnaround "
        "hides behind other frames and the bound is the wire time). Broadcast: request + turnaround + all "
        "replies. RS485: per exchange, request and reply bytes at 10 bits per byte (8N1, "
        "`servobus.timing.uart_time_s`) + the motor's turnaround (200 µs) + the 3.5-character `gap_s` "
        "rest that `SerialTransport` declares for the line and the Bus keeps after every exchange "
        "(304 µs at 115200, 35 µs at 1 Mbaud, 14 µs at 2.5 Mbaud; the line's declared `turnaround_s` is "
        "the same value and is not added twice). The RS485 line is `bench/_serial_line.py`: the simulator "
        "has no in-process serial path, so it joins the Bus to the simulator's serial devices "
        "(`MyActuatorRs485Motor`) on the loop's clock, with the rules `SerialTransport` declares. "
        "Streams: min(1 / interval, 1 / (n x stream frame wire time)).",
        "",
    ]
    buses = [
        ("can1m", "classic CAN 1 Mbit/s, MyActuator, `cycle()` of ReadStatus2"),
        ("canfd1m5m", "CAN FD 1/5 Mbit/s, hollow FD, `cycle()` of the 16-byte poll"),
        ("rs485_115200", "RS485 115200 baud, MyActuator, `cycle()` of ReadStatus2"),
        ("rs485_1m", "RS485 1 Mbaud, MyActuator"),
        ("rs485_2500k", "RS485 2.5 Mbaud, MyActuator"),
        ("can1m_bcast", "CAN 1 Mbit/s, `broadcast()` 0x280 ReadStatus2"),
        ("can1m_lkmulti", "CAN 1 Mbit/s, LK multi-motor torque 0x280 (motors 1..4)"),
        ("can1m_stream", "CAN 1 Mbit/s, 0xB6 streams of ReadStatus2 every 10 ms"),
    ]
    rows = []
    for prefix, label in buses:
        for n in MOTOR_COUNTS:
            name = f"{prefix}_{n}"
            if name not in detail:
                continue
            d = detail[name]
            rows.append(
                (
                    f"`{name}`",
                    label if n == min(m for m in MOTOR_COUNTS if f"{prefix}_{m}" in detail) else "",
                    n,
                    f"{d['achieved_cycles_s']:,.2f}",
                    f"{d['bound_cycles_s']:,.2f}",
                    f"**{d['efficiency']:.4f}**",
                    f"{d['bus_load']:.0%}",
                )
            )
    lines += [
        _results.markdown_table(
            [
                "key",
                "bus, pattern",
                "motors",
                "cycles/s (virtual)",
                "bound cycles/s",
                "efficiency",
                "wire busy",
            ],
            rows,
            "llrrrrr",
        ),
        f"Target: >= {TARGET} for every `<bus>_<motors>` (the first five buses). "
        + (
            "Missed: " + "; ".join(figures["targets_missed"]) if figures["targets_missed"] else "Met for all."
        ),
    ]
    rs = [detail[n] for n in detail if n.startswith("rs485")]
    if rs:
        lines += [
            "",
            "RS485 against the bound without the gap (wire + turnaround only): "
            + ", ".join(
                f"`{n}` {detail[n]['vs_bound_without_gap']:.3f}"
                for n in detail
                if n.startswith("rs485") and n.endswith("_32")
            )
            + ": the declared gap is what separates them.",
        ]
    if figures.get("profile"):
        lines += [
            "",
            "### Where the time goes: `can1m_32` (cProfile of one run)",
            "",
            "On virtual time the figure does not depend on host speed; this is where the run's wall-clock "
            "time goes (the simulator's bus and motor models against the Bus itself), for whoever wants "
            "the efficiency runs faster.",
            "",
            *_profile.markdown(figures["profile"], 10),
        ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick", action="store_true", help="a few cycles per run (CI smoke run), writes nothing"
    )
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--only", action="append", default=[], help="figure name prefix (repeatable)")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    load = _meta.load_average()
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    print(f"bench_efficiency ({cfg.mode}): virtual time, {cfg.cycles} cycles per run", flush=True)
    detail = measure(cfg, lambda line: print(line, flush=True), args.only)
    figures = summarise(detail)
    if not args.quick:
        figures["profile"] = _profile.cprofile(lambda: virtual.run(can_run(CAN, 32, cfg.cycles)), top=12)
    arguments = list(sys.argv[1:] if argv is None else argv)
    info = _meta.meta(
        "bench/bench_efficiency.py",
        arguments,
        mode=cfg.mode,
        cycles=cfg.cycles,
        stream_s=cfg.stream_s,
        load_average_at_start=load,
        statistic="one deterministic run per figure (virtual time)",
        runtime_s=round(time.perf_counter() - started, 1),
    )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All efficiency targets met.")
    if out_dir is not None and not args.only:
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

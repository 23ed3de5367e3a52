"""The simulator's own cost: the C engine against the Python models, in the same run (issue [simcore]).

What is measured (both networks get the same seeded trace, repeats alternated, medians):

* ``sim.us_per_exchange``: CPU (``time.process_time``) per simulated request/reply pair through
  :class:`~servobus.sim.corenet.CoreCanNetwork`: 32 MyActuator motors on one 1 Mbit/s bus, a control
  loop's traffic: every cycle each motor gets a position set-point (0xA4, a sine with seeded noise and
  speed limit) or, every fourth cycle, a status read (0x9C), and the next cycle starts when the 32 replies
  are in (the bus saturated). The network is driven the way :class:`~servobus.transports.sim.SimTransport`
  drives it: requests ``send`` one by one, then ``host_turn`` per wake-up (the network run to the
  host's time and ahead past it, one C call) until the replies are in, request frames built before
  the clock starts, the host's reply :class:`~servobus.frame.Frame` objects (stamped) counted in.
  A tree from before ``host_turn`` (``--before``) is driven as this bench drove it then:
  ``next_event_s`` -> ``advance`` -> ``run_ahead``, the network's (cached, unstamped) reply Frames
  counted in and the transport's stamped copy of each not (so its figure is, if anything, low).
  ``sim.python_us_per_exchange``: the same through the Python reference
  (:class:`~servobus.sim.network.SimCanNetwork` and the device models alone); ``sim.vs_python`` = the ratio.
  The replies (time, id, bytes) of an untimed run of the trace must be identical between the two, or
  the bench stops; the timed runs only count replies, with the start-up objects frozen out of the
  garbage collector (``gc.freeze``) as a long-running control process would have them.
* ``sim.virtual_speedup``: 10 virtual seconds of that scenario (32 motors saturating the bus, ~4,000
  pairs per virtual second) / the wall time it took, through CoreCanNetwork; the trace is the same for
  the same seed (checked: two runs, one digest). ``sim.virtual_speedup_python``: the same through the
  Python models. ``sim.virtual_speedup_transport``: the same scenario through ``SimTransport`` on a
  virtual-time asyncio loop (``servobus.sim.virtual``), for the cost the event loop adds (info).
* ``sim.instructions_per_exchange`` (with ``--instructions``): instructions per pair of the exchange
  trace, counted by valgrind's callgrind (two repeats minus none), and ``sim.before``'s: a figure the
  load of this shared machine does not move.
* ``sim.before``: with ``--before TREE``, the C engine's figures of the code in TREE (e.g. the main
  branch before this issue), each measured by this script in a child process with
  ``PYTHONPATH=TREE/src`` right next to this tree's own run of the same figure (exchange: one child
  run per repeat, alternately before and after; speed-ups: before each of the three), medians;
  ``sim.vs_before`` = its exchange figure / this tree's, ``sim.speedup_vs_before`` = this tree's
  speed-up / its.

Usage (from the repository root)::

    python bench/bench_sim.py            # full: 7 repeats, writes bench/RESULTS.md and results.json
    python bench/bench_sim.py --before /work/main   # the same, beside the code in that tree
    SERVOBUS_BENCH_BEFORE=/work/main python -m bench --only sim   # the same through the runner
    python bench/bench_sim.py --quick    # CI smoke run, writes nothing
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import hashlib
import math
import os
import random
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _results  # noqa: E402
from servobus.frame import Frame  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402
from servobus.protocols.myactuator.sim.device import MyActuatorMotor  # noqa: E402
from servobus.sim import virtual  # noqa: E402
from servobus.sim.corenet import CoreCanNetwork  # noqa: E402
from servobus.sim.network import SimCanNetwork  # noqa: E402

KEY = "sim"
REPO = BENCH_DIR.parent
BEFORE_ENV = "SERVOBUS_BENCH_BEFORE"  # a tree --before measures by default (python -m bench passes no flags)
MOTORS = 32
TARGETS = {"us_per_exchange": 3.0, "vs_python": 20.0, "virtual_speedup": 50.0}

Network = SimCanNetwork | CoreCanNetwork


@dataclass(frozen=True, slots=True)
class Config:
    mode: str
    repeats: int
    cycles: int  # cycles of 32 pairs per repeat (exchange figure)
    virtual_s: float  # virtual seconds of the speed-up scenario


FULL = Config("full", repeats=7, cycles=400, virtual_s=10.0)
QUICK = Config("quick", repeats=1, cycles=20, virtual_s=0.2)


def trace(seed: int, cycles: int) -> list[list[Frame]]:
    """The host's requests, cycle by cycle: position set-points (a sine, seeded noise and speed limits),
    every fourth cycle a status read; the same list for the same seed."""
    rng = random.Random(seed)
    codecs = [ma.FAMILY.bind(i) for i in range(1, MOTORS + 1)]
    out: list[list[Frame]] = []
    for c in range(cycles):
        if c % 4 == 3:
            out.append([codec.encode(ma.ReadStatus2()) for codec in codecs])
            continue
        batch = []
        for n, codec in enumerate(codecs):
            angle = 90.0 * math.sin(2 * math.pi * (c / 200 + n / MOTORS)) + rng.uniform(-1.0, 1.0)
            speed = rng.choice((None, 360.0, 720.0, 1800.0))
            batch.append(
                codec.encode(ma.AbsolutePositionControl(angle_deg=round(angle, 2), max_speed_dps=speed))
            )
        out.append(batch)
    return out


def network(kind: type[Network]) -> Network:
    return kind([MyActuatorMotor(i) for i in range(1, MOTORS + 1)])


class Received:
    """What the host received, counted as it comes and, with ``hashed``, hashed (time, id, bytes);
    never kept, so no growing list rides through the garbage collector. The timed runs only count:
    the hash is for the untimed runs that check the traces."""

    __slots__ = ("add", "count", "hash")

    def __init__(self, *, hashed: bool = False) -> None:
        self.count = 0
        self.hash = hashlib.sha256()
        self.add = self._hash if hashed else self._count

    def _count(self, frames: list[Frame] | list[tuple[float, Frame]]) -> None:
        self.count += len(frames)

    def _hash(self, frames: list[Frame] | list[tuple[float, Frame]]) -> None:
        self.count += len(frames)
        update = self.hash.update
        for item in frames:
            at, frame = (item.timestamp, item) if isinstance(item, Frame) else item
            update(f"{at!r} {frame.arbitration_id} ".encode() + frame.data)

    def digest(self) -> str:
        return self.hash.hexdigest()[:16]


def drive(
    net: Network, cycles: Sequence[Sequence[Frame]], until_s: float = math.inf, *, hashed: bool = False
) -> Received:
    """Run ``cycles`` (repeated from the start while virtual time is below ``until_s``, once if it is
    infinite) the way SimTransport does; return what the host received."""
    received = Received(hashed=hashed)
    turn = getattr(net, "host_turn", None)
    t = net.now_s
    first = True
    while first or net.now_s < until_s:
        first = False
        for batch in cycles:
            for frame in batch:
                net.send(frame, t)
            want = received.count + len(batch)
            at = net.next_event_s()
            while received.count < want:
                if at is None:
                    raise RuntimeError(f"{type(net).__name__}: {want - received.count} replies never came")
                if turn is None:  # the code before host_turn (a --before tree), as this bench drove it
                    received.add(net.advance(at))  # (time, Frame) pairs: the transport's copy not counted
                    at = net.run_ahead(at)
                else:
                    got, at = turn(at)
                    received.add(got)
            t = net.now_s
            if t >= until_s:
                break
        if until_s == math.inf:
            break
    return received


@contextlib.contextmanager
def frozen() -> Iterator[None]:
    """Everything alive so far out of the collector's sight (``gc.freeze``), as a long-running control
    process does after start-up: the run then pays for the garbage it makes, not for full collections
    that walk every object the imports left (a fifth of the C engine's time otherwise)."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def exchange_us(kind: type[Network], cycles: list[list[Frame]]) -> float:
    """CPU µs per request/reply pair over ``cycles`` on a fresh network (a warm-up cycle first)."""
    net = network(kind)
    drive(net, cycles[:1])
    with frozen():
        start = time.process_time()
        received = drive(net, cycles[1:])
        return (time.process_time() - start) / received.count * 1e6


def trace_digest(
    kind: type[Network], cycles: list[list[Frame]], until_s: float = math.inf
) -> tuple[int, str]:
    """(pairs, digest of every reply's time, id and bytes) of an untimed run."""
    received = drive(network(kind), cycles, until_s, hashed=True)
    return received.count, received.digest()


def speedup(kind: type[Network], seconds: float, seed: int) -> float:
    """Virtual seconds per wall second of ``seconds`` of the saturating scenario."""
    cycles = trace(seed, 200)
    net = network(kind)
    with frozen():
        start = time.perf_counter()
        drive(net, cycles, until_s=seconds)
        return net.now_s / (time.perf_counter() - start)


def transport_speedup(seconds: float, seed: int) -> tuple[float, int]:
    """The scenario through SimTransport on a virtual-time loop: (speed-up, pairs)."""
    from servobus.transports.sim import SimTransport

    cycles = trace(seed, 200)

    async def scenario() -> int:
        done = asyncio.Event()
        state = {"got": 0, "want": 0, "cycle": 0}

        async with SimTransport(devices=[MyActuatorMotor(i) for i in range(1, MOTORS + 1)]) as bus:
            loop = asyncio.get_running_loop()

            def send_next() -> None:
                batch = cycles[state["cycle"] % len(cycles)]
                state["cycle"] += 1
                state["want"] += len(batch)
                for frame in batch:
                    bus.send(frame)

            def consume(frames: list[Frame]) -> None:
                state["got"] += len(frames)
                if state["got"] >= state["want"]:
                    if loop.time() >= seconds:
                        done.set()
                    else:
                        send_next()

            bus.set_consumer(consume)
            send_next()
            await done.wait()
        return state["got"]

    virtual.run(scenario())  # warm-up: imports, first calls
    start = time.perf_counter()
    pairs = virtual.run(scenario())
    return seconds / (time.perf_counter() - start), pairs


def measure(cfg: Config, log: Callable[[str], None], was: Before | None = None) -> dict[str, Any]:
    cycles = trace(1, cfg.cycles + 1)
    if trace_digest(CoreCanNetwork, cycles) != trace_digest(SimCanNetwork, cycles):
        raise SystemExit("bench_sim: the C engine's replies differ from the Python models'")
    core_us: list[float] = []
    py_us: list[float] = []
    for r in range(cfg.repeats):
        order = (CoreCanNetwork, SimCanNetwork) if r % 2 == 0 else (SimCanNetwork, CoreCanNetwork)
        b_us = was.run("exchange") if was is not None and r % 2 == 0 else None
        got = {kind: exchange_us(kind, cycles) for kind in order}
        if was is not None and r % 2 == 1:
            b_us = was.run("exchange")
        c_us, p_us = got[CoreCanNetwork], got[SimCanNetwork]
        core_us.append(c_us)
        py_us.append(p_us)
        log(f"  repeat {r + 1}: C {c_us:.2f} µs/pair, Python {p_us:.2f} µs/pair ({p_us / c_us:.1f}x)"
            + (f", before {b_us:.2f} µs/pair" if b_us is not None else ""))  # fmt: skip
    scenario = trace(7, 200)
    c_pairs, c_digest = trace_digest(CoreCanNetwork, scenario, cfg.virtual_s)
    same = (
        (c_pairs, c_digest)
        == trace_digest(CoreCanNetwork, scenario, cfg.virtual_s)
        == trace_digest(SimCanNetwork, scenario, cfg.virtual_s)
    )
    speeds = []
    for _ in range(3):
        if was is not None:
            was.run("speedup")
        speeds.append(speedup(CoreCanNetwork, cfg.virtual_s, seed=7))
    c_speed = statistics.median(speeds)
    p_speed = speedup(SimCanNetwork, cfg.virtual_s, seed=7)
    if was is not None:
        was.run("transport")
    t_speed, t_pairs = transport_speedup(cfg.virtual_s, seed=7)
    log(f"  {cfg.virtual_s:g} virtual s: C {c_speed:.1f}x ({c_pairs} pairs), Python {p_speed:.1f}x, "
        f"through SimTransport {t_speed:.1f}x"
        + (f"; before: C {statistics.median(was.runs['speedup']):.1f}x, through SimTransport "
           f"{was.runs['transport'][-1]:.1f}x" if was is not None else ""))  # fmt: skip
    c_med, p_med = statistics.median(core_us), statistics.median(py_us)
    figures: dict[str, Any] = {
        "us_per_exchange": round(c_med, 3),
        "python_us_per_exchange": round(p_med, 2),
        "vs_python": round(p_med / c_med, 1),
        "us_per_exchange_runs": [round(x, 3) for x in core_us],
        "python_us_per_exchange_runs": [round(x, 2) for x in py_us],
        "virtual_speedup": round(c_speed, 1),
        "virtual_speedup_python": round(p_speed, 1),
        "virtual_speedup_transport": round(t_speed, 1),
        "virtual_pairs": c_pairs,
        "virtual_pairs_per_s": round(c_pairs / cfg.virtual_s),
        "virtual_same_trace": same,
        "transport_pairs": t_pairs,
    }
    missed = [
        f"sim.{name} {figures[name]} (target {'<=' if name == 'us_per_exchange' else '>='} {target})"
        for name, target in TARGETS.items()
        if (figures[name] > target if name == "us_per_exchange" else figures[name] < target)
    ]
    if not figures["virtual_same_trace"]:
        missed.append("sim.virtual_same_trace: the same seed gave another trace")
    figures["targets_missed"] = missed
    return figures


def child(mode: str, cfg: Config) -> float:
    """One figure of this tree, for a parent run's ``--before`` or ``--instructions`` (``--child MODE``)."""
    if mode.startswith("drive"):  # the exchange trace, repeated N times, untimed: for callgrind
        cycles = trace(1, cfg.cycles + 1)
        net = network(CoreCanNetwork)
        drive(net, cycles[:1])
        with frozen():
            return float(sum(drive(net, cycles[1:]).count for _ in range(int(mode[5:]))))
    if mode == "exchange":
        return exchange_us(CoreCanNetwork, trace(1, cfg.cycles + 1))
    if mode == "speedup":
        return speedup(CoreCanNetwork, cfg.virtual_s, seed=7)
    return transport_speedup(cfg.virtual_s, seed=7)[0]


def instructions(tree: Path, cfg: Config) -> int:
    """Instructions per pair of the exchange trace through ``tree``'s code, counted by valgrind's
    callgrind (a run of 2 repeats minus a run of none: start-up and imports cancel out)."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}

    def count(repeats: int) -> tuple[int, int]:
        args = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, __file__]
        done = subprocess.run(
            [*args, "--child", f"drive{repeats}", *(["--quick"] if cfg is QUICK else [])],
            env=env, capture_output=True, text=True, check=True,
        )  # fmt: skip
        collected = [line for line in done.stderr.splitlines() if "Collected :" in line]
        return int(collected[-1].split(":")[-1].replace(",", "").strip()), int(float(done.stdout.split()[-1]))

    (base, _), (total, pairs) = count(0), count(2)
    return round((total - base) / pairs)


class Before:
    """The code in another tree, measured figure by figure by this script in a child process
    (``PYTHONPATH=TREE/src``), each run next to this tree's own of the same figure."""

    def __init__(self, tree: Path, cfg: Config) -> None:
        self.tree = tree
        self.cfg = cfg
        self.runs: dict[str, list[float]] = {"exchange": [], "speedup": [], "transport": []}

    def run(self, mode: str) -> float:
        env = {**os.environ, "PYTHONPATH": str(self.tree / "src")}
        args = [sys.executable, __file__, "--child", mode, *(["--quick"] if self.cfg is QUICK else [])]
        done = subprocess.run(args, env=env, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise SystemExit(f"bench_sim: the run on {self.tree} failed:\n{done.stderr[-2000:]}")
        value = float(done.stdout.strip().splitlines()[-1])
        self.runs[mode].append(value)
        return value

    def figures(self) -> dict[str, Any]:
        rev = subprocess.run(
            ["git", "-C", str(self.tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        )
        runs = self.runs
        return {
            "tree": str(self.tree),
            "commit": rev.stdout.strip() or None,
            "us_per_exchange": round(statistics.median(runs["exchange"]), 3),
            "us_per_exchange_runs": [round(x, 3) for x in runs["exchange"]],
            "virtual_speedup": round(statistics.median(runs["speedup"]), 1),
            "virtual_speedup_runs": [round(x, 1) for x in runs["speedup"]],
            "virtual_speedup_transport": round(statistics.median(runs["transport"]), 1),
        }


def render_markdown(f: dict[str, Any], info: dict[str, Any]) -> str:
    b = f.get("before", {})

    def was(name: str, unit: str) -> str:
        return (f"{b[name]:.2f}" if unit == " µs" else f"{b[name]:.1f}") + unit if name in b else "-"

    rows = [
        ("CPU per request/reply pair, C engine (`sim.us_per_exchange`)", f"{f['us_per_exchange']:.2f} µs",
         was("us_per_exchange", " µs"), "<= 3 µs"),
        ("the same, Python models (`sim.python_us_per_exchange`)",
         f"{f['python_us_per_exchange']:.2f} µs", was("python_us_per_exchange", " µs"), "-"),
        ("Python / C (`sim.vs_python`)", f"{f['vs_python']:.1f}x", "-", ">= 20x"),
        ("virtual scenario, C engine (`sim.virtual_speedup`)", f"{f['virtual_speedup']:.1f}x real time",
         was("virtual_speedup", "x"), ">= 50x"),
        ("the same, Python models (`sim.virtual_speedup_python`)",
         f"{f['virtual_speedup_python']:.1f}x", was("virtual_speedup_python", "x"), "-"),
        ("the same through `SimTransport` on a virtual-time loop (`sim.virtual_speedup_transport`)",
         f"{f['virtual_speedup_transport']:.1f}x", was("virtual_speedup_transport", "x"), "(info)"),
    ]  # fmt: skip
    if "instructions_per_exchange" in f:
        before_ir = b.get("instructions_per_exchange")
        was_ir = f"{before_ir:,}" if before_ir else "-"
        rows.append(("instructions per pair, C engine (`sim.instructions_per_exchange`)",
                     f"{f['instructions_per_exchange']:,}", was_ir, "(info)"))  # fmt: skip
    doc = (__doc__ or "").split("What is measured", 1)[1].split("\n\nUsage", 1)[0]
    before_note = (
        f"Before: `{b['tree']}` at {b['commit']}, this script in a child process next to each of this "
        f"tree's runs; its exchange runs (µs per pair): "
        f"{', '.join(f'{x:.2f}' for x in b['us_per_exchange_runs'])}; speed-ups: "
        f"{', '.join(f'{x:.1f}' for x in b['virtual_speedup_runs'])}; before / now (`sim.vs_before`): "
        f"{f['vs_before']:.2f}x; now / before (`sim.speedup_vs_before`): {f['speedup_vs_before']:.2f}x."
        if b
        else "No tree before was measured (`--before`)."
    )
    lines = [
        *_meta.header_lines("## The simulator's cost (`bench/bench_sim.py`)", info),
        "",
        "What is measured" + doc.rstrip(),
        "",
        _results.markdown_table(["figure", "value", "before", "target"], rows, "lrrl"),
        f"Runs (µs per pair, C): {', '.join(f'{x:.2f}' for x in f['us_per_exchange_runs'])}; "
        f"Python: {', '.join(f'{x:.2f}' for x in f['python_us_per_exchange_runs'])}. "
        f"Virtual scenario: {f['virtual_pairs']:,} pairs ({f['virtual_pairs_per_s']:,} per virtual second); "
        f"same trace for the same seed, and the same as the Python models': {f['virtual_same_trace']}.",
        "",
        before_note,
        "",
        "Targets missed: " + ("; ".join(f["targets_missed"]) if f["targets_missed"] else "none."),
    ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a few cycles (CI smoke run), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument(
        "--before",
        type=Path,
        metavar="TREE",
        default=os.environ.get(BEFORE_ENV) or None,
        help=f"measure the code in TREE (a checkout) beside this one (default: ${BEFORE_ENV}, if set)",
    )
    parser.add_argument(
        "--instructions",
        action="store_true",
        help="also count instructions per pair under valgrind (load-independent; with --before, both trees)",
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)  # exchange, speedup, transport, driveN
    args = parser.parse_args(argv)
    if args.child:  # one figure for a parent's --before
        print(child(args.child, QUICK if args.quick else FULL))
        return 0
    started = time.perf_counter()
    load = _meta.load_average()
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    print(
        f"bench_sim ({cfg.mode}): {cfg.repeats} repeats of {cfg.cycles} cycles x {MOTORS} motors", flush=True
    )
    was = Before(args.before, cfg) if args.before else None
    figures = measure(cfg, lambda line: print(line, flush=True), was)
    if was is not None:
        figures["before"] = was.figures()
        figures["vs_before"] = round(figures["before"]["us_per_exchange"] / figures["us_per_exchange"], 2)
        figures["speedup_vs_before"] = round(
            figures["virtual_speedup"] / figures["before"]["virtual_speedup"], 2
        )
    if args.instructions:
        figures["instructions_per_exchange"] = instructions(REPO, cfg)
        if args.before:
            figures["before"]["instructions_per_exchange"] = instructions(args.before, cfg)
        was_ir = f", before {figures['before']['instructions_per_exchange']:,}" if args.before else ""
        print(f"instructions per pair: {figures['instructions_per_exchange']:,}{was_ir}")
    arguments = list(sys.argv[1:] if argv is None else argv)
    info = _meta.meta(
        "bench/bench_sim.py",
        arguments,
        mode=cfg.mode,
        load_average_at_start=load,
        statistic=f"median of {cfg.repeats} repeats, C and Python alternated",
        runtime_s=round(time.perf_counter() - started, 1),
    )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All sim targets met.")
    print(
        f"sim.us_per_exchange {figures['us_per_exchange']} µs, vs_python {figures['vs_python']}x, "
        f"virtual_speedup {figures['virtual_speedup']}x"
    )
    if out_dir is not None:
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

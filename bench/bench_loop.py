"""Host CPU per tick of the pipelined loop: 32 motors on 11 buses, in-process zero-latency reflectors.

What is measured (each figure against baselines measured in the same run, runners alternated repeat by
repeat, each repeat on a fresh event loop; every runner paced by the same ``servobus.ticks.ticks(1000)``):

* ``loop``: ``servobus.Loop(hz=1000)`` over 32 MyActuator motors on 11 buses (3 per bus, the last 2),
  one ``ReadStatus2`` per motor per tick, the body reading every motor's state (what a controller
  does) and giving the next command: ``host_us_per_tick``.
* ``floor``: the least any host must do per tick on the same reflectors: the prebuilt request frames
  written to each bus's reflector (``Reflector.send``), the replies read (a consumer keeping each as
  its sender's latest frame); nothing encoded, decoded or matched. ``host_vs_floor`` = the Loop's µs
  per tick / the floor's.
* ``cycle``: today's send-and-wait ``Bus.cycle`` over the same 11 buses each tick (all buses' cycles
  awaited together): the issue's "~400" (``cycle_us_per_tick``).
* ``pacer``: ``ticks(1000)`` with an empty body: what the pacer alone costs per tick on this clock,
  shown beside (``pacer_us_per_tick``; each figure net of it is in results.json).

The buses' links are :class:`bench_bus.Reflector` (a FrameLink answering every frame with the reply a
simulated motor at rest gives, looked up by arbitration id: ``bench_bus.prebuilt_replies``), so every
CPU µs is the host's.

**Clock: virtual time** (``servobus.sim.virtual``: looptime's loop on asyncio, trio's
``MockClock(autojump_threshold=0)`` on trio). With a real clock the pacer's waiting would be part of
the run: a spinning pacer counts 1,000 µs per tick whatever the hot path costs, and a sleeping one
adds its wake-ups, which are ``pacer.cpu_pct`` (the pacer's own bench). On a virtual clock every wait
ends at once when nothing else is ready, so the ticks run back to back at 1 kHz of loop time: process
CPU over them is the host's work per tick with the pacer's bookkeeping counted and its sleeping not.
That bookkeeping includes the pacer's test for a virtual clock (a yield, then a sleep) and the virtual
loop's clock jump, tens of µs per tick: it is in the floor and ``cycle`` too (same pacer, same clock),
so the ratio compares like with like, and the idle pacer's own figure says how much of each it is. The
replies come back in the same loop iteration (zero latency), so every tick's body sees the state its
previous tick's commands asked for; the runner checks that (fresh state for every motor, no loss).

CPU = ``time.process_time`` over the measured ticks (after warm-up ticks), / ticks; medians of repeats;
the ratio is also given repeat by repeat (each pair ran back to back). The garbage collector stays on.
asyncio is the figure; trio is measured beside it.

Targets (issue 39): ``loop.host_us_per_tick`` <= 150; ``loop.host_vs_floor`` <= 2. When one is missed a
py-spy profile of the loop is taken (a child process running only the loop) and shown.

Usage (from the repository root)::

    python bench/bench_loop.py            # full: 5 repeats x 3,000 ticks per runner (~1 min)
    python bench/bench_loop.py --quick    # CI smoke (a few s), writes nothing
    python bench/bench_loop.py --check    # exit 1 when a target is missed
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _profile  # noqa: E402
import _results  # noqa: E402
from bench_bus import Reflector, prebuilt_replies  # noqa: E402
from servobus.bus import Bus  # noqa: E402
from servobus.frame import Frame  # noqa: E402
from servobus.protocols import get_family  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402
from servobus.sim import virtual  # noqa: E402
from servobus.ticks import ticks  # noqa: E402

KEY = "loop"
HZ = 1000
FAMILY = "myactuator"
MOTORS_PER_BUS = (3,) * 10 + (2,)  # 32 motors: 3 per bus keep a classic 1 Mbit/s bus inside 1 ms
HOST_US_TARGET = 150.0
VS_FLOOR_TARGET = 2.0
RUNNERS = ("loop", "floor", "cycle", "pacer")
BACKENDS = ("asyncio", "trio")


@dataclass(frozen=True, slots=True)
class Config:
    mode: str
    ticks: int  # measured ticks per repeat
    warmup: int  # ticks before the measurement starts
    repeats: int
    profile_s: float  # py-spy seconds when a target is missed (0: none)


FULL = Config("full", 3000, 200, 5, 8.0)
QUICK = Config("quick", 200, 20, 1, 0.0)


@dataclass(frozen=True, slots=True)
class Sample:
    """One repeat of one runner: process CPU µs per tick and wall µs per tick over the measured ticks."""

    cpu_us: float
    wall_us: float


def bus_ids() -> list[range]:
    """Motor ids per bus: 1-3, 4-6, ... 31-32 (distinct ids, so one prebuilt reply table serves all)."""
    out, first = [], 1
    for n in MOTORS_PER_BUS:
        out.append(range(first, first + n))
        first += n
    return out


class _Window:
    """Process CPU and wall time from the first measured tick to the end."""

    def __init__(self) -> None:
        self.cpu0 = self.wall0 = 0.0

    def start(self) -> None:
        self.cpu0, self.wall0 = time.process_time(), time.perf_counter()

    def sample(self, ticks_run: int) -> Sample:
        cpu, wall = time.process_time() - self.cpu0, time.perf_counter() - self.wall0
        return Sample(cpu / ticks_run * 1e6, wall / ticks_run * 1e6)


async def _open_buses(
    stack: contextlib.AsyncExitStack, replies: dict[int, Frame], link: type[Reflector] = Reflector
) -> list[Bus]:
    return [await stack.enter_async_context(Bus(link(replies), safe=None)) for _ in MOTORS_PER_BUS]


async def run_loop(
    n: int, warmup: int, replies: dict[int, Frame], link: type[Reflector] = Reflector
) -> Sample:
    """The pipelined Loop: every motor's state read, one ReadStatus2 per motor per tick. Raises when a
    state was not fresh on a measured tick, a reply was lost or a tick overran (``link``: the
    reflector class, for tests)."""
    from servobus.loop import Loop

    command = ma.ReadStatus2()
    window = _Window()
    async with contextlib.AsyncExitStack() as stack:
        buses = await _open_buses(stack, replies, link)
        motors = [bus.motor(FAMILY, i) for bus, ids in zip(buses, bus_ids(), strict=True) for i in ids]
        not_fresh = 0
        async with Loop(hz=HZ) as loop:
            async for tick in loop.ticks(count=warmup + n + 1):
                if tick.index == warmup:
                    window.start()
                elif tick.index > warmup:
                    for motor in motors:
                        state = tick.state(motor)
                        if state is None or not state.fresh:
                            not_fresh += 1
                for motor in motors:
                    tick.command(motor, command)
            sample = window.sample(n)
            metrics = loop.metrics()
    if not_fresh or metrics.lost or metrics.overruns:
        raise RuntimeError(f"loop on the reflector: {not_fresh} states not fresh; {metrics}")
    return sample


async def run_cycle(n: int, warmup: int, replies: dict[int, Frame]) -> Sample:
    """Today's send-and-wait: every bus's ``cycle`` each tick, awaited together, paced by ``ticks``."""
    command = ma.ReadStatus2()
    window = _Window()
    async with contextlib.AsyncExitStack() as stack:
        buses = await _open_buses(stack, replies)
        plan = [
            (bus, [(bus.motor(FAMILY, i), command) for i in ids])
            for bus, ids in zip(buses, bus_ids(), strict=True)
        ]
        gather = _gather_all()
        wrong = 0
        async for tick in ticks(HZ, count=warmup + n):
            if tick.index == warmup:
                window.start()
            results = await gather([bus.cycle(items) for bus, items in plan])
            wrong += sum(1 for per_bus in results for r in per_bus if not isinstance(r, ma.StatusReply))
        sample = window.sample(n)
    if wrong:
        raise RuntimeError(f"cycle on the reflector: {wrong} results are not a StatusReply")
    return sample


async def run_floor(n: int, warmup: int, replies: dict[int, Frame]) -> Sample:
    """The bare floor on the same reflectors, paced by ``ticks``: the prebuilt request frames written,
    each reply kept as its sender's latest frame as it is handed over; nothing encoded, decoded or
    matched."""
    family = get_family(FAMILY)
    command = ma.ReadStatus2()
    plan: list[tuple[Reflector, list[Frame]]] = []
    received = [0]
    latest: dict[int, Frame] = {}

    def consumer(frames: Sequence[Frame]) -> None:
        for frame in frames:  # read: each reply kept as its sender's latest, nothing decoded
            latest[frame.arbitration_id] = frame
        received[0] += len(frames)

    for ids in bus_ids():
        reflector = Reflector(replies)
        await reflector.open()
        reflector.set_consumer(consumer)
        plan.append((reflector, [family.bind(i).encode(command) for i in ids]))
    window = _Window()
    async for tick in ticks(HZ, count=warmup + n):
        if tick.index == warmup:
            window.start()
        for reflector, frames in plan:
            send = reflector.send
            for frame in frames:
                send(frame)
    sample = window.sample(n)
    await anyio.sleep(1 / HZ)  # the last tick's replies (virtual time: at once)
    sent = sum(r.sent for r, _ in plan)
    for reflector, _ in plan:
        await reflector.close()
    if received[0] != sent:
        raise RuntimeError(f"floor: {received[0]} replies for {sent} requests")
    return sample


async def run_pacer(n: int, warmup: int, replies: dict[int, Frame]) -> Sample:
    """``ticks(1000)`` with an empty body: the pacer's own cost per tick on this clock (information)."""
    window = _Window()
    async for tick in ticks(HZ, count=warmup + n):
        if tick.index == warmup:
            window.start()
    return window.sample(n)


def _gather_all() -> Callable[[list[Coroutine[Any, Any, Any]]], Coroutine[Any, Any, list[Any]]]:
    """Await coroutines together, results in order: ``asyncio.gather`` on asyncio, a nursery on trio."""
    import sniffio

    if sniffio.current_async_library() == "asyncio":

        async def gather_asyncio(coros: list[Coroutine[Any, Any, Any]]) -> list[Any]:
            return list(await asyncio.gather(*coros))

        return gather_asyncio
    import trio

    async def gather_trio(coros: list[Coroutine[Any, Any, Any]]) -> list[Any]:
        results: list[Any] = [None] * len(coros)

        async def one(i: int, coro: Coroutine[Any, Any, Any]) -> None:
            results[i] = await coro

        async with trio.open_nursery() as nursery:
            for i, coro in enumerate(coros):
                nursery.start_soon(one, i, coro)
        return results

    return gather_trio


RUN: dict[str, Callable[[int, int, dict[int, Frame]], Coroutine[Any, Any, Sample]]] = {
    "loop": run_loop,
    "floor": run_floor,
    "cycle": run_cycle,
    "pacer": run_pacer,
}


def measure(
    cfg: Config, backends: Sequence[str], log: Callable[[str], None]
) -> dict[str, dict[str, list[Sample]]]:
    """Every runner on every backend once per repeat, in turn, each on a fresh virtual-time loop."""
    replies = prebuilt_replies(ma.ReadStatus2())
    samples: dict[str, dict[str, list[Sample]]] = {b: {r: [] for r in RUNNERS} for b in backends}
    for repeat in range(cfg.repeats):
        for backend in backends:
            for name in RUNNERS:
                sample = virtual.run(RUN[name](cfg.ticks, cfg.warmup, replies), backend=backend)
                samples[backend][name].append(sample)
                log(
                    f"  repeat {repeat + 1}/{cfg.repeats} {backend:<7} {name:<6} "
                    f"{sample.cpu_us:8.1f} CPU µs/tick ({sample.wall_us:8.1f} wall µs/tick)"
                )
    return samples


def _net(runs: dict[str, list[Sample]], name: str) -> list[float]:
    """CPU µs per tick of ``name`` minus the idle pacer's, repeat by repeat (they ran back to back)."""
    return [a.cpu_us - p.cpu_us for a, p in zip(runs[name], runs["pacer"], strict=True)]


def summarise(samples: dict[str, dict[str, list[Sample]]], cfg: Config) -> dict[str, Any]:
    per_backend: dict[str, Any] = {}
    for backend, runs in samples.items():
        cpu = {name: statistics.median(s.cpu_us for s in runs[name]) for name in RUNNERS}
        net = {name: statistics.median(_net(runs, name)) for name in ("loop", "floor", "cycle")}
        pairs = [a.cpu_us / b.cpu_us for a, b in zip(runs["loop"], runs["floor"], strict=True)]
        per_backend[backend] = {
            "host_us_per_tick": round(cpu["loop"], 1),
            "floor_us_per_tick": round(cpu["floor"], 1),
            "cycle_us_per_tick": round(cpu["cycle"], 1),
            "pacer_us_per_tick": round(cpu["pacer"], 1),
            "host_vs_floor": round(cpu["loop"] / cpu["floor"], 2),
            "host_vs_floor_per_repeat": [round(min(pairs), 2), round(max(pairs), 2)],
            "cycle_vs_host": round(cpu["cycle"] / cpu["loop"], 2),
            "net_of_pacer_us_per_tick": {name: round(value, 1) for name, value in net.items()},
            "wall_us_per_tick": {
                name: round(statistics.median(s.wall_us for s in runs[name]), 1) for name in RUNNERS
            },
            "cpu_us_per_tick_runs": {k: [round(s.cpu_us, 1) for s in v] for k, v in runs.items()},
        }
    main = per_backend["asyncio"]
    figures: dict[str, Any] = {
        "host_us_per_tick": main["host_us_per_tick"],
        "host_vs_floor": main["host_vs_floor"],
        "floor_us_per_tick": main["floor_us_per_tick"],
        "cycle_us_per_tick": main["cycle_us_per_tick"],
        "pacer_us_per_tick": main["pacer_us_per_tick"],
        "cycle_vs_host": main["cycle_vs_host"],
        "host_net_of_pacer_us_per_tick": main["net_of_pacer_us_per_tick"]["loop"],
        "basis": "process CPU µs per tick (time.process_time over the measured ticks), median of repeats; "
        "every runner paced by servobus.ticks.ticks(1000) on a virtual clock (ticks back to back at 1 kHz "
        "of loop time: the pacer's bookkeeping counted, its sleeping not); asyncio",
        "layout": f"{sum(MOTORS_PER_BUS)} MyActuator motors on {len(MOTORS_PER_BUS)} buses "
        f"({'/'.join(map(str, MOTORS_PER_BUS))}), ReadStatus2 each per tick, bench_bus.Reflector per bus",
        "backends": per_backend,
        "sizes": {"ticks": cfg.ticks, "warmup": cfg.warmup, "repeats": cfg.repeats},
    }
    if "trio" in per_backend:
        figures["trio_host_us_per_tick"] = per_backend["trio"]["host_us_per_tick"]
        figures["trio_host_vs_floor"] = per_backend["trio"]["host_vs_floor"]
    targets: dict[str, dict[str, Any]] = {
        "host_us_per_tick": {"max": HOST_US_TARGET},
        "host_vs_floor": {"max": VS_FLOOR_TARGET},
    }
    for name, target in targets.items():
        target["met"] = figures[name] <= target["max"]
    figures["targets"] = targets
    figures["targets_missed"] = [
        f"{KEY}.{name} = {figures[name]} (target <= {t['max']:g})"
        for name, t in targets.items()
        if not t["met"]
    ]
    return figures


def spin(seconds: float) -> None:
    """The loop alone, repeat after repeat, for ``seconds``: the profiled process."""
    replies = prebuilt_replies(ma.ReadStatus2())
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        virtual.run(run_loop(1000, 50, replies))


def profile(seconds: float) -> dict[str, Any]:
    """Where the loop's time goes: py-spy over ``seconds`` of :func:`spin` in a child process (cProfile
    of one repeat when py-spy is missing or fails)."""
    if _profile.pyspy_available():
        with tempfile.TemporaryDirectory(prefix="bench-loop-") as tmp:
            stacks = Path(tmp) / "stacks.txt"
            command = [sys.executable, str(Path(__file__).resolve()), "--spin", str(seconds)]
            done = _profile.pyspy_record(command, stacks, rate=500)
            if done.returncode == 0 and stacks.exists():
                return _profile.collapsed(stacks, top=16)
    replies = prebuilt_replies(ma.ReadStatus2())
    return _profile.cprofile(lambda: virtual.run(run_loop(1000, 50, replies)), top=16)


def render_markdown(figures: dict[str, Any], info: dict[str, Any]) -> str:
    lines = _meta.header_lines(
        "## The pipelined loop's host cost, 32 motors on 11 buses (`bench/bench_loop.py`)", info
    )
    sizes = figures["sizes"]
    lines += [
        "",
        "Host CPU per tick of `servobus.Loop(hz=1000)` over 32 MyActuator motors on 11 buses (3 per bus, the "
        "last 2), one `ReadStatus2` per motor per tick and every motor's state read by the body, each bus's "
        "link a zero-latency reflector (`bench_bus.Reflector`, replies prebuilt by `prebuilt_replies`). "
        "Beside it, in the same run: the **floor** (the prebuilt request frames written to each reflector, "
        "each reply kept as its sender's latest frame: nothing encoded, decoded or matched) and today's "
        "send-and-wait **`Bus.cycle`** over the same 11 buses each tick. All paced by "
        "`servobus.ticks.ticks(1000)` on a virtual clock (ticks back to back at 1 kHz of loop time); on "
        "such a clock the pacer's sleeping costs nothing and its bookkeeping counts: its test for a "
        "virtual clock and the clock's jump, the same in every runner; an idle pacer (`ticks(1000)`, "
        f"empty body) costs {figures['pacer_us_per_tick']:.1f} µs per tick of each figure (net of it: the "
        "last column). The pacer's wake-ups on a real clock are `pacer.cpu_pct`. CPU = "
        f"`time.process_time` over {sizes['ticks']:,} ticks after "
        f"{sizes['warmup']} of warm-up, median of {sizes['repeats']} repeats, runners alternated, GC on.",
        "",
    ]
    rows = []
    for backend, b in figures["backends"].items():
        rows.append(
            (
                backend,
                f"**{b['host_us_per_tick']:.1f}**",
                f"{b['floor_us_per_tick']:.1f}",
                "**{:.2f}** ({:.2f} to {:.2f})".format(b["host_vs_floor"], *b["host_vs_floor_per_repeat"]),
                f"{b['cycle_us_per_tick']:.1f}",
                f"{b['cycle_vs_host']:.2f}",
                "{loop:.1f} / {floor:.1f} / {cycle:.1f}".format(**b["net_of_pacer_us_per_tick"]),
            )
        )
    lines += [
        _results.markdown_table(
            [
                "backend",
                "Loop CPU µs/tick (`loop.host_us_per_tick`)",
                "floor CPU µs/tick",
                "Loop / floor (`loop.host_vs_floor`; per repeat)",
                "`Bus.cycle` CPU µs/tick (`loop.cycle_us_per_tick`)",
                "cycle / Loop",
                "net of the idle pacer: Loop / floor / cycle",
            ],
            rows,
            "lrrrrrr",
        ),
        f"Targets (asyncio): `loop.host_us_per_tick` <= {HOST_US_TARGET:g} µs, `loop.host_vs_floor` <= "
        f"{VS_FLOOR_TARGET:g}. "
        + (
            "**Not met**: " + "; ".join(figures["targets_missed"]) + "."
            if figures["targets_missed"]
            else "Met."
        ),
    ]
    prof = figures.get("profile")
    if prof:
        unit_us = figures["host_us_per_tick"]
        lines += [
            "",
            f"### Where the time goes: the Loop on the reflectors ({prof['tool']})",
            "",
            "Shares of the profiled process's samples; µs = share x the measured CPU µs per tick "
            f"({unit_us:.1f}).",
            "",
            *_profile.markdown(prof, 16, unit_us=unit_us, unit="tick"),
        ]
        halves = _halves(prof, unit_us)
        if halves:
            lines += ["", "The halves of a tick (inclusive shares): " + "; ".join(halves) + "."]
    return "\n".join(lines) + "\n"


#: (function name prefix in a profile, what it stands for): the two halves of a tick and the timers
HALVES = (
    ("Loop._send ", "the send side, `Loop._send` (encoding, the scheduler's request and submit, the pump)"),
    ("Reflector._flush ", "the receive side, `Reflector._flush` into `Engine.on_frames` (matching, "
     "decoding, the loop's attribution)"),
    ("Timer.run ", "the engine's timers, `Timer.run` (the requests' deadlines)"),
)  # fmt: skip


def _halves(prof: dict[str, Any], unit_us: float) -> list[str]:
    """Where a tick's time goes, from a profile's inclusive list: each of :data:`HALVES` found."""
    out = []
    for prefix, label in HALVES:
        entry = next((e for e in prof.get("inclusive", []) if e["function"].startswith(prefix)), None)
        if entry is not None:
            out.append(f"{label} {entry['pct']:.0f} % ({entry['pct'] / 100 * unit_us:.0f} µs)")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="CI smoke run (a few s), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--repeats", type=int, help="repeats per runner")
    parser.add_argument("--ticks", type=int, help="measured ticks per repeat")
    parser.add_argument("--asyncio-only", action="store_true", help="leave trio out")
    parser.add_argument("--spin", type=float, metavar="SECONDS", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.spin:
        spin(args.spin)
        return 0
    started = time.perf_counter()
    load = _meta.load_average()
    base = QUICK if args.quick else FULL
    cfg = Config(
        base.mode, args.ticks or base.ticks, base.warmup, args.repeats or base.repeats, base.profile_s
    )
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    backends = ("asyncio",) if args.asyncio_only else BACKENDS
    print(
        f"bench_loop ({cfg.mode}): {sum(MOTORS_PER_BUS)} motors on {len(MOTORS_PER_BUS)} reflector buses, "
        f"{cfg.repeats} repeat(s) x {cfg.ticks} ticks; {', '.join(backends)}",
        flush=True,
    )
    samples = measure(cfg, backends, lambda line: print(line, flush=True))
    figures = summarise(samples, cfg)
    if figures["targets_missed"] and cfg.profile_s > 0:
        print(f"a target was missed: profiling the loop ({cfg.profile_s:g} s under py-spy)", flush=True)
        figures["profile"] = profile(cfg.profile_s)
    info = _meta.meta(
        "bench/bench_loop.py",
        argv,
        mode=cfg.mode,
        load_average_at_start=load,
        runtime_s=round(time.perf_counter() - started, 1),
    )
    print(
        f"loop.host_us_per_tick {figures['host_us_per_tick']:.1f} µs, "
        f"floor {figures['floor_us_per_tick']:.1f} µs, host_vs_floor {figures['host_vs_floor']:.2f}, "
        f"cycle {figures['cycle_us_per_tick']:.1f} µs"
    )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All loop targets met.")
    if out_dir is not None:
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

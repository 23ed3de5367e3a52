"""Scaling: what a tick costs as motors per bus, buses per process and processes grow.

Every bus here is the zero-latency reflector of bench_bus.py (a FrameLink answering each frame with a
prebuilt reply), so the time is servobus's alone: encoding, the scheduler, matching, typed decoding,
futures, and the event loop's work for every bus.

1. **Motors per bus** (1, 2, 4, 8, 16, 32; one bus): one tick = ``await bus.cycle(items)`` of ReadStatus2
   to every motor. CPU µs per tick (``time.process_time``) and wall µs per tick, ticks run back to back.
2. **Buses per process** (1, 2, 4, ..., 64; 4 motors per bus, one pacer-less loop): one tick =
   ``asyncio.gather(*(bus.cycle(items) for each bus))``, as a pacer driving several buses does. CPU µs
   per tick; the 1 kHz budget is 1,000 µs.
3. **Processes** (1, 2, 4; this machine has 2 cores): each process owns 8 buses x 4 motors (32 motors)
   and runs ticks back to back for a few seconds, all starting at the same instant; the aggregate
   transactions/s is what a user gets by giving each core its own process and its own buses.

Each in-process figure is the median of 5 repeats (quick: 1); the process figures are one run of each
count per repeat, the median repeat. The machine is shared: its load average is recorded with the run.
Writes ``scaling`` in results.json, the ``scaling`` section of RESULTS.md, and ``bench/scaling.png``.

Usage (from the repository root)::

    python bench/bench_scaling.py            # full (~1-2 min)
    python bench/bench_scaling.py --quick    # small (CI smoke), writes nothing
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _profile  # noqa: E402
import _results  # noqa: E402
from bench_bus import Reflector, prebuilt_replies  # noqa: E402
from servobus.bus import Bus  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402

KEY = "scaling"
MOTORS_PER_BUS = (1, 2, 4, 8, 16, 32)
BUSES = (1, 2, 4, 8, 16, 32, 64)
BUS_MOTORS = 4  # motors per bus in the buses-per-process sweep
PROCESSES = (1, 2, 4)
PROCESS_BUSES, PROCESS_MOTORS = 8, 4
PLOT = BENCH_DIR / "scaling.png"


@dataclass(frozen=True)
class Config:
    mode: str
    transactions: int  # per in-process measurement (ticks = transactions / per tick)
    repeats: int
    process_seconds: float
    process_repeats: int
    process_counts: tuple[int, ...]


FULL = Config("full", 20_000, 5, 3.0, 5, PROCESSES)
QUICK = Config("quick", 1_000, 1, 0.3, 1, (1, 2))


async def ticks_cost(buses: int, motors: int, ticks: int) -> dict[str, float]:
    """CPU and wall µs per tick of ``buses`` reflector buses x ``motors`` motors, ticks back to back."""
    replies = prebuilt_replies(ma.ReadStatus2())
    async with contextlib.AsyncExitStack() as stack:
        plan = []
        for _ in range(buses):
            bus = await stack.enter_async_context(Bus(Reflector(replies)))
            plan.append((bus, [(bus.motor("myactuator", i), ma.ReadStatus2()) for i in range(1, motors + 1)]))

        if buses == 1:
            bus, items = plan[0]

            async def tick() -> None:
                await bus.cycle(items)
        else:

            async def tick() -> None:
                await asyncio.gather(*[b.cycle(items) for b, items in plan])

        await tick()  # warm-up
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for _ in range(ticks):
            await tick()
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        for bus, _ in plan:
            stats = bus.stats()
            if stats.get("requests") != stats.get("replies"):
                raise RuntimeError(f"scaling: unanswered requests {stats}")
    n = buses * motors
    return {
        "cpu_tick_us": cpu / ticks * 1e6,
        "wall_tick_us": wall / ticks * 1e6,
        "cpu_us_per_transaction": cpu / (ticks * n) * 1e6,
    }


def sweep(
    points: Sequence[tuple[int, int]], by: str, cfg: Config, log: Callable[[str], None]
) -> dict[str, dict[str, Any]]:
    """(buses, motors) points, each measured ``cfg.repeats`` times in turn; the medians, keyed by the
    number of ``by`` ("buses" or "motors")."""
    samples: dict[tuple[int, int], list[dict[str, float]]] = {p: [] for p in points}
    for _ in range(cfg.repeats):
        for buses, motors in points:
            ticks = max(5, cfg.transactions // (buses * motors))
            samples[(buses, motors)].append(asyncio.run(ticks_cost(buses, motors, ticks)))
    out: dict[str, dict[str, Any]] = {}
    for (buses, motors), runs in samples.items():
        med: dict[str, Any] = {k: round(statistics.median(r[k] for r in runs), 2) for k in runs[0]}
        cpu = [r["cpu_tick_us"] for r in runs]
        med["spread_cpu_tick_us"] = [round(min(cpu), 1), round(max(cpu), 1)]
        med["max_hz_one_core"] = round(1e6 / med["cpu_tick_us"])
        out[str(buses if by == "buses" else motors)] = med
        log(
            f"  {buses:>2} bus(es) x {motors:>2} motors: {med['cpu_tick_us']:9.1f} CPU µs/tick "
            f"({med['cpu_us_per_transaction']:.2f} µs/transaction), wall {med['wall_tick_us']:9.1f} µs"
        )
    return out


# --------------------------------------------------------------------------------------- processes


async def worker(buses: int, motors: int, seconds: float, start_at: float) -> dict[str, float]:
    replies = prebuilt_replies(ma.ReadStatus2())
    async with contextlib.AsyncExitStack() as stack:
        plan = []
        for _ in range(buses):
            bus = await stack.enter_async_context(Bus(Reflector(replies)))
            plan.append((bus, [(bus.motor("myactuator", i), ma.ReadStatus2()) for i in range(1, motors + 1)]))
        await asyncio.gather(*[b.cycle(items) for b, items in plan])  # warm-up
        await asyncio.sleep(max(0.0, start_at - time.monotonic()))
        cpu0, wall0 = time.process_time(), time.perf_counter()
        ticks = 0
        end = wall0 + seconds
        while time.perf_counter() < end:
            await asyncio.gather(*[b.cycle(items) for b, items in plan])
            ticks += 1
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return {
        "ticks": ticks,
        "transactions_s": ticks * buses * motors / wall,
        "ticks_s": ticks / wall,
        "cpu_pct": 100 * cpu / wall,
        "cpu_us_per_transaction": cpu / (ticks * buses * motors) * 1e6,
    }


def processes_run(count: int, seconds: float) -> dict[str, Any]:
    start_at = time.monotonic() + 1.0 + 0.2 * count  # every worker imported and warmed up by then
    command = [
        sys.executable, str(Path(__file__).resolve()), "--worker", str(PROCESS_BUSES), str(PROCESS_MOTORS),
        str(seconds), repr(start_at),
    ]  # fmt: skip
    procs = [subprocess.Popen(command, stdout=subprocess.PIPE, text=True) for _ in range(count)]
    results = []
    for proc in procs:
        out, _ = proc.communicate(timeout=seconds + 60)
        if proc.returncode != 0:
            raise RuntimeError(f"scaling worker failed ({proc.returncode})")
        results.append(json.loads(out.strip().splitlines()[-1]))
    return {
        "transactions_s": sum(r["transactions_s"] for r in results),
        "per_process_transactions_s": [round(r["transactions_s"]) for r in results],
        "per_process_cpu_pct": [round(r["cpu_pct"], 1) for r in results],
        "per_process_ticks_s": [round(r["ticks_s"], 1) for r in results],
    }


def processes(cfg: Config, log: Callable[[str], None]) -> dict[str, dict[str, Any]]:
    runs: dict[int, list[dict[str, Any]]] = {p: [] for p in cfg.process_counts}
    for _ in range(cfg.process_repeats):
        for count in cfg.process_counts:
            runs[count].append(processes_run(count, cfg.process_seconds))
    out: dict[str, dict[str, Any]] = {}
    base = statistics.median(r["transactions_s"] for r in runs[1])
    for count, results in runs.items():
        ordered = sorted(results, key=lambda r: r["transactions_s"])
        med = ordered[len(ordered) // 2]
        out[str(count)] = {
            "transactions_s": round(med["transactions_s"]),
            "vs_one_process": round(med["transactions_s"] / base, 2),
            "per_process_transactions_s": med["per_process_transactions_s"],
            "per_process_cpu_pct": med["per_process_cpu_pct"],
            "per_process_ticks_s": med["per_process_ticks_s"],
            "spread_transactions_s": [
                round(ordered[0]["transactions_s"]),
                round(ordered[-1]["transactions_s"]),
            ],
        }
        log(
            f"  {count} process(es) x {PROCESS_BUSES} buses x {PROCESS_MOTORS} motors: "
            f"{med['transactions_s']:10,.0f} transactions/s in all "
            f"({med['transactions_s'] / base:.2f}x one), CPU {med['per_process_cpu_pct']} %"
        )
    return out


# ----------------------------------------------------------------------------------------- report


def plot(figures: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    mpb = figures["motors_per_bus"]
    xs = [int(k) for k in mpb]
    ax = axes[0]
    ax.plot(xs, [mpb[k]["cpu_tick_us"] for k in mpb], "o-", label="CPU µs per tick")
    ax.plot(
        xs, [mpb[k]["cpu_us_per_transaction"] * 10 for k in mpb], "s--", label="CPU µs per transaction x10"
    )
    ax.axhline(1000, color="red", lw=0.8, ls=":", label="1 kHz budget (1,000 µs)")
    ax.set_xscale("log", base=2)
    ax.set_xticks(xs, [str(x) for x in xs])
    ax.set_xlabel("motors on the bus (one bus)")
    ax.set_ylabel("µs")
    ax.set_title("one bus: cost per tick")
    ax.legend(fontsize=8)
    bpp = figures["buses_per_process"]
    xs = [int(k) for k in bpp]
    ax = axes[1]
    ax.plot(
        xs, [bpp[k]["cpu_tick_us"] for k in bpp], "o-", label=f"CPU µs per tick ({BUS_MOTORS} motors per bus)"
    )
    ax.axhline(1000, color="red", lw=0.8, ls=":", label="1 kHz budget (1,000 µs)")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(xs, [str(x) for x in xs])
    ax.set_xlabel("buses in one process (one pacer, gather of cycles)")
    ax.set_ylabel("CPU µs per tick")
    ax.set_title("buses per process")
    ax.legend(fontsize=8)
    procs = figures["processes"]
    xs = [int(k) for k in procs]
    ax = axes[2]
    ax.bar([str(x) for x in xs], [procs[k]["transactions_s"] / 1000 for k in procs])
    ax.set_xlabel(f"processes ({PROCESS_BUSES} buses x {PROCESS_MOTORS} motors each; {os.cpu_count()} cores)")
    ax.set_ylabel("thousand transactions/s, all processes")
    ax.set_title("filling the machine")
    fig.suptitle("servobus scaling on the zero-latency reflector (bench/bench_scaling.py)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def render_markdown(figures: dict[str, Any], info: dict[str, Any]) -> str:
    lines = _meta.header_lines("## Scaling (`bench/bench_scaling.py`)", info)
    mpb, bpp, procs = figures["motors_per_bus"], figures["buses_per_process"], figures["processes"]
    lines += [
        "",
        "Zero-latency reflector buses (bench_bus.py's `Reflector`), so every µs is servobus's and the event "
        f"loop's. Ticks back to back; CPU = `time.process_time`. Medians of {info['repeats']} repeats "
        f"(processes: median of {info['process_repeats']}). Plot: `bench/scaling.png`.",
        "",
        "**Motors per bus** (one bus, one `cycle()` per tick):",
        "",
        _results.markdown_table(
            [
                "motors",
                "CPU µs per tick",
                "wall µs per tick",
                "CPU µs per transaction",
                "max ticks/s on one core",
            ],
            [
                (
                    k,
                    f"{v['cpu_tick_us']:,.1f}",
                    f"{v['wall_tick_us']:,.1f}",
                    f"{v['cpu_us_per_transaction']:.2f}",
                    f"{v['max_hz_one_core']:,}",
                )
                for k, v in mpb.items()
            ],
            "rrrrr",
        ),
        f"**Buses per process** ({BUS_MOTORS} motors per bus, one tick = `gather` of every bus's `cycle()`):",
        "",
        _results.markdown_table(
            ["buses", "motors", "CPU µs per tick", "CPU µs per transaction", "max ticks/s on one core"],
            [
                (
                    k,
                    int(k) * BUS_MOTORS,
                    f"{v['cpu_tick_us']:,.1f}",
                    f"{v['cpu_us_per_transaction']:.2f}",
                    f"{v['max_hz_one_core']:,}",
                )
                for k, v in bpp.items()
            ],
            "rrrrr",
        ),
        f"**Processes** (each {PROCESS_BUSES} buses x {PROCESS_MOTORS} motors, ticks back to back for "
        f"{info['process_seconds']:g} s, all started at once; {os.cpu_count()} cores, shared):",
        "",
        _results.markdown_table(
            ["processes", "transactions/s, all", "vs one process", "per process", "CPU % per process"],
            [
                (
                    k,
                    f"{v['transactions_s']:,}",
                    f"{v['vs_one_process']:.2f}",
                    ", ".join(f"{x:,}" for x in v["per_process_transactions_s"]),
                    ", ".join(f"{x:.0f}" for x in v["per_process_cpu_pct"]),
                )
                for k, v in procs.items()
            ],
            "rrrrr",
        ),
        figures["reading"],
    ]
    profile = figures.get("profile")
    if profile:
        lines += [
            "",
            f"### Where the time goes: 64 buses x {BUS_MOTORS} motors, one process (cProfile)",
            "",
            *_profile.markdown(profile, 12),
        ]
    return "\n".join(lines) + "\n"


def reading(figures: dict[str, Any]) -> str:
    """One paragraph that reads the tables: how many motors fit a 1 kHz tick on one core."""
    bpp = figures["buses_per_process"]
    per_tx = bpp[str(max(BUSES))]["cpu_us_per_transaction"]
    fit = [int(k) * BUS_MOTORS for k, v in bpp.items() if v["cpu_tick_us"] <= 1000]
    best = max(figures["processes"].values(), key=lambda v: v["transactions_s"])
    return (
        f"Reading: at {per_tx:.1f} CPU µs per transaction with many buses, one core's 1 kHz budget (1,000 µs "
        f"per tick, with nothing else to do) holds at most about {1000 / per_tx:.0f} motors' exchanges; in "
        f"this sweep the largest layout under 1,000 µs per tick was {max(fit) if fit else 0} motors. "
        f"Across processes the best aggregate here was {best['transactions_s']:,} transactions/s "
        f"({best['vs_one_process']:.2f}x one process): a user fills a machine with one process per core, "
        "each with its own buses and pacer."
    )


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--worker"]:
        buses, motors, seconds, start_at = int(argv[1]), int(argv[2]), float(argv[3]), float(argv[4])
        print(json.dumps(asyncio.run(worker(buses, motors, seconds, start_at))), flush=True)
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small and once (CI smoke), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md, results.json, scaling.png here")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    load = _meta.load_average()
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    log = lambda line: print(line, flush=True)  # noqa: E731
    print(f"bench_scaling ({cfg.mode}): reflector buses, {cfg.repeats} repeat(s)", flush=True)
    print("motors per bus (one bus):", flush=True)
    figures: dict[str, Any] = {"motors_per_bus": sweep([(1, m) for m in MOTORS_PER_BUS], "motors", cfg, log)}
    print(f"buses per process ({BUS_MOTORS} motors each):", flush=True)
    figures["buses_per_process"] = sweep([(b, BUS_MOTORS) for b in BUSES], "buses", cfg, log)
    figures["buses_motors_per_bus"] = BUS_MOTORS
    print("processes:", flush=True)
    figures["processes"] = processes(cfg, log)
    figures["process_layout"] = {"buses": PROCESS_BUSES, "motors_per_bus": PROCESS_MOTORS}
    figures["reading"] = reading(figures)
    if not args.quick:
        ticks = max(5, 5 * cfg.transactions // (max(BUSES) * BUS_MOTORS))  # setup below 5 % of it
        figures["profile"] = _profile.cprofile(lambda: asyncio.run(ticks_cost(max(BUSES), BUS_MOTORS, ticks)))
    info = _meta.meta(
        "bench/bench_scaling.py",
        argv,
        mode=cfg.mode,
        repeats=cfg.repeats,
        process_repeats=cfg.process_repeats,
        process_seconds=cfg.process_seconds,
        load_average_at_start=load,
        load_average_at_end=_meta.load_average(),
        runtime_s=round(time.perf_counter() - started, 1),
    )
    print(figures["reading"])
    if out_dir is not None:
        plot(figures, out_dir / PLOT.name)
        figures["plot"] = f"bench/{PLOT.name}" if out_dir == BENCH_DIR else str(out_dir / PLOT.name)
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        print(f"Wrote {out_dir / 'RESULTS.md'}, {out_dir / 'results.json'} (key {KEY!r}) and {PLOT.name}.")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The pacer's cost and precision: ``servobus.ticks.ticks(1000)`` idle, the timer against the spin.

What is measured (every configuration in each repeat, their order alternated, medians of the repeats):

* ``pacer.cpu_pct``: the process's CPU (``time.process_time`` over wall time, % of one core) while an
  idle 1 kHz pacer runs on asyncio for ``seconds`` (the body does nothing), waiting on the timer (the
  default on Linux: a timerfd the event loop polls). ``pacer.late_p50_us`` / ``pacer.late_p99_us``: how
  late each tick started (``Tick.late_s``), the run's median and 99th percentile. ``pacer.trio_*``: the
  same on trio.
* ``pacer.spin_*``, ``pacer.spin_trio_*``: the same run with ``precise=False``, the pacer of before
  this timer (sleep until 1.2 ms before the deadline, then yield until it), in the same repeats.
* ``pacer.floor_*``: the machine's own floor, no event loop: a loop that arms the same timerfd and
  blocks in ``epoll_wait`` on it (the CPU a sleep and a wake-up 1,000 times a second cost here, and
  how late the kernel wakes a process).
* ``pacer.rt_*``, ``pacer.rt_trio_*`` (info, where the process may take a real-time priority): the
  timer's runs again with the process at SCHED_FIFO priority 10 (``chrt -f 10``), which a sleeping
  pacer can use safely (a spinning one at that priority would starve the machine's other work).
* ``pacer.cpu_vs_spin``: ``cpu_pct / spin_cpu_pct``; ``pacer.cpu_vs_floor``: ``cpu_pct / floor_cpu_pct``.

The machine is shared (2 cores, other work running): a process that sleeps waits for a core when it
wakes, which the spin never does (it never gives its core up), so lateness p99 depends on the load
given with each run.

Usage (from the repository root)::

    python bench/bench_pacer.py            # full: 5 repeats of 3 s, writes bench/RESULTS.md, results.json
    python bench/bench_pacer.py --quick    # CI smoke run (~2 s), writes nothing
"""

from __future__ import annotations

import argparse
import os
import select
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _results  # noqa: E402
from servobus.core import timer  # noqa: E402
from servobus.ticks import ticks  # noqa: E402

KEY = "pacer"
HZ = 1000
TARGET_CPU_PCT = 5.0
TARGET_LATE_P99_US = 100.0
RT_PRIORITY = 10


@dataclass(frozen=True, slots=True)
class Config:
    mode: str
    repeats: int
    seconds: float


FULL = Config("full", repeats=5, seconds=3.0)
QUICK = Config("quick", repeats=1, seconds=0.3)


@dataclass(frozen=True, slots=True)
class Run:
    """One run of one configuration."""

    cpu_pct: float
    late_p50_us: float
    late_p99_us: float
    late_max_us: float
    ticks: int
    skipped: int


def _percentile(sorted_values: list[float], q: float) -> float:
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def _summary(late_s: list[float], cpu_s: float, wall_s: float, skipped: int) -> Run:
    late = sorted(x * 1e6 for x in late_s)
    return Run(
        cpu_pct=100.0 * cpu_s / wall_s,
        late_p50_us=_percentile(late, 0.5),
        late_p99_us=_percentile(late, 0.99),
        late_max_us=late[-1],
        ticks=len(late),
        skipped=skipped,
    )


def run_pacer(backend: str, precise: bool, seconds: float) -> Run:
    """An idle pacer at HZ for ``seconds`` on ``backend``: its process CPU and its lateness."""

    async def main() -> Run:
        late: list[float] = []
        skipped = 0
        cpu0, wall0 = time.process_time(), time.perf_counter()
        async for tick in ticks(HZ, count=round(seconds * HZ), precise=precise):
            late.append(tick.late_s)
            skipped += tick.skipped
        return _summary(late, time.process_time() - cpu0, time.perf_counter() - wall0, skipped)

    result: Run = anyio.run(main, backend=backend)
    return result


def run_floor(seconds: float) -> Run:
    """The same deadlines without an event loop: arm the timerfd, block in epoll_wait, take it."""
    late: list[float] = []
    period_ns = round(1e9 / HZ)
    with timer.MonotonicTimer() as clock_timer:
        poller = select.epoll()
        try:
            poller.register(clock_timer.fileno(), select.EPOLLIN)
            cpu0, wall0 = time.process_time(), time.perf_counter()
            start_ns = time.monotonic_ns()
            for n in range(round(seconds * HZ)):
                due_ns = start_ns + n * period_ns
                clock_timer.arm(due_ns)
                poller.poll()
                late.append((time.monotonic_ns() - due_ns) / 1e9)
                clock_timer.clear()
            return _summary(late, time.process_time() - cpu0, time.perf_counter() - wall0, 0)
        finally:
            poller.close()


def can_run_realtime() -> bool:
    """True when this process may take SCHED_FIFO (root, or CAP_SYS_NICE, on Linux)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except (AttributeError, OSError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def realtime(run: Callable[[float], Run]) -> Callable[[float], Run]:
    """``run`` with this process at SCHED_FIFO priority RT_PRIORITY (a sleeping pacer: it cannot
    starve the machine, as a spinning one at that priority would), then back to SCHED_OTHER."""

    def wrapped(seconds: float) -> Run:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
        try:
            return run(seconds)
        finally:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    return wrapped


CONFIGS: dict[str, Callable[[float], Run]] = {
    "": lambda s: run_pacer("asyncio", True, s),
    "trio_": lambda s: run_pacer("trio", True, s),
    "spin_": lambda s: run_pacer("asyncio", False, s),
    "spin_trio_": lambda s: run_pacer("trio", False, s),
    "floor_": run_floor,
}
#: the timer again with a real-time priority (SCHED_FIFO), where the process may take one: how late the
#: ticks are when the process does not wait for a core behind others' work
RT_CONFIGS: dict[str, Callable[[float], Run]] = {
    "rt_": realtime(CONFIGS[""]),
    "rt_trio_": realtime(CONFIGS["trio_"]),
}


def measure(cfg: Config, say: Callable[[str], None]) -> dict[str, Any]:
    configs = {**CONFIGS, **(RT_CONFIGS if can_run_realtime() else {})}
    runs: dict[str, list[Run]] = {prefix: [] for prefix in configs}
    order = list(configs)
    for repeat in range(cfg.repeats):
        for prefix in order if repeat % 2 == 0 else reversed(order):
            run = configs[prefix](cfg.seconds)
            runs[prefix].append(run)
            say(
                f"  repeat {repeat + 1} {prefix or 'timer_'}: cpu {run.cpu_pct:.1f} %, late p50 "
                f"{run.late_p50_us:.0f} µs, p99 {run.late_p99_us:.0f} µs, max {run.late_max_us:.0f} µs, "
                f"skipped {run.skipped}"
            )
    figures: dict[str, Any] = {}
    for prefix, done in runs.items():
        for name in ("cpu_pct", "late_p50_us", "late_p99_us", "late_max_us"):
            values = [getattr(r, name) for r in done]
            figures[f"{prefix}{name}"] = round(statistics.median(values), 1)
            figures[f"{prefix}{name}_runs"] = [round(v, 1) for v in values]
        figures[f"{prefix}skipped"] = sum(r.skipped for r in done)
    figures["cpu_vs_spin"] = round(figures["cpu_pct"] / figures["spin_cpu_pct"], 3)
    figures["trio_cpu_vs_spin"] = round(figures["trio_cpu_pct"] / figures["spin_trio_cpu_pct"], 3)
    figures["cpu_vs_floor"] = round(figures["cpu_pct"] / figures["floor_cpu_pct"], 2)
    figures["realtime_measured"] = "rt_" in runs
    figures["hz"] = HZ
    figures["seconds_per_run"] = cfg.seconds
    figures["repeats"] = cfg.repeats
    missed = []
    if figures["cpu_pct"] > TARGET_CPU_PCT:
        missed.append(f"pacer.cpu_pct {figures['cpu_pct']} > {TARGET_CPU_PCT}")
    if figures["late_p99_us"] > TARGET_LATE_P99_US:
        missed.append(f"pacer.late_p99_us {figures['late_p99_us']} > {TARGET_LATE_P99_US}")
    figures["targets_missed"] = missed
    return figures


def render_markdown(f: dict[str, Any], info: dict[str, Any]) -> str:
    def row(label: str, prefix: str) -> tuple[str, ...]:
        return (
            label,
            f"{f[prefix + 'cpu_pct']:.1f} %",
            f"{f[prefix + 'late_p50_us']:.0f} µs",
            f"{f[prefix + 'late_p99_us']:.0f} µs",
            f"{f[prefix + 'late_max_us']:,.0f} µs",
            f"{f[prefix + 'skipped']}",
        )

    rows = [
        row("timer, asyncio (`pacer.cpu_pct`, `pacer.late_p50_us`, `pacer.late_p99_us`)", ""),
        row("timer, trio (`pacer.trio_*`)", "trio_"),
        row("spin (before), asyncio (`pacer.spin_*`)", "spin_"),
        row("spin (before), trio (`pacer.spin_trio_*`)", "spin_trio_"),
        row("floor: timerfd + epoll_wait, no event loop (`pacer.floor_*`)", "floor_"),
    ]
    if f["realtime_measured"]:
        rows += [
            row(f"timer, asyncio, SCHED_FIFO {RT_PRIORITY} (`pacer.rt_*`, info)", "rt_"),
            row(f"timer, trio, SCHED_FIFO {RT_PRIORITY} (`pacer.rt_trio_*`, info)", "rt_trio_"),
        ]
    doc = (__doc__ or "").split("What is measured", 1)[1].split("\n\nUsage", 1)[0]
    lines = [
        *_meta.header_lines("## The pacer: an idle 1 kHz `ticks()` (`bench/bench_pacer.py`)", info),
        "",
        "What is measured" + doc.rstrip(),
        "",
        _results.markdown_table(
            ["configuration", "CPU (% of a core)", "late p50", "late p99", "late max", "skipped"],
            rows,
            "lrrrrr",
        ),
        f"Ratios: timer / spin CPU, asyncio {f['cpu_vs_spin']:.3f} (trio {f['trio_cpu_vs_spin']:.3f}); "
        f"timer / floor CPU {f['cpu_vs_floor']:.2f}. Targets: `pacer.cpu_pct` <= {TARGET_CPU_PCT:g} %, "
        f"`pacer.late_p99_us` <= {TARGET_LATE_P99_US:g} µs. Runs (CPU %, timer, asyncio): "
        f"{', '.join(f'{x:.1f}' for x in f['cpu_pct_runs'])}; late p99 µs: "
        f"{', '.join(f'{x:.0f}' for x in f['late_p99_us_runs'])}.",
        "",
        "Targets missed: " + ("; ".join(f["targets_missed"]) if f["targets_missed"] else "none."),
    ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs (CI smoke run), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    load = _meta.load_average()
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    if not timer.available():
        print("bench_pacer: no timerfd on this platform (the pacer spins here): nothing to compare")
        return 0
    print(f"bench_pacer ({cfg.mode}): {cfg.repeats} x {cfg.seconds} s at {HZ} Hz; load {load}", flush=True)
    figures = measure(cfg, lambda line: print(line, flush=True))
    arguments = list(sys.argv[1:] if argv is None else argv)
    info = _meta.meta(
        "bench/bench_pacer.py",
        arguments,
        mode=cfg.mode,
        load_average_at_start=load,
        statistic=f"median of {cfg.repeats} repeats of {cfg.seconds} s, configurations alternated",
        runtime_s=round(time.perf_counter() - started, 1),
    )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All pacer targets met.")
    print(
        f"pacer.cpu_pct {figures['cpu_pct']} % (spin {figures['spin_cpu_pct']} %, floor "
        f"{figures['floor_cpu_pct']} %), late p50/p99 {figures['late_p50_us']}/{figures['late_p99_us']} µs "
        "(spin "
        f"{figures['spin_late_p50_us']}/{figures['spin_late_p99_us']}); trio {figures['trio_cpu_pct']} %, "
        f"{figures['trio_late_p50_us']}/{figures['trio_late_p99_us']} µs"
    )
    if out_dir is not None:
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

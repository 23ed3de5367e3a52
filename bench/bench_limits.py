"""What host-side limits cost the 1 kHz loop: 32 motors on 11 buses, with and without limits.

The pipelined ``servobus.Loop(hz=1000)`` of ``bench_loop.py`` (32 MyActuator motors on 11 in-process
zero-latency reflector buses, virtual time), every motor given a set-point each tick and its state
read by the body, run with every motor's ``Limits`` set (a position range, speed, current and a field
range: every check a set-point meets) and without, runners alternated repeat by repeat, each repeat
on a fresh event loop. Two set-points: ``SpeedControl`` (one limited field) and the MIT-mode
``MotionCommand`` (five fields, three of them converted from radians).

``limits.<command>_ratio`` = CPU µs per tick with limits / without (median of the per-repeat ratios,
each pair back to back); ``limits.<command>_us_per_command`` = the difference per command. The
limits are within every set-point sent (nothing is refused or clamped: the cost of checking).

Target: ``limits.speed_ratio`` <= 1.10 (a loop that declares its limits keeps 90 % of its rate).

Usage (from the repository root)::

    python bench/bench_limits.py            # full: 11 repeats x 3,000 ticks per runner (~3 min)
    python bench/bench_limits.py --quick    # CI smoke (a few s), writes nothing
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _results  # noqa: E402
from bench_bus import prebuilt_replies  # noqa: E402
from bench_loop import FAMILY, MOTORS_PER_BUS, Sample, _open_buses, _Window, bus_ids  # noqa: E402
from servobus.frame import Frame  # noqa: E402
from servobus.limits import Limits  # noqa: E402
from servobus.loop import Loop  # noqa: E402
from servobus.protocols import Command  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402
from servobus.sim import virtual  # noqa: E402

KEY = "limits"
HZ = 1000
RATIO_TARGET = 1.10
LIMITS = Limits(
    position_deg=(-180, 180), speed_dps=720, current_a=10.0, torque_nm=5.0, fields={"kp": (0, 100)}
)
COMMANDS: dict[str, Command] = {
    "speed": ma.SpeedControl(speed_dps=90.0),
    "mit": ma.MotionCommand(position_rad=0.5, velocity_rad_s=1.0, kp=20, kd=1, torque_ff_nm=0.1),
}


async def run(n: int, warmup: int, replies: dict[int, Frame], command: Command, limited: bool) -> Sample:
    """The Loop giving every motor ``command`` each tick, its limits set (``limited``) or not (a
    set-point beyond them would end the run with LimitExceeded: ``LIMITS`` refuse, never clamp)."""
    window = _Window()
    async with contextlib.AsyncExitStack() as stack:
        buses = await _open_buses(stack, replies)
        motors = [bus.motor(FAMILY, i) for bus, ids in zip(buses, bus_ids(), strict=True) for i in ids]
        for motor in motors:
            motor.limits = LIMITS if limited else None
        async with Loop(hz=HZ) as loop:
            async for tick in loop.ticks(count=warmup + n + 1):
                if tick.index == warmup:
                    window.start()
                for motor in motors:
                    tick.state(motor)
                    tick.command(motor, command)
            sample = window.sample(n)
    return sample


def measure(ticks: int, warmup: int, repeats: int, log: Any) -> dict[str, dict[str, list[Sample]]]:
    samples: dict[str, dict[str, list[Sample]]] = {c: {"with": [], "without": []} for c in COMMANDS}
    for name, command in COMMANDS.items():
        replies = prebuilt_replies(command)
        for repeat in range(repeats):
            for runner in ("without", "with"):
                sample = virtual.run(run(ticks, warmup, replies, command, runner == "with"))
                samples[name][runner].append(sample)
                log(f"  {name:<5} repeat {repeat + 1}/{repeats} {runner:<7} {sample.cpu_us:8.1f} CPU µs/tick")
    return samples


def summarise(samples: dict[str, dict[str, list[Sample]]], ticks: int, repeats: int) -> dict[str, Any]:
    motors = sum(MOTORS_PER_BUS)
    figures: dict[str, Any] = {}
    for name, runs in samples.items():
        pairs = [w.cpu_us / o.cpu_us for w, o in zip(runs["with"], runs["without"], strict=True)]
        extra = [(w.cpu_us - o.cpu_us) / motors for w, o in zip(runs["with"], runs["without"], strict=True)]
        figures[f"{name}_ratio"] = round(statistics.median(pairs), 3)
        figures[f"{name}_ratio_per_repeat"] = [round(min(pairs), 3), round(max(pairs), 3)]
        figures[f"{name}_us_per_command"] = round(statistics.median(extra), 2)
        figures[f"{name}_without_us_per_tick"] = round(
            statistics.median(s.cpu_us for s in runs["without"]), 1
        )
        figures[f"{name}_with_us_per_tick"] = round(statistics.median(s.cpu_us for s in runs["with"]), 1)
    figures["basis"] = (
        f"process CPU µs per tick of servobus.Loop(hz=1000), {motors} MyActuator motors on "
        f"{len(MOTORS_PER_BUS)} reflector buses, virtual time, asyncio; every motor's limits set vs none, "
        "alternated; median of per-repeat ratios"
    )
    figures["limits"] = repr(LIMITS)
    figures["sizes"] = {"ticks": ticks, "repeats": repeats}
    met = figures["speed_ratio"] <= RATIO_TARGET
    figures["targets"] = {"speed_ratio": {"max": RATIO_TARGET, "met": met}}
    figures["targets_missed"] = (
        [] if met else [f"{KEY}.speed_ratio = {figures['speed_ratio']} (<= {RATIO_TARGET})"]
    )
    return figures


def render_markdown(figures: dict[str, Any], info: dict[str, Any]) -> str:
    lines = _meta.header_lines("## What host-side limits cost the 1 kHz loop (`bench/bench_limits.py`)", info)
    sizes = figures["sizes"]
    lines += [
        "",
        "`servobus.Loop(hz=1000)` over 32 MyActuator motors on 11 zero-latency reflector buses (virtual "
        "time, asyncio), every motor given a set-point each tick and its state read, with every motor's "
        f"limits set (`{figures['limits']}`) against none, alternated; {sizes['ticks']:,} ticks per run, "
        f"median of {sizes['repeats']} per-repeat ratios. Every set-point is within the limits: this is the "
        "cost of the check, nothing is refused or clamped.",
        "",
        _results.markdown_table(
            ["set-point", "without µs/tick", "with µs/tick", "with / without (per repeat)", "µs per command"],
            [
                (
                    f"`{type(COMMANDS[name]).__name__}`",
                    f"{figures[f'{name}_without_us_per_tick']:.1f}",
                    f"{figures[f'{name}_with_us_per_tick']:.1f}",
                    "**{:.3f}** ({:.3f} to {:.3f})".format(
                        figures[f"{name}_ratio"], *figures[f"{name}_ratio_per_repeat"]
                    ),
                    f"{figures[f'{name}_us_per_command']:.2f}",
                )
                for name in COMMANDS
            ],
            "lrrrr",
        ),
        f"Target: `limits.speed_ratio` <= {RATIO_TARGET:g}. "
        + (
            "**Not met**: " + "; ".join(figures["targets_missed"]) + "."
            if figures["targets_missed"]
            else "Met."
        ),
    ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="CI smoke run (a few s), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    load = _meta.load_average()
    ticks, warmup, repeats = (100, 10, 1) if args.quick else (3000, 100, 11)
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    print(f"bench_limits: {ticks} ticks x {repeats} repeat(s) per runner", flush=True)
    figures = summarise(measure(ticks, warmup, repeats, lambda line: print(line, flush=True)), ticks, repeats)
    info = _meta.meta(
        "bench/bench_limits.py",
        argv,
        mode="quick" if args.quick else "full",
        load_average_at_start=load,
        runtime_s=round(time.perf_counter() - started, 1),
    )
    for name in COMMANDS:
        print(
            f"limits.{name}_ratio {figures[f'{name}_ratio']:.3f}, "
            f"{figures[f'{name}_us_per_command']:.2f} µs per command"
        )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All limits targets met.")
    if out_dir is not None:
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())

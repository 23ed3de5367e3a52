"""The benchmark suite in one command: ``python -m bench`` (from the repository root).

    python -m bench                 # full: every part, medians of >= 5 runs; writes bench/RESULTS.md,
                                    # bench/results.json and bench/scaling.png (~15-20 min on 2 cores)
    python -m bench --quick         # CI smoke run (well under a minute), writes nothing
    python -m bench --only efficiency --only bus      # some parts
    python -m bench --wait-load 1.0 # first wait (up to --wait-max-s) for a 1-minute load below 1.0
    python -m bench --check         # exit 1 when a target is missed

Parts, in order (each is also a script of its own, ``python bench/bench_<part>.py``):

* ``codec``: C core vs the pure-Python reference (tests/reference) vs hand-written struct code, per call
  and in batch; typed encode/decode through ``Family.bind()`` (``bench_codec.py``).
* ``transport``: the RS485, SLCAN and python-can-virtual receive/send paths (``bench_transport.py``).
* ``bus``: orchestrator cost, ``cycle()`` over 1, 4 and 32 motors on a zero-latency reflector against the
  naive python-can loop and the bare asyncio floor (``bench_bus.py``; ``bus.cycle32_vs_floor``).
* ``efficiency``: bus efficiency on virtual time, CAN, CAN FD and RS485, 1-32 motors, broadcast, LK
  multi-motor torque, 0xB6 streams (``bench_efficiency.py``; ``efficiency.<bus>_<motors>``).
* ``sim``: the simulator's own cost, the C engine against the Python models in the same run: CPU per
  request/reply pair of 32 motors on one bus, and a 10-second virtual scenario's speed-up
  (``bench_sim.py``; ``sim.us_per_exchange``, ``sim.vs_python``, ``sim.virtual_speedup``).
* ``loop``: host CPU per tick of the pipelined ``servobus.Loop``, 32 motors on 11 buses against in-process
  zero-latency reflectors, beside the bare floor and ``Bus.cycle`` (``bench_loop.py``; ``loop.*``).
* ``loop1k``: 32 motors at 1 kHz in real time on the pipelined Loop, the simulated devices in another
  process, the send-and-wait ``cycle`` beside it (``bench_loop1k.py``; ``loop1k.*``, ``loop1k_fd.*``).
* ``scaling``: cost per tick against motors per bus, buses per process and processes, with a plot
  (``bench_scaling.py``; ``scaling.*``).
* ``remote``: servobus.remote across processes on loopback: a Zenoh bridge serving 32 simulated motors,
  a client in another process: set-point updates/s, publish-to-wire latency, request round trip against
  the local Bus, the safe stop after the client is SIGKILLed (``bench_remote.py``; ``remote.*``).
* ``limits``: host-side limits' cost on the pipelined Loop of ``loop``, every motor's limits set against
  none, ``SpeedControl`` and ``MotionCommand`` set-points (``bench_limits.py``; ``limits.*_ratio``).
* ``dashboard``: the dashboard's cost on the loop: ``servobus demo``'s tick rate and loop1k's figures with
  the page open in headless Chromium against without, runs alternated (``bench_dashboard.py``;
  ``dashboard.*_ratio``).

Every part writes its own key of results.json and its own section of RESULTS.md (others' keys and
sections are kept); profiles (cProfile or py-spy) of each headline figure go into its section. The runner
adds a summary section at the top, built from results.json, that lists every headline figure, its target
and whether it was met.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import shlex
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

PARTS = {
    "codec": "bench_codec",
    "transport": "bench_transport",
    "bus": "bench_bus",
    "efficiency": "bench_efficiency",
    "sim": "bench_sim",
    "loop": "bench_loop",
    "loop1k": "bench_loop1k",
    "scaling": "bench_scaling",
    "remote": "bench_remote",
    "pacer": "bench_pacer",
    "dashboard": "bench_dashboard",
    "limits": "bench_limits",
}
SUMMARY = "summary"


def wait_for_load(limit: float, max_s: float) -> list[float]:
    """Wait until the 1-minute load average is below ``limit`` (or ``max_s`` passed); the load then."""
    deadline = time.monotonic() + max_s
    while True:
        load = _meta.load_average()
        if load[0] < limit or time.monotonic() >= deadline:
            return load
        print(f"load average {load[0]:.2f} >= {limit}: waiting (up to {deadline - time.monotonic():.0f} s)")
        time.sleep(min(30.0, max(1.0, deadline - time.monotonic())))


def _get(data: dict[str, Any], path: str) -> Any:
    node: Any = data
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


# (results.json path, label, format, target text, met(value) or None)
HEADLINES: tuple[tuple[str, str, str, str], ...] = (
    ("codec.crc16_mb_s", "CRC16 bulk, C core", "{:,.0f} MB/s", ">= 300 MB/s"),
    ("codec.mit_pack_frames_s", "MIT pack, batch, C core", "{:,.0f} frames/s", ">= 10 M frames/s"),
    ("codec.mit_pack_calls_s_vs_handwritten", "MIT pack per call: C / hand-written struct", "{:.2f}x",
     "(info)"),
    ("codec.typed_decode_us", "typed decode, slowest hot reply", "{:.2f} µs", "<= 2.0 µs"),
    ("bus.cycle32_transactions_s", "`cycle()` x32 on the reflector", "{:,} transactions/s", ">= 100,000"),
    ("bus.cycle32_cpu_us_per_transaction", "`cycle()` x32, CPU per transaction", "{:.2f} µs", "-"),
    ("bus.cycle32_vs_naive", "`cycle()` x32 / naive python-can loop", "{:.2f}x", ">= 5x"),
    ("bus.cycle32_vs_floor", "`cycle()` x32 cost / bare asyncio floor", "{:.2f}x", "<= 4x"),
    ("efficiency.can1m_32", "efficiency, CAN 1 Mbit/s, 32 motors", "{:.4f}", ">= 0.95"),
    ("efficiency.canfd1m5m_32", "efficiency, CAN FD 1/5 Mbit/s, 32 motors", "{:.4f}", ">= 0.95"),
    ("efficiency.rs485_115200_32", "efficiency, RS485 115200, 32 motors", "{:.4f}", ">= 0.95"),
    ("efficiency.rs485_2500k_32", "efficiency, RS485 2.5 Mbaud, 32 motors", "{:.4f}", ">= 0.95"),
    ("sim.us_per_exchange", "simulator: CPU per request/reply pair, 32 motors (C)", "{:.2f} µs", "<= 3 µs"),
    ("sim.vs_python", "simulator: Python models / C engine", "{:.1f}x", ">= 20x"),
    ("sim.virtual_speedup", "simulator: 10 virtual s, 32 motors, saturated bus", "{:.1f}x real time",
     ">= 50x"),
    ("loop.host_us_per_tick", "Loop: host CPU per 1 kHz tick, 32 motors on 11 reflector buses", "{:.1f} µs",
     "<= 150 µs"),
    ("loop.host_vs_floor", "Loop: host CPU per tick / the bare floor's", "{:.2f}x", "<= 2x"),
    ("loop.cycle_us_per_tick", "`Bus.cycle` over the same 11 buses, CPU per tick (before)", "{:.1f} µs",
     "(info)"),
    ("loop1k.on_time_pct", "1 kHz x 32 (CAN, 11 buses), Loop: ticks on time", "{:.2f} %", ">= 99.5 %"),
    ("loop1k.on_time_pct_cycle", "1 kHz x 32 (CAN), `Bus.cycle`: ticks on time (before)", "{:.2f} %",
     "(info)"),
    ("loop1k.state_age_p99_ms", "1 kHz x 32 (CAN), Loop: state age p99", "{:.2f} ms", "<= 2.5 ms"),
    ("loop1k.host_cpu_pct", "1 kHz x 32 (CAN), Loop: host CPU", "{:.0f} %", "<= 50 %"),
    ("loop1k.jitter_p99_us", "1 kHz x 32 (CAN), Loop: tick jitter p99", "{:,.0f} µs", "<= 200 µs"),
    ("loop1k.device_cpu_pct", "1 kHz x 32 (CAN): simulated devices' CPU", "{:.0f} %", "< 25 %"),
    ("loop1k_fd.on_time_pct", "1 kHz x 32 (CAN FD, 8 per bus): ticks on time", "{:.2f} %", ">= 99.5 %"),
    ("loop1k_fd_4pb.on_time_pct", "1 kHz x 32 (CAN FD, 4 per bus): ticks on time", "{:.2f} %", "(info)"),
    ("remote.tick_hz_32", "remote client -> 32 motors: set-point updates/s per motor", "{:,.0f}", ">= 200"),
    ("remote.setpoint_to_wire_p99_ms", "remote set-point: client publish -> bus, p99", "{:.2f} ms",
     "<= 5 ms"),
    ("remote.request_rtt_p50_ms", "remote `read_status2()` round trip, p50", "{:.2f} ms", "(info)"),
    ("remote.request_rtt_vs_local", "remote read p50 / local `Bus.request` p50", "{:.1f}x", "(info)"),
    ("remote.stop_after_client_loss_ms", "client SIGKILLed -> 32 motors stopped, median", "{:.0f} ms",
     "<= 250 ms"),
    ("remote.stop_after_client_loss_max_ms", "client SIGKILLed -> 32 motors stopped, max", "{:.0f} ms",
     "<= 250 ms"),
    ("dashboard.demo_ticks_s_ratio", "`servobus demo` tick rate, dashboard open / without", "{:.3f}",
     ">= 0.95"),
    ("dashboard.loop1k_ticks_s_ratio", "loop1k ticks/s, dashboard open / without", "{:.3f}", ">= 0.95"),
    ("dashboard.loop1k_state_age_p99_ms_ratio", "loop1k state age p99, dashboard open / without", "{:.3f}",
     "<= 1.05"),
    ("dashboard.loop1k_host_cpu_pct_ratio", "loop1k host CPU, dashboard open / without", "{:.3f}",
     "0.95 to 1.05"),
    ("limits.speed_ratio", "Loop 1 kHz x 32, `SpeedControl`: CPU with host-side limits / without", "{:.3f}",
     "<= 1.10"),
    ("limits.mit_ratio", "Loop 1 kHz x 32, `MotionCommand`: CPU with host-side limits / without", "{:.3f}",
     "(info)"),
    ("scaling.buses_per_process.64.cpu_us_per_transaction", "64 buses x 4 motors: CPU per transaction",
     "{:.2f} µs", "-"),
)  # fmt: skip

MISSED_KEYS = (
    "codec", "bus", "efficiency", "sim", "loop", "loop1k", "loop1k_fd", "remote", "pacer", "dashboard",
    "limits",
)  # fmt: skip


def summary_markdown(results: dict[str, Any], command: str, load: list[float], runtime_s: float) -> str:
    machine = _results.machine_info()
    rows = []
    for path, label, form, target in HEADLINES:
        value = _get(results, path)
        if value is None:
            continue
        date = _get(results, path.split(".")[0] + ".meta.machine.date_utc") or _get(
            results, path.split(".")[0] + ".machine.date_utc"
        )
        rows.append((label, f"`{path}`", form.format(value), target, date or ""))
    missed = [m for key in MISSED_KEYS for m in (_get(results, f"{key}.targets_missed") or [])]
    lines = [
        "## Summary (`python -m bench`)",
        "",
        "- Full suite: `python -m bench` (from the repository root, servobus installed: `pip install -e "
        ".[test]`); parts can be rerun alone with `--only <part>`. This summary was last rewritten by "
        f"`{command}` ({runtime_s / 60:.0f} min); each row's date says when its figure was measured",
        f"- Machine: {machine['platform']}; CPU {machine['cpu_model']}, {machine['cpu_count']} cores "
        f"(shared with other work); {machine['python']}",
        "- Load average (1, 5, 15 min) when that invocation started: "
        + ", ".join(f"{x:.2f}" for x in load)
        + " (each section gives the load at its own start; the machine is shared)",
        "- Each section below names its own command, date, load and method; figures are medians of >= 5 "
        "runs unless the section says it is deterministic (virtual time).",
        "",
        _results.markdown_table(["figure", "key", "value", "target", "measured (UTC)"], rows, "llrll"),
        "Targets missed: " + ("; ".join(missed) if missed else "none."),
    ]
    return "\n".join(lines) + "\n"


def write_summary(out_dir: Path, command: str, load: list[float], runtime_s: float) -> None:
    path = out_dir / "results.json"
    results = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
    md = out_dir / "RESULTS.md"
    begin = f"<!-- {SUMMARY}:begin -->"
    text = md.read_text(encoding="utf-8") if md.exists() else ""
    if begin not in text and "\n<!-- " in text:  # put the summary first, right after the title
        head, tail = text.split("\n<!-- ", 1)
        md.write_text(f"{head.rstrip()}\n\n{begin}\n<!-- {SUMMARY}:end -->\n\n<!-- {tail}", encoding="utf-8")
    _results.replace_markdown_section(md, SUMMARY, summary_markdown(results, command, load, runtime_s))


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="CI smoke run: small sizes, writes nothing")
    parser.add_argument("--only", action="append", choices=sorted(PARTS), help="parts to run (repeatable)")
    parser.add_argument(
        "--skip", action="append", choices=sorted(PARTS), default=[], help="parts to leave out"
    )
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--wait-load", type=float, help="first wait for a 1-minute load average below this")
    parser.add_argument("--wait-max-s", type=float, default=1800.0, help="the longest wait (default 30 min)")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    os.environ[_meta.COMMAND_ENV] = shlex.join(["python", "-m", "bench", *argv])
    load = wait_for_load(args.wait_load, args.wait_max_s) if args.wait_load else _meta.load_average()
    parts = [p for p in (args.only or PARTS) if p not in args.skip]
    print(
        f"python -m bench ({'quick' if args.quick else 'full'}): {', '.join(parts)}; load {load}", flush=True
    )
    common = (["--quick"] if args.quick else []) + (["--output", str(args.output)] if args.output else [])
    statuses: dict[str, int] = {}
    times: dict[str, float] = {}
    for part in parts:
        module = importlib.import_module(PARTS[part])
        part_args = [
            *common,
            *(["--check"] if args.check and part != "transport" and part != "scaling" else []),
        ]
        print(f"\n=== {part}: python bench/{PARTS[part]}.py {shlex.join(part_args)}", flush=True)
        t0 = time.perf_counter()
        statuses[part] = int(module.main(part_args) or 0)
        times[part] = time.perf_counter() - t0
    runtime = time.perf_counter() - started
    out_dir = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    if out_dir is not None:
        write_summary(out_dir, os.environ[_meta.COMMAND_ENV], load, runtime)
    print("\n" + ", ".join(f"{p} {t:.0f} s" for p, t in times.items()) + f"; total {runtime:.0f} s")
    failed = [p for p, s in statuses.items() if s]
    if failed:
        print(f"parts with a missed target (--check): {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

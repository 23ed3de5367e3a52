"""Transport benchmark: RS485 frames/s received through SerialTransport vs a plain pyserial read loop.

Set-up: a pseudo-terminal stands in for a USB-RS485 adapter, and its slave is opened at 2.5 Mbaud,
the highest rate MyActuator RS485 allows. A separate writer process pours N MyActuator frames
(``0x3E, ID, 8, DATA[8], CRC16``: 13 bytes, with varying ids and data) into the master as fast as
the kernel takes them. A pty does not pace bytes at the baud rate, so this measures the ceiling of
the host's receive path, which the real line caps at 2.5e6 / 10 / 13 = 19,231 frames/s (8N1); the
table shows both, so the headroom is visible.

Two receivers, in the same run, alternated (A, B, A, B, ...) so that machine noise hits both:

* ``servobus``: ``SerialTransport(framing=<MyActuator's RS485 framing>, baud=2_500_000)``, frames
  taken with ``receive_batch()`` on the event loop (pyserial-asyncio-fast reads, the family's
  framing cuts with the C de-framer, each frame becomes a serial ``Frame`` stamped with the loop's
  clock).
* ``pyserial``: ``serial.Serial(...).read(in_waiting or 1)`` in a blocking loop, the bytes fed to the
  same C de-framer (``MyActuatorRs485Deframer.feed``), so both sides do the same framing work and
  the ratio shows what the asyncio transport costs or saves.

Rate of one repeat = (N - 1) / (time of the last frame - time of the first frame), both taken on the
receiving side with ``time.perf_counter``. Every repeat must receive exactly N frames with no byte
discarded, or the run fails. Reported: the MEDIAN repeat of each, and ``rs485_vs_pyserial`` = median
servobus rate / median pyserial rate. The machine is shared and noisy: rerun before reading much
into a 10 % change.

Usage (from the repository root, with servobus installed)::

    python bench/bench_transport.py            # full run (~20 s): writes bench/RESULTS.md, results.json
    python bench/bench_transport.py --quick    # CI smoke run (a few s): small, writes nothing
    python bench/bench_transport.py --quick --output /tmp/out   # ... and writes there

Outputs: the ``transport`` key of results.json (``rs485_frames_s``, ``rs485_vs_pyserial``, ...,
merged into what other benchmarks keep under that key; other keys are kept too) and the
``transport`` section of RESULTS.md, through bench/_results.py.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

import _meta
import _results
import _slcan
import _virtual
import servobus
from _pty import Pty
from servobus.core import MyActuatorRs485Deframer
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.rs485 import encode_rs485
from servobus.timing import uart_time_s
from servobus.transports import SerialTransport

KEY = "transport"
BAUD = 2_500_000
FRAME_BYTES = 13
WIRE_LIMIT_FRAMES_S = 1 / uart_time_s(FRAME_BYTES, BAUD)

# The writer runs in its own process (its own core and GIL): it writes the stream into the master
# as fast as the kernel's pty buffer drains, then waits to be killed (closing the master would make
# the reader's port vanish before it has read everything).
_WRITER = """
import os, sys, time
fd = int(sys.argv[1]); blob = sys.stdin.buffer.read()
os.set_blocking(fd, True)
view = memoryview(blob)
while view:
    view = view[os.write(fd, view[:65536]):]
time.sleep(3600)
"""


@dataclass(frozen=True)
class Config:
    mode: str
    frames: int
    repeats: int


FULL = Config("full", 200_000, 5)
QUICK = Config("quick", 20_000, 2)


def stream(n: int, seed: int) -> bytes:
    rng = random.Random(seed)
    return b"".join(encode_rs485(rng.randint(1, 32), rng.randbytes(8)) for _ in range(n))


def run_pyserial(path: str, pty: Pty, blob: bytes, n: int) -> float:
    deframer = MyActuatorRs485Deframer()
    got = 0
    with serial.Serial(path, BAUD, timeout=5.0) as port:
        pty.start(blob)
        first = 0.0
        while got < n:
            data = port.read(port.in_waiting or 1)
            if not data:
                raise RuntimeError(f"pyserial: stream stalled after {got} of {n} frames")
            if not first:
                first = time.perf_counter()
            got += len(deframer.feed(data))
        last = time.perf_counter()
    check(got, n, deframer.discarded_bytes, "pyserial")
    return (n - 1) / (last - first)


async def _servobus(path: str, pty: Pty, blob: bytes, n: int) -> float:
    got = 0
    framing = ma.FAMILY.bind(1, link="rs485").framing
    async with SerialTransport(path, framing=framing, baud=BAUD, reopen=False) as transport:
        pty.start(blob)
        first = 0.0
        while got < n:
            frames = await asyncio.wait_for(transport.receive_batch(), 5.0)
            if not first:
                first = time.perf_counter()
            got += len(frames)
        last = time.perf_counter()
        stats = transport.stats()
    check(got, n, stats.discarded_bytes + stats.crc_errors, "servobus")
    return (n - 1) / (last - first)


def run_servobus(path: str, pty: Pty, blob: bytes, n: int) -> float:
    return asyncio.run(_servobus(path, pty, blob, n))


def check(got: int, n: int, bad: int, who: str) -> None:
    if got != n or bad:
        raise RuntimeError(f"{who}: {got} of {n} frames, {bad} bytes discarded: the run is invalid")


def measure(cfg: Config, seed: int, log: Callable[[str], None]) -> dict[str, list[float]]:
    blob = stream(cfg.frames, seed)
    rates: dict[str, list[float]] = {"servobus": [], "pyserial": []}
    runners = {"servobus": run_servobus, "pyserial": run_pyserial}
    for repeat in range(cfg.repeats):
        for name, run in runners.items():
            pty = Pty(_WRITER)
            try:
                rate = run(pty.path, pty, blob, cfg.frames)
            finally:
                pty.close()
            rates[name].append(rate)
            log(f"  repeat {repeat + 1}/{cfg.repeats} {name:8s} {rate:12,.0f} frames/s")
    return rates


def summarise(rates: dict[str, list[float]]) -> dict[str, Any]:
    ours, plain = statistics.median(rates["servobus"]), statistics.median(rates["pyserial"])
    return {
        "rs485_frames_s": round(ours),
        "rs485_vs_pyserial": round(ours / plain, 3),
        "pyserial_frames_s": round(plain),
        "rs485_spread_frames_s": [round(min(rates["servobus"])), round(max(rates["servobus"]))],
        "pyserial_spread_frames_s": [round(min(rates["pyserial"])), round(max(rates["pyserial"]))],
        "wire_limit_frames_s": round(WIRE_LIMIT_FRAMES_S),
        "rs485_vs_wire_limit": round(ours / WIRE_LIMIT_FRAMES_S, 2),
    }


def render_markdown(figures: dict[str, Any], meta: dict[str, Any]) -> str:
    machine = meta["machine"]
    rows = [
        (
            "SerialTransport (`servobus`)",
            f"{figures['rs485_frames_s']:,}",
            "{:,} to {:,}".format(*figures["rs485_spread_frames_s"]),
        ),
        (
            "pyserial read loop + same de-framer",
            f"{figures['pyserial_frames_s']:,}",
            "{:,} to {:,}".format(*figures["pyserial_spread_frames_s"]),
        ),
        ("2.5 Mbaud wire limit, 13-byte frames (8N1)", f"{figures['wire_limit_frames_s']:,}", "(arithmetic)"),
    ]
    return "\n".join(
        [
            "## Transport: RS485 receive path over a pty (`bench/bench_transport.py`)",
            "",
            f"- Command: `{meta['command']}` (from the repository root; {meta['runtime_s']:.0f} s)",
            f"- Date: {machine['date_utc']}; servobus {meta['servobus']}",
            f"- Machine: {machine['platform']}; CPU {machine['cpu_model']}, {machine['cpu_count']} cores "
            "(shared, noisy)",
            f"- Python: {machine['python']}",
            f"- Method: {meta['frames']:,} MyActuator RS485 frames (13 bytes) written into a pty's master by "
            f"a separate process as fast as the kernel takes them; the slave opened at {BAUD:,} baud (a pty "
            "does not pace, so this is the host's ceiling); frames/s from the first to the last frame "
            f"received; median of {meta['repeats']} repeats per receiver, alternated in one run; every "
            "repeat received every frame with no byte discarded.",
            "",
            _results.markdown_table(["receiver", "frames/s (median)", "spread"], rows, "lrr"),
            f"`transport.rs485_vs_pyserial` = **{figures['rs485_vs_pyserial']:.2f}** (servobus / plain "
            f"pyserial, same run); servobus takes in {figures['rs485_vs_wire_limit']:.1f}x what the "
            "2.5 Mbaud line can carry.",
            "",
        ]
    )


def _link_lines(figures: dict[str, Any]) -> list[str]:
    """The native SLCAN and virtual-interface figures (issue 14), under the RS485 table."""
    rows = [
        (
            "native SLCAN (`SlcanTransport`) vs python-can `slcan`, frames/s received",
            f"{figures['slcan_native_frames_s']:,.0f}",
            f"{figures['slcan_python_can_frames_s']:,.0f}",
            f"{figures['slcan_vs_python_can']:.1f}",
            ">= 5",
        ),
        *(
            (
                f"`CanTransport` on `virtual` vs a naive python-can loop: {name}",
                f"{figures[f'virtual_{name}_per_s']:,}",
                f"{figures[f'virtual_{name}_naive_per_s']:,}",
                f"{figures[f'virtual_{name}_vs_naive']:.2f}",
                ">= 1.0",
            )
            for name in ("tx", "rx", "rtt", "pipelined32")
        ),
    ]
    return [
        "### Links (issue 14): native SLCAN and the loop-native virtual path",
        "",
        "Each pair measured in the same run, repeats alternated, median (bench/_slcan.py and "
        "bench/_virtual.py say exactly what each side does). rtt: sequential request/reply to an echo "
        "thread; pipelined32: 32 requests, then their 32 replies.",
        "",
        _results.markdown_table(["figure", "servobus", "baseline", "ratio", "target"], rows, "lrrrr"),
    ]


def kept(out_dir: Path) -> dict[str, Any]:
    """What results.json already holds under ``transport`` (other benchmarks' figures stay)."""
    path = out_dir / "results.json"
    try:
        previous = json.loads(path.read_text(encoding="utf-8")).get(KEY, {})
    except (OSError, ValueError, AttributeError):
        return {}
    return previous if isinstance(previous, dict) else {}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small stream, 2 repeats (CI smoke run)")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--seed", type=int, default=20261121, help="seed of the frame stream")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    cfg = QUICK if args.quick else FULL
    default_dir = None if args.quick else _results.BENCH_DIR
    out_dir: Path | None = args.output if args.output is not None else default_dir
    print(f"bench_transport ({cfg.mode}): {cfg.frames:,} frames x {cfg.repeats} per receiver", flush=True)
    log = lambda line: print(line, flush=True)  # noqa: E731
    figures = summarise(measure(cfg, args.seed, log))
    print("native SLCAN against python-can's slcan, same pty feed:", flush=True)
    figures |= _slcan.run(args.quick, log)
    print("CanTransport on python-can's virtual interface against a naive python-can loop:", flush=True)
    figures |= _virtual.run(args.quick, log)
    arguments = sys.argv[1:] if argv is None else argv
    command = _meta.command_line("bench/bench_transport.py", list(arguments))
    meta = {
        "command": command,
        "machine": _results.machine_info(),
        "servobus": servobus.__version__,
        "frames": cfg.frames,
        "repeats": cfg.repeats,
        "baud": BAUD,
        "runtime_s": round(time.perf_counter() - started, 1),
    }
    print(
        f"servobus {figures['rs485_frames_s']:,} frames/s, pyserial loop {figures['pyserial_frames_s']:,} "
        f"frames/s, ratio {figures['rs485_vs_pyserial']:.2f}; wire limit {figures['wire_limit_frames_s']:,}"
    )
    if out_dir is not None:
        markdown = (
            render_markdown(figures, meta).rstrip("\n") + "\n\n" + "\n".join(_link_lines(figures)) + "\n"
        )
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, markdown)
        _results.update_results_json(out_dir / "results.json", KEY, {**kept(out_dir), **figures, **meta})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

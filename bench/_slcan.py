"""SLCAN receive path: frames/s through SlcanTransport vs python-can's ``slcan`` interface, same pty.

Set-up: a pseudo-terminal stands in for a USB SLCAN adapter. A separate writer process plays the
adapter: it answers every command line the host sends while opening (``\\r``, LAWICEL's OK) and,
once the host has sent ``O``, pours N standard frame lines (``t`` + 3-digit id + DLC 8 + 16 hex
digits + CR: 22 bytes, varying ids and data) into the master as fast as the kernel takes them. A pty
does not pace bytes, so this measures each host's receive ceiling, not a bus's.

Two receivers, alternated (A, B, A, B, ...) in one run so that machine noise hits both:

* ``native``: ``SlcanTransport(path, bitrate=1_000_000)``, frames taken with ``receive_batch()`` on the
  event loop (the port's descriptor read by the loop's reader callback, the C line de-framer cuts and
  checks, each frame becomes a timestamped ``Frame``).
* ``python-can``: ``can.Bus(interface="slcan", channel=path, bitrate=1_000_000, sleep_after_open=0)``,
  frames taken with ``bus.recv()`` in a loop. Its reader takes one byte per ``read(1)`` call, so it
  gets a smaller N (the rate, not the count, is compared).

Rate of one repeat = (N - 1) / (time of the last frame - time of the first frame), both taken on the
receiving side with ``time.perf_counter``. Every repeat must receive exactly N frames, the last one
with the expected identifier and data, and (native) no bad line, or the run fails. Reported: the
MEDIAN repeat of each, and ``slcan_vs_python_can`` = median native rate / median python-can rate.

Run alone (from the repository root): ``python bench/_slcan.py [--quick]``; bench_transport.py calls
:func:`run`.
"""

from __future__ import annotations

import argparse
import asyncio
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from _pty import Pty
from servobus.transports import SlcanTransport

BITRATE = 1_000_000

# The adapter: answer the open sequence, then pour the stream and wait to be killed (closing the
# master would make the host's port vanish before it has read everything).
_ADAPTER = r"""
import os, sys, time
fd = int(sys.argv[1]); blob = sys.stdin.buffer.read()
os.set_blocking(fd, True)
seen = b""
while True:
    data = os.read(fd, 4096)
    os.write(fd, b"\r" * data.count(b"\r"))
    seen = (seen + data)[-64:]
    if b"O\r" in seen:
        break
view = memoryview(blob)
while view:
    view = view[os.write(fd, view[:65536]):]
time.sleep(3600)
"""


@dataclass(frozen=True)
class Config:
    mode: str
    native_frames: int
    python_can_frames: int
    repeats: int


FULL = Config("full", 100_000, 5_000, 5)
QUICK = Config("quick", 20_000, 1_000, 2)


def stream(n: int, seed: int) -> tuple[bytes, tuple[int, bytes]]:
    """N frame lines, and the (id, data) of the last one."""
    rng = random.Random(seed)
    lines = []
    ident, data = 0, b""
    for _ in range(n):
        ident, data = rng.randint(0x241, 0x260), rng.randbytes(8)
        lines.append(b"t%03X8%s\r" % (ident, data.hex().upper().encode()))
    return b"".join(lines), (ident, data)


def run_python_can(pty: Pty, blob: bytes, n: int, last: tuple[int, bytes]) -> float:
    pty.start(blob)
    bus = can.Bus(interface="slcan", channel=pty.path, bitrate=BITRATE, sleep_after_open=0)
    try:
        got = 0
        first = end = 0.0
        message = None
        while got < n:
            message = bus.recv(timeout=10.0)
            if message is None:
                raise RuntimeError(f"python-can: stream stalled after {got} of {n} frames")
            if not first:
                first = time.perf_counter()
            got += 1
        end = time.perf_counter()
    finally:
        bus.shutdown()
    assert message is not None
    check((message.arbitration_id, bytes(message.data)), last, 0, "python-can")
    return (n - 1) / (end - first)


async def _native(pty: Pty, blob: bytes, n: int, last: tuple[int, bytes]) -> float:
    pty.start(blob)
    async with SlcanTransport(pty.path, bitrate=BITRATE, reopen=False, open_timeout_s=10.0) as transport:
        got = 0
        first = end = 0.0
        frames = []
        while got < n:
            frames = await asyncio.wait_for(transport.receive_batch(), 10.0)
            if not first:
                first = time.perf_counter()
            got += len(frames)
        end = time.perf_counter()
        stats = transport.stats()
    if got != n:
        raise RuntimeError(f"native: {got} frames where {n} were sent: the run is invalid")
    check(
        (frames[-1].arbitration_id, frames[-1].data), last, stats.bad_frames + stats.discarded_bytes, "native"
    )
    return (n - 1) / (end - first)


def run_native(pty: Pty, blob: bytes, n: int, last: tuple[int, bytes]) -> float:
    return asyncio.run(_native(pty, blob, n, last))


def check(got: tuple[int, bytes], want: tuple[int, bytes], bad: int, who: str) -> None:
    if got != want or bad:
        raise RuntimeError(f"{who}: last frame {got} (expected {want}), {bad} bad: the run is invalid")


def measure(cfg: Config, seed: int, log: Callable[[str], None]) -> dict[str, list[float]]:
    streams = {
        "native": (run_native, cfg.native_frames, *stream(cfg.native_frames, seed)),
        "python-can": (run_python_can, cfg.python_can_frames, *stream(cfg.python_can_frames, seed)),
    }
    rates: dict[str, list[float]] = {name: [] for name in streams}
    for repeat in range(cfg.repeats):
        for name, (run, n, blob, last) in streams.items():
            pty = Pty(_ADAPTER)
            try:
                rate = run(pty, blob, n, last)
            finally:
                pty.close()
            rates[name].append(rate)
            log(f"  slcan repeat {repeat + 1}/{cfg.repeats} {name:10s} {rate:12,.0f} frames/s ({n:,} frames)")
    return rates


def summarise(rates: dict[str, list[float]], cfg: Config) -> dict[str, Any]:
    native, python_can = statistics.median(rates["native"]), statistics.median(rates["python-can"])
    return {
        "slcan_native_frames_s": round(native),
        "slcan_python_can_frames_s": round(python_can),
        "slcan_vs_python_can": round(native / python_can, 2),
        "slcan_native_spread_frames_s": [round(min(rates["native"])), round(max(rates["native"]))],
        "slcan_python_can_spread_frames_s": [
            round(min(rates["python-can"])),
            round(max(rates["python-can"])),
        ],
        "slcan_frames": {"native": cfg.native_frames, "python_can": cfg.python_can_frames},
        "slcan_repeats": cfg.repeats,
    }


def run(quick: bool, log: Callable[[str], None], seed: int = 20261121) -> dict[str, Any]:
    """Measure both receivers (alternated, median of the repeats); the figures for results.json."""
    cfg = QUICK if quick else FULL
    log(
        f"slcan ({cfg.mode}): native {cfg.native_frames:,} frames, python-can {cfg.python_can_frames:,} "
        f"frames, x {cfg.repeats} each"
    )
    return summarise(measure(cfg, seed, log), cfg)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small streams, 2 repeats")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    figures = run(args.quick, lambda line: print(line, flush=True))
    for key, value in figures.items():
        print(f"{key}: {value}")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Codec benchmark: the C core (servobus.core) against the pure-Python reference, in one run.

What is measured, each as seen from Python through the public wrapper (servobus.core):

* CRC16/MODBUS and CRC32/IEEE in bulk: one call over a 1 MiB random buffer, MB/s (MB = 10**6 bytes).
* CRC16 per call: ``crc16_modbus(b)`` on an 11-byte frame body in a tight loop, calls/s. The loop
  overhead (``for _ in itertools.repeat(None, n)``) is included: it is what a caller pays.
* MIT_COMMAND batch pack and unpack: one ``Packer.pack_into`` / ``Packer.unpack_into`` call over 100k
  frames of random in-range values; frames/s = frames per call / time per call.
* MIT_COMMAND per call: ``Packer.pack(values)`` and ``Packer.unpack(frame)`` on one frame, calls/s.
* De-framing in bulk: ``feed_into`` over a buffer of 100k valid MyActuator RS485 13-byte frames
  (0x3E, ID, 8, DATA[8], CRC16), MB/s. Also, as extra information: the Python-level ``feed()`` (list of
  bytes back) on the same buffer, and ``feed_into`` over hollow transparent (21-byte CRC32) and Modbus RTU
  (0x03 replies, 13 bytes) streams.

The reference (tests/reference: crc.py, packing.py, deframe.py) runs the same operations on smaller
inputs (it is slow; the figures are rates, so the size does not change their meaning), in the same
run, and every C figure is divided by its reference figure (``<name>_vs_reference``). Before timing,
C and reference outputs are compared on the reference-sized inputs, so both sides do the same work.

Method: ``time.perf_counter_ns``; each measurement is calibrated so one repeat takes ~100 ms (C) or
~80 ms (reference), then repeated 7 times (reference: 5) with the garbage collector off, and the
MEDIAN repeat is reported, with the min-max spread of the repeats in results.json. The calibration runs
double as warm-up. The machine is shared and noisy: rerun before reading much into a 10 % change.

Targets (C): CRC16 >= 300 MB/s, CRC32 >= 1000 MB/s, MIT pack and unpack >= 10 M frames/s each,
de-framing >= 100 MB/s, CRC16 per call >= 2 M calls/s, and every C figure >= 20x the reference.
Missed targets are printed; the exit status is 0 unless ``--check`` is given.

Usage (from the repository root, with servobus installed: ``pip install -e .``)::

    python bench/bench_codec.py            # full run (~15 s): writes bench/RESULTS.md, bench/results.json
    python bench/bench_codec.py --quick    # CI smoke run (< 10 s): tiny sizes, 3 repeats, writes nothing
    python bench/bench_codec.py --quick --output /tmp/out   # ... and writes there
    python bench/bench_codec.py --check    # exit 1 when a target is missed

Outputs: the ``codec`` key of results.json (other keys are kept) and the ``codec`` section of
RESULTS.md (other sections are kept), through bench/_results.py.
"""

from __future__ import annotations

import argparse
import array
import gc
import importlib
import importlib.util
import random
import re
import statistics
import sys
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import repeat
from pathlib import Path
from typing import Any, Protocol

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
if str(BENCH_DIR) not in sys.path:  # so `_results` imports however this script is started
    sys.path.insert(0, str(BENCH_DIR))

import _handwritten  # noqa: E402
import _meta  # noqa: E402
import _results  # noqa: E402
import _typed  # noqa: E402
import servobus  # noqa: E402
from servobus.core import (  # noqa: E402
    MIT_COMMAND,
    FieldScale,
    HollowTransparentDeframer,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
    Packer,
    crc16_modbus,
    crc32_ieee,
)

KEY = "codec"
MIN_RATIO = 20.0


def default_cflags() -> str:
    """The compile flags of the C core's default build, asked of the builder itself so the report
    cannot drift from it (SERVOBUS_DEBUG/SANITIZE builds are not benchmark builds)."""
    spec = importlib.util.spec_from_file_location("_sb_builder", REPO / "src" / "servobus" / "_build_core.py")
    assert spec and spec.loader
    builder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(builder)
    cflags, _ = builder.compile_args({})
    return " ".join(f for f in cflags if not f.startswith("-W"))


CFLAGS = default_cflags()

# MIT motion-mode scales of myactuator-v4.md §5.5 ([002] V4.3 ranges).
MIT_SCALES = (
    FieldScale.linear("position_rad", -12.5, 12.5, 16),
    FieldScale.linear("velocity_rad_s", -45.0, 45.0, 12),
    FieldScale.linear("kp", 0.0, 500.0, 12),
    FieldScale.linear("kd", 0.0, 5.0, 12),
    FieldScale.linear("torque_ff_nm", -24.0, 24.0, 12),
)
# Round values near the manual's worked example (myactuator-v4.md §5.6; its v_des is 0x82E = 1.022
# rad/s, so 1.0 packs one code lower), the example frame itself, and the 11-byte RS485 body.
MIT_EXAMPLE_VALUES = (10.0, 1.0, 10.0, 1.0, 10.0)
MIT_EXAMPLE_FRAME = bytes.fromhex("E6 66 82 E0 52 33 3B 55")
RS485_BODY_11 = bytes.fromhex("3E 01 08 9C 00 00 00 00 00 00 00")


# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Config:
    """Sizes and timing of one run."""

    mode: str
    repeats: int
    ref_repeats: int
    c_target_s: float  # wall time of one C repeat
    ref_target_s: float  # wall time of one reference repeat
    crc_bytes: int  # bulk CRC buffer, C
    ref_crc_bytes: int  # bulk CRC buffer, reference
    frames: int  # batch pack/unpack and de-framing, C
    ref_frames: int  # the same, reference


FULL = Config("default", 7, 5, 0.100, 0.080, 1 << 20, 16 << 10, 100_000, 2_000)
QUICK = Config("quick", 3, 3, 0.010, 0.010, 64 << 10, 2 << 10, 5_000, 200)


# ---------------------------------------------------------------------------------------------
# Timing
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Rate:
    """A measured rate: ``units`` per second, the median over the repeats."""

    per_s: float
    iterations: int  # operations per repeat
    units_per_repeat: int
    repeats_ns: tuple[int, ...]

    @property
    def spread(self) -> float:
        """(slowest - fastest repeat) / median repeat."""
        median = statistics.median(self.repeats_ns)
        return (max(self.repeats_ns) - min(self.repeats_ns)) / median

    def as_json(self) -> dict[str, Any]:
        return {
            "per_s": self.per_s,
            "iterations_per_repeat": self.iterations,
            "units_per_repeat": self.units_per_repeat,
            "median_repeat_ms": statistics.median(self.repeats_ns) / 1e6,
            "spread": round(self.spread, 4),
        }


def measure(run: Callable[[int], int], target_s: float, repeats: int) -> Rate:
    """Time ``run(k)``, which performs ``k`` operations and returns the units they processed.

    ``k`` is calibrated (doubling, then scaled) so that one repeat takes about ``target_s``; the
    calibration runs are the warm-up. The rate is units / median repeat time.
    """
    target_ns = target_s * 1e9
    k = 1
    while True:
        t0 = time.perf_counter_ns()
        run(k)
        elapsed = time.perf_counter_ns() - t0
        if elapsed >= target_ns / 4 or k >= 1 << 40:
            break
        k *= 2 if elapsed > target_ns / 64 else 8
    k = max(1, round(k * target_ns / max(elapsed, 1)))
    times: list[int] = []
    units = 0
    gc_was_enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        for _ in range(repeats):
            t0 = time.perf_counter_ns()
            units = run(k)
            times.append(time.perf_counter_ns() - t0)
    finally:
        if gc_was_enabled:
            gc.enable()
    return Rate(units * 1e9 / statistics.median(times), k, units, tuple(times))


# ---------------------------------------------------------------------------------------------
# The reference implementation, seen through a small adapter
# ---------------------------------------------------------------------------------------------


class FeedsBytes(Protocol):
    def feed(self, data: bytes) -> Sequence[Any]: ...


@dataclass(frozen=True, slots=True)
class Reference:
    """The reference's entry points, in the shape the benchmark calls them."""

    source: str
    crc16: Callable[[bytes], int]
    crc32: Callable[[bytes], int]
    mit_pack: Callable[[Sequence[Sequence[float]]], bytes]  # rows of values -> frames back to back
    mit_unpack: Callable[[bytes], Sequence[Sequence[float]]]  # frames back to back -> rows of values
    rs485_deframer: Callable[[], FeedsBytes]
    transparent_deframer: Callable[[], FeedsBytes]
    modbus_deframer: Callable[[], FeedsBytes]  # replies direction


def load_reference() -> Reference:
    """Import tests/reference (crc.py, packing.py, deframe.py) and adapt it.

    tests/ goes on sys.path, as tests/conftest.py does, so the package imports as ``reference``.

    Raises:
        SystemExit: the reference is missing or no longer has the entry points used here.
    """
    tests_dir = REPO / "tests"
    if not (tests_dir / "reference" / "__init__.py").exists():
        raise SystemExit(f"bench_codec: the reference implementation is missing ({tests_dir / 'reference'})")
    if str(tests_dir) not in sys.path:
        sys.path.insert(0, str(tests_dir))
    try:
        crc = importlib.import_module("reference.crc")
        packing = importlib.import_module("reference.packing")
        deframe = importlib.import_module("reference.deframe")

        # packing.pack/unpack take the layout's name and any objects with lo/hi/origin/codes/span
        # (FieldScale has them), and work on batches: rows in, frames out, and back.
        layout_name, scales = MIT_COMMAND.name, MIT_SCALES
        ref_pack, ref_unpack = packing.pack, packing.unpack

        def mit_pack(rows: Sequence[Sequence[float]]) -> bytes:
            return ref_pack(layout_name, scales, rows)  # type: ignore[no-any-return]

        def mit_unpack(frames: bytes) -> Sequence[Sequence[float]]:
            return ref_unpack(layout_name, scales, frames)  # type: ignore[no-any-return]

        modbus = deframe.ModbusRtuDeframer
        return Reference(
            source="tests/reference (crc.py, packing.py, deframe.py)",
            crc16=crc.crc16_modbus,
            crc32=crc.crc32_ieee,
            mit_pack=mit_pack,
            mit_unpack=mit_unpack,
            rs485_deframer=deframe.MyActuatorRs485Deframer,
            transparent_deframer=deframe.TransparentDeframer,
            modbus_deframer=lambda: modbus("replies"),
        )
    except (ImportError, AttributeError) as exc:
        raise SystemExit(
            f"bench_codec: tests/reference does not have what this benchmark calls: {exc}"
        ) from exc


# ---------------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------------


def mit_values(rng: random.Random, n: int) -> array.array[float]:
    """n rows of in-range MIT_COMMAND values, flat."""
    flat = array.array("d")
    bounds = [(s.lo, s.hi) for s in MIT_SCALES]
    uniform = rng.uniform
    flat.extend(uniform(lo, hi) for _ in range(n) for lo, hi in bounds)
    return flat


def rs485_stream(rng: random.Random, n: int) -> bytes:
    """n MyActuator RS485 frames with 8 data bytes: 0x3E, ID, 8, DATA[8], CRC16 low byte first."""
    out = bytearray()
    for _ in range(n):
        body = bytes((0x3E, rng.randint(1, 32), 8)) + rng.randbytes(8)
        out += body + crc16_modbus(body).to_bytes(2, "little")
    return bytes(out)


def transparent_stream(rng: random.Random, n: int) -> bytes:
    """n hollow transparent frames: ID, 16 bytes, CRC32 LSB first (21 bytes)."""
    out = bytearray()
    for _ in range(n):
        body = bytes((rng.randint(1, 32),)) + rng.randbytes(16)
        out += body + crc32_ieee(body).to_bytes(4, "little")
    return bytes(out)


def modbus_stream(rng: random.Random, n: int) -> bytes:
    """n Modbus RTU 0x03 replies with 4 registers: addr, 0x03, 8, DATA[8], CRC16 (13 bytes)."""
    out = bytearray()
    for _ in range(n):
        body = bytes((rng.randint(1, 247), 0x03, 8)) + rng.randbytes(8)
        out += body + crc16_modbus(body).to_bytes(2, "little")
    return bytes(out)


# ---------------------------------------------------------------------------------------------
# The figures
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Figure:
    """One row of the table."""

    name: str  # results.json key
    label: str
    unit: str  # "MB/s", "frames/s" or "calls/s"
    c: Rate
    ref: Rate
    target: float | None  # minimum C rate (in `unit`); None: information only, no target at all
    hand: Rate | None = None  # the hand-written pure-Python baseline (struct / table), where there is one

    @property
    def scale(self) -> float:
        return 1e-6 if self.unit == "MB/s" else 1.0

    @property
    def c_value(self) -> float:
        return self.c.per_s * self.scale

    @property
    def ref_value(self) -> float:
        return self.ref.per_s * self.scale

    @property
    def ratio(self) -> float:
        return self.c.per_s / self.ref.per_s

    @property
    def hand_value(self) -> float | None:
        return None if self.hand is None else self.hand.per_s * self.scale

    @property
    def hand_ratio(self) -> float | None:
        return None if self.hand is None else self.c.per_s / self.hand.per_s

    @property
    def misses(self) -> list[str]:
        """The targets this figure misses (an information-only figure has none)."""
        if self.target is None:
            return []
        missed = []
        if self.c_value < self.target:
            missed.append(
                f"{self.name}: {fmt(self.c_value, self.unit)} < target {fmt(self.target, self.unit)}"
            )
        if self.ratio < MIN_RATIO:
            missed.append(f"{self.name}: {self.ratio:.1f}x the reference < {MIN_RATIO:.0f}x")
        return missed


def size_text(n: int) -> str:
    return f"{n >> 20} MiB" if n >= 1 << 20 and not n % (1 << 20) else f"{n >> 10} KiB"


def fmt(value: float, unit: str) -> str:
    if unit == "MB/s":
        return f"{value:,.0f} MB/s" if value >= 100 else f"{value:.3g} MB/s"
    if value >= 1e6:
        return f"{value / 1e6:.3g} M {unit}"
    if value >= 1e3:
        return f"{value / 1e3:.3g} k {unit}"
    return f"{value:.3g} {unit}"


class Bench:
    """Runs every measurement of one mode, C and reference side by side."""

    def __init__(self, cfg: Config, ref: Reference, log: Callable[[str], None]) -> None:
        self.cfg = cfg
        self.ref = ref
        self.log = log
        self.figures: list[Figure] = []
        self.extra: dict[str, float] = {}
        self.checks: list[str] = []

    def c_rate(self, run: Callable[[int], int]) -> Rate:
        return measure(run, self.cfg.c_target_s, self.cfg.repeats)

    def ref_rate(self, run: Callable[[int], int]) -> Rate:
        return measure(run, self.cfg.ref_target_s, self.cfg.ref_repeats)

    def add(
        self,
        name: str,
        label: str,
        unit: str,
        c: Rate,
        ref: Rate,
        target: float | None = None,
        hand: Rate | None = None,
    ) -> None:
        fig = Figure(name, label, unit, c, ref, target, hand)
        self.figures.append(fig)
        by_hand = "" if fig.hand_value is None else f"   struct/table {fmt(fig.hand_value, unit)}"
        self.log(
            f"  {label:<62} C {fmt(fig.c_value, unit):>16}   ref {fmt(fig.ref_value, unit):>14}"
            f"   {fig.ratio:>8,.0f}x   (spread C {c.spread:.0%}, ref {ref.spread:.0%}){by_hand}"
        )

    def hand_rate(self, run: Callable[[int], int]) -> Rate:
        """A hand-written baseline: timed like the reference (it is Python too)."""
        return measure(run, self.cfg.ref_target_s, self.cfg.ref_repeats)

    def agree(self, what: str, ok: bool) -> None:
        if not ok:
            self.checks.append(what)
            self.log(f"  WARNING: C and reference disagree on {what}: the figures compare different work")

    # ---- CRC ----

    def crc(self, rng: random.Random) -> None:
        cfg, ref = self.cfg, self.ref
        data = rng.randbytes(cfg.crc_bytes)
        small = data[: cfg.ref_crc_bytes]
        for name, c_fn, ref_fn, target in (
            ("crc16_mb_s", crc16_modbus, ref.crc16, 300.0),
            ("crc32_mb_s", crc32_ieee, ref.crc32, 1000.0),
        ):
            self.agree(f"{name} over {len(small)} bytes", c_fn(small) == ref_fn(small))

            def run_c(k: int, f: Callable[[bytes], int] = c_fn) -> int:
                for _ in repeat(None, k):
                    f(data)
                return k * len(data)

            def run_ref(k: int, f: Callable[[bytes], int] = ref_fn) -> int:
                for _ in repeat(None, k):
                    f(small)
                return k * len(small)

            hand = None
            if name == "crc16_mb_s":
                self.agree("table-driven crc16", _handwritten.crc16_table(small) == c_fn(small))

                def run_hand(k: int) -> int:
                    for _ in repeat(None, k):
                        _handwritten.crc16_table(small)
                    return k * len(small)

                hand = self.hand_rate(run_hand)
            label = f"{name[:5].upper()} bulk ({size_text(len(data))} per call)"
            self.add(name, label, "MB/s", self.c_rate(run_c), self.ref_rate(run_ref), target, hand)

        # Context only: the stdlib's CRC-32 (zlib), same buffer.
        def run_zlib(k: int) -> int:
            for _ in repeat(None, k):
                zlib.crc32(data)
            return k * len(data)

        self.extra["crc32_zlib_mb_s"] = self.c_rate(run_zlib).per_s / 1e6

        # Per call from Python: 11 bytes, the body of a MyActuator RS485 frame.
        body = RS485_BODY_11
        self.agree("crc16 of the 11-byte body", crc16_modbus(body) == ref.crc16(body))

        def calls_c(k: int) -> int:
            f = crc16_modbus
            for _ in repeat(None, k):
                f(body)
            return k

        def calls_ref(k: int) -> int:
            f = ref.crc16
            for _ in repeat(None, k):
                f(body)
            return k

        def calls_hand(k: int) -> int:
            f = _handwritten.crc16_table
            for _ in repeat(None, k):
                f(body)
            return k

        self.add(
            "crc16_calls_s",
            "CRC16 per call, 11 bytes",
            "calls/s",
            self.c_rate(calls_c),
            self.ref_rate(calls_ref),
            2e6,
            self.hand_rate(calls_hand),
        )

    # ---- MIT pack / unpack ----

    def packing(self, rng: random.Random) -> None:
        cfg, ref = self.cfg, self.ref
        packer = Packer(MIT_COMMAND, MIT_SCALES)
        nf, size = len(MIT_SCALES), MIT_COMMAND.size
        values = mit_values(rng, cfg.frames)
        frames = bytearray(cfg.frames * size)
        decoded = array.array("d", bytes(8 * len(values)))
        packer.pack_into(values, frames)
        frames_b = bytes(frames)

        # The reference packs a batch as a list of rows and unpacks back to a list of tuples.
        rows = [tuple(values[i * nf : (i + 1) * nf]) for i in range(cfg.ref_frames)]
        small_frames = frames_b[: len(rows) * size]
        packer.unpack_into(frames_b, decoded)
        hand = _handwritten.make_mit(MIT_SCALES)
        self.agree(f"struct MIT pack of {len(rows)} frames", hand.pack_many(rows) == small_frames)
        self.agree(
            f"struct MIT unpack of {len(rows)} frames",
            hand.unpack_many(small_frames)
            == [tuple(decoded[i * nf : (i + 1) * nf]) for i in range(len(rows))],
        )

        def pack_hand(k: int) -> int:
            pack_many = hand.pack_many
            for _ in repeat(None, k):
                pack_many(rows)
            return k * len(rows)

        def unpack_hand(k: int) -> int:
            unpack_many = hand.unpack_many
            for _ in repeat(None, k):
                unpack_many(small_frames)
            return k * len(rows)

        self.agree(f"MIT pack of {len(rows)} frames", ref.mit_pack(rows) == small_frames)
        self.agree(
            f"MIT unpack of {len(rows)} frames",
            [tuple(r) for r in ref.mit_unpack(small_frames)]
            == [tuple(decoded[i * nf : (i + 1) * nf]) for i in range(len(rows))],
        )

        def pack_c(k: int) -> int:
            pack_into = packer.pack_into
            for _ in repeat(None, k):
                pack_into(values, frames)
            return k * cfg.frames

        def pack_ref(k: int) -> int:
            pack = ref.mit_pack
            for _ in repeat(None, k):
                pack(rows)
            return k * len(rows)

        def unpack_c(k: int) -> int:
            unpack_into = packer.unpack_into
            for _ in repeat(None, k):
                unpack_into(frames_b, decoded)
            return k * cfg.frames

        def unpack_ref(k: int) -> int:
            unpack = ref.mit_unpack
            for _ in repeat(None, k):
                unpack(small_frames)
            return k * len(rows)

        batch = f"{cfg.frames // 1000}k frames per call"
        pack_rate, pack_ref_rate = self.c_rate(pack_c), self.ref_rate(pack_ref)
        self.add(
            "mit_pack_frames_s",
            f"MIT pack_into, batch ({batch})",
            "frames/s",
            pack_rate,
            pack_ref_rate,
            10e6,
            self.hand_rate(pack_hand),
        )
        unpack_rate, unpack_ref_rate = self.c_rate(unpack_c), self.ref_rate(unpack_ref)
        self.add(
            "mit_unpack_frames_s",
            f"MIT unpack_into, batch ({batch})",
            "frames/s",
            unpack_rate,
            unpack_ref_rate,
            10e6,
            self.hand_rate(unpack_hand),
        )

        # Per call from Python, one frame: Packer.pack(list of 5 floats) -> bytes, Packer.unpack(bytes)
        # -> tuple; the reference's batch functions with a batch of one.
        one_values, one_frame = list(MIT_EXAMPLE_VALUES), MIT_EXAMPLE_FRAME
        one_rows = [one_values]
        self.agree("MIT pack of the manual's example", packer.pack(one_values) == ref.mit_pack(one_rows))
        self.agree(
            "MIT unpack of the manual's example",
            [packer.unpack(one_frame)] == list(ref.mit_unpack(one_frame)),
        )

        self.agree(
            "struct MIT pack of the manual's example", hand.pack(one_values) == packer.pack(one_values)
        )
        self.agree(
            "struct MIT unpack of the manual's example", hand.unpack(one_frame) == packer.unpack(one_frame)
        )

        def pack1_hand(k: int) -> int:
            pack = hand.pack
            for _ in repeat(None, k):
                pack(one_values)
            return k

        def unpack1_hand(k: int) -> int:
            unpack = hand.unpack
            for _ in repeat(None, k):
                unpack(one_frame)
            return k

        def pack1_c(k: int) -> int:
            pack = packer.pack
            for _ in repeat(None, k):
                pack(one_values)
            return k

        def pack1_ref(k: int) -> int:
            pack = ref.mit_pack
            for _ in repeat(None, k):
                pack(one_rows)
            return k

        def unpack1_c(k: int) -> int:
            unpack = packer.unpack
            for _ in repeat(None, k):
                unpack(one_frame)
            return k

        def unpack1_ref(k: int) -> int:
            unpack = ref.mit_unpack
            for _ in repeat(None, k):
                unpack(one_frame)
            return k

        self.add(
            "mit_pack_calls_s",
            "MIT Packer.pack, one frame per call",
            "calls/s",
            self.c_rate(pack1_c),
            self.ref_rate(pack1_ref),
            hand=self.hand_rate(pack1_hand),
        )
        self.add(
            "mit_unpack_calls_s",
            "MIT Packer.unpack, one frame per call",
            "calls/s",
            self.c_rate(unpack1_c),
            self.ref_rate(unpack1_ref),
            hand=self.hand_rate(unpack1_hand),
        )

    # ---- de-framing ----

    def deframing(self, rng: random.Random) -> None:
        cfg = self.cfg
        cases: tuple[
            tuple[
                str,
                str,
                Callable[[random.Random, int], bytes],
                Callable[[], Any],
                Callable[[], FeedsBytes],
                float | None,
            ],
            ...,
        ] = (
            (
                "deframe_mb_s",
                "MyActuator RS485",
                rs485_stream,
                MyActuatorRs485Deframer,
                self.ref.rs485_deframer,
                100.0,
            ),
            (
                "deframe_transparent_mb_s",
                "hollow transparent",
                transparent_stream,
                HollowTransparentDeframer,
                self.ref.transparent_deframer,
                None,
            ),
            (
                "deframe_modbus_mb_s",
                "Modbus RTU replies",
                modbus_stream,
                ModbusRtuDeframer,
                self.ref.modbus_deframer,
                None,
            ),
        )
        for name, what, make_stream, c_cls, ref_cls, target in cases:
            stream = make_stream(rng, cfg.frames)
            frame_len = len(stream) // cfg.frames
            small = stream[: cfg.ref_frames * frame_len]

            c_frames = c_cls().feed(small)
            ref_frames = [bytes(f) for f in ref_cls().feed(small)]
            self.agree(
                f"{what} de-framing of {cfg.ref_frames} frames",
                c_frames == ref_frames and len(c_frames) == cfg.ref_frames,
            )

            deframer = c_cls()
            out = bytearray(len(stream) + 4096)
            lens = array.array("H", bytes(2 * (cfg.frames + 1)))
            n, used = deframer.feed_into(stream, out, lens)
            if (n, used) != (cfg.frames, len(stream)) or out[: len(stream)] != stream:
                raise SystemExit(f"bench_codec: {what} feed_into returned {n} frames, consumed {used}")

            def into_c(
                k: int, d: Any = deframer, s: bytes = stream, o: bytearray = out, ln: array.array[int] = lens
            ) -> int:
                feed_into = d.feed_into
                for _ in repeat(None, k):
                    feed_into(s, o, ln)
                return k * len(s)

            def feed_ref(k: int, make: Callable[[], FeedsBytes] = ref_cls, s: bytes = small) -> int:
                d = make()
                for _ in repeat(None, k):
                    d.feed(s)
                return k * len(s)

            ref_rate = self.ref_rate(feed_ref)
            per_call = f"{cfg.frames // 1000}k x {frame_len} B frames"
            self.add(
                name,
                f"De-frame {what}, feed_into ({per_call})",
                "MB/s",
                self.c_rate(into_c),
                ref_rate,
                target,
            )
            if (deframer.discarded_bytes, deframer.crc_errors, deframer.pending) != (0, 0, 0):
                raise SystemExit(f"bench_codec: {what} de-framer dropped bytes: {deframer!r}")

            if name == "deframe_mb_s":  # the Python-level feed(): a list of bytes objects back

                def feed_c(k: int, s: bytes = stream) -> int:
                    d = MyActuatorRs485Deframer()
                    for _ in repeat(None, k):
                        d.feed(s)
                    return k * len(s)

                self.add(
                    "deframe_feed_mb_s",
                    f"De-frame {what}, feed() -> list[bytes]",
                    "MB/s",
                    self.c_rate(feed_c),
                    ref_rate,
                )


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------


def compiler_of_core() -> str:
    """The compiler that built servobus._core, from the shared object's .comment section."""
    import servobus._core as core

    try:
        blob = Path(core.__file__).read_bytes()
    except (OSError, TypeError):
        return "unknown compiler"
    found = re.search(rb"GCC: \([^)]*\) [0-9.]+|clang version [0-9.]+", blob)
    return found.group(0).decode() if found else "unknown compiler"


def target_text(fig: Figure) -> str:
    if fig.target is None:
        return "(info)"
    return f">= {fmt(fig.target, fig.unit)}, >= {MIN_RATIO:.0f}x"


def met_text(fig: Figure) -> str:
    if fig.target is None:
        return "-"
    return "no" if fig.misses else "yes"


def info_below_ratio(bench: Bench) -> list[str]:
    """Information-only figures under MIN_RATIO: not targets, but said out loud."""
    return [f"{f.name} {f.ratio:.1f}x" for f in bench.figures if f.target is None and f.ratio < MIN_RATIO]


def render_markdown(bench: Bench, meta: dict[str, Any], missed: list[str]) -> str:
    machine = meta["machine"]
    rows = []
    for fig in bench.figures:
        hand_value, hand_ratio = fig.hand_value, fig.hand_ratio
        rows.append(
            (
                f"{fig.label} (`{fig.name}`)",
                fmt(fig.c_value, fig.unit),
                fmt(fig.ref_value, fig.unit),
                f"{fig.ratio:,.0f}x",
                "-" if hand_value is None else fmt(hand_value, fig.unit),
                "-" if hand_ratio is None else f"{hand_ratio:,.1f}x",
                target_text(fig),
                met_text(fig),
            )
        )
    lines = [
        "## Codec: C core vs the pure-Python reference (`bench/bench_codec.py`)",
        "",
        f"- Command: `{meta['command']}` (from the repository root; {meta['runtime_s']:.0f} s)",
        f"- Date: {machine['date_utc']}; servobus {meta['servobus']}",
        f"- Machine: {machine['platform']}; CPU {machine['cpu_model']}, {machine['cpu_count']} cores "
        "(shared, noisy)",
        f"- Python: {machine['python']}; C core: {meta['compiler']}, `{CFLAGS}` (cffi, default build)",
        f"- Reference: {meta['reference']}",
        f"- Method: `time.perf_counter_ns`, median of {bench.cfg.repeats} repeats of ~"
        f"{bench.cfg.c_target_s * 1000:.0f} ms for C and {bench.cfg.ref_repeats} of ~"
        f"{bench.cfg.ref_target_s * 1000:.0f} ms for the reference (smaller inputs, same operation), GC off; "
        "ratio = C rate / reference rate in this run. MB = 10^6 bytes. Per-call figures include the "
        "Python loop.",
        "",
        _results.markdown_table(
            ["figure", "C", "reference", "C / ref", "hand-written", "C / hand", "target", "met?"],
            rows,
            "lrrrrrll",
        ),
        "Hand-written = what a user writes in plain Python without the C core (bench/_handwritten.py): "
        "MIT pack/unpack with `struct` and shifts, unrolled for the layout, same range check and float "
        "operations (its bytes are checked equal to the C core's before timing), per frame and in batch "
        "(one `struct.pack` of all words / `iter_unpack`); CRC16 table-driven, one lookup per byte.",
        "",
        "Targets apply to the figures named in the issue; rows marked (info) are extra information with "
        "no target.",
        "",
        f"Context: stdlib `zlib.crc32` over the same {size_text(bench.cfg.crc_bytes)} buffer: "
        f"{bench.extra['crc32_zlib_mb_s']:,.0f} MB/s.",
        "",
        "Missed: " + ("; ".join(missed) if missed else "none: every target met."),
    ]
    below = info_below_ratio(bench)
    if below:
        lines += [
            "",
            f"Information-only figures under {MIN_RATIO:.0f}x the reference: {', '.join(below)}. With one "
            "frame per call, the C side's time goes to the wrapper's Python work (argument checks, filling "
            "the cdata row, building the bytes or tuple), not to the C packing itself.",
        ]
    if bench.checks:
        lines += ["", "C/reference DISAGREED on: " + "; ".join(bench.checks)]
    return "\n".join(lines) + "\n"


def build_json(bench: Bench, meta: dict[str, Any], missed: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    targets: dict[str, Any] = {}
    detail: dict[str, Any] = {}
    for fig in bench.figures:
        out[fig.name] = round(fig.c_value, 3)
        out[f"{fig.name}_reference"] = round(fig.ref_value, 3)
        out[f"{fig.name}_vs_reference"] = round(fig.ratio, 2)
        if fig.hand_value is not None and fig.hand_ratio is not None:
            out[f"{fig.name}_handwritten"] = round(fig.hand_value, 3)
            out[f"{fig.name}_vs_handwritten"] = round(fig.hand_ratio, 2)
        if fig.target is not None:
            targets[fig.name] = {"min": fig.target, "min_vs_reference": MIN_RATIO, "met": not fig.misses}
        detail[fig.name] = {"c": fig.c.as_json(), "reference": fig.ref.as_json(), "unit": fig.unit}
    out.update({name: round(value, 3) for name, value in bench.extra.items()})
    out["targets"] = targets
    out["targets_missed"] = missed
    out["reference_agrees"] = not bench.checks
    out["detail"] = detail
    out["meta"] = meta | {
        "mode": bench.cfg.mode,
        "repeats": bench.cfg.repeats,
        "reference_repeats": bench.cfg.ref_repeats,
        "statistic": "median",
        "units": {
            "MB/s": "10**6 bytes per second",
            "frames/s": "frames per second",
            "calls/s": "calls/second",
        },
        "cflags": CFLAGS,
    }
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes and 3 repeats (CI smoke run)")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--seed", type=int, default=20240601, help="seed of the random inputs")
    args = parser.parse_args(argv)

    started = time.perf_counter()
    cfg = QUICK if args.quick else FULL
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    ref = load_reference()
    print(f"bench_codec ({cfg.mode}): C core vs {ref.source}", flush=True)
    bench = Bench(cfg, ref, lambda line: print(line, flush=True))
    rng = random.Random(args.seed)
    bench.crc(rng)
    bench.packing(rng)
    bench.deframing(rng)
    print("typed codec through Family.bind():", flush=True)
    typed = _typed.run(args.quick, lambda line: print(line, flush=True))

    missed = [m for fig in bench.figures for m in fig.misses] + _typed.misses(typed)
    command = _meta.command_line("bench/bench_codec.py", list(sys.argv[1:] if argv is None else argv))
    meta = {
        "command": command,
        "machine": _results.machine_info(),
        "compiler": compiler_of_core(),
        "reference": ref.source,
        "servobus": servobus.__version__,
        "runtime_s": round(time.perf_counter() - started, 1),
    }

    print()
    if bench.checks:
        print("C and reference DISAGREE on: " + "; ".join(bench.checks))
    if missed:
        print("TARGETS MISSED:")
        for line in missed:
            print(f"  - {line}")
    else:
        print("All targets met.")
    below = info_below_ratio(bench)
    if below:
        print(f"Information only (no target), under {MIN_RATIO:.0f}x the reference: {', '.join(below)}")
    if out_dir is not None:
        markdown = (
            render_markdown(bench, meta, missed).rstrip("\n")
            + "\n"
            + "\n".join(_typed.markdown(typed))
            + "\n"
        )
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, markdown)
        _results.update_results_json(out_dir / "results.json", KEY, build_json(bench, meta, missed) | typed)
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and (missed or bench.checks) else 0


if __name__ == "__main__":
    sys.exit(main())

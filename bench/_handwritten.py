"""Hand-written pure-Python baselines for bench_codec: what a user writes without servobus's C core.

* MIT_COMMAND pack and unpack with ``struct`` and integer shifts, unrolled for the one layout (p 16 bits,
  v, kp, kd, t 12 bits each, big-endian: myactuator-v4.md §5.2), with the same range check and the same
  float operations as the C core (``(x - origin) * codes / span``, rounded half up, which is half away
  from zero for the non-negative values an in-range field gives), so the bytes agree with the C core's
  (bench_codec checks that before timing). Per frame (``mit_pack``, ``mit_unpack``) and in batch
  (``mit_pack_many``: one ``struct.pack`` of all the 64-bit words; ``mit_unpack_many``: ``iter_unpack``).
* CRC-16/MODBUS the usual fast way in Python: a 256-entry table, one lookup per byte.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

__all__ = ["Mit", "crc16_table", "make_mit"]

_Q = struct.Struct(">Q")
Row = tuple[float, float, float, float, float]


class Mit(NamedTuple):
    pack: Callable[[Sequence[float]], bytes]
    unpack: Callable[[bytes], Row]
    pack_many: Callable[[Sequence[Sequence[float]]], bytes]
    unpack_many: Callable[[bytes], list[Row]]


def make_mit(scales: Sequence[Any]) -> Mit:
    """The four MIT_COMMAND functions for these five FieldScales (lo, hi, origin, codes, span)."""
    fields = [(float(s.lo), float(s.hi), float(s.origin), float(s.codes), float(s.span)) for s in scales]
    (plo, phi, po, pc, ps), (vlo, vhi, vo, vc, vs), (klo, khi, ko, kc, ks) = fields[:3]
    (dlo, dhi, do, dc, ds), (tlo, thi, to, tc, ts) = fields[3:]
    floor = math.floor

    def word(values: Sequence[float]) -> int:
        p, v, kp, kd, t = values
        if not (plo <= p <= phi and vlo <= v <= vhi and klo <= kp <= khi and dlo <= kd <= dhi):
            raise ValueError(f"MIT value out of range: {values!r}")
        if not tlo <= t <= thi:
            raise ValueError(f"MIT value out of range: {values!r}")
        return (
            floor((p - po) * pc / ps + 0.5) << 48
            | floor((v - vo) * vc / vs + 0.5) << 36
            | floor((kp - ko) * kc / ks + 0.5) << 24
            | floor((kd - do) * dc / ds + 0.5) << 12
            | floor((t - to) * tc / ts + 0.5)
        )

    def pack(values: Sequence[float]) -> bytes:
        return _Q.pack(word(values))

    def unpack(frame: bytes) -> Row:
        (w,) = _Q.unpack(frame)
        return (
            (w >> 48) * ps / pc + po,
            ((w >> 36) & 0xFFF) * vs / vc + vo,
            ((w >> 24) & 0xFFF) * ks / kc + ko,
            ((w >> 12) & 0xFFF) * ds / dc + do,
            (w & 0xFFF) * ts / tc + to,
        )

    def pack_many(rows: Sequence[Sequence[float]]) -> bytes:
        return struct.pack(f">{len(rows)}Q", *map(word, rows))

    def unpack_many(frames: bytes) -> list[Row]:
        return [
            (
                (w >> 48) * ps / pc + po,
                ((w >> 36) & 0xFFF) * vs / vc + vo,
                ((w >> 24) & 0xFFF) * ks / kc + ko,
                ((w >> 12) & 0xFFF) * ds / dc + do,
                (w & 0xFFF) * ts / tc + to,
            )
            for (w,) in _Q.iter_unpack(frames)
        ]

    return Mit(pack, unpack, pack_many, unpack_many)


def _crc16_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_TABLE = _crc16_table()


def crc16_table(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MODBUS, table-driven."""
    table = _TABLE
    for byte in data:
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc

"""Field scaling and frame bit layouts, written from the specs: the oracle for csrc/bitpack.c.

Scaling (csrc/servobus_core.h)::

    code = round_half_away_from_zero((x - origin) * codes / span)     # this order of float operations
    x    = code * span / codes + origin

Packing checks ``lo <= x <= hi`` first (NaN always fails; ``saturate`` clamps x into [lo, hi] instead),
then clamps the code into the field's bit range. Python floats are IEEE doubles and every operation
here is one correctly rounded double operation, so results are bit-identical to C built without FMA
contraction (_build_core.py passes -ffp-contract=off).

Layouts, one function per direction, byte by byte as the manuals' tables give them:

* MIT_COMMAND: myactuator-v4.md §5.2 (= hollow.md §4.2 setpoint), p 16 bits, v/kp/kd/t 12 bits.
* HOLLOW_SETPOINT: the same, but never FF x7 + F9..FE (a special command, hollow.md §4.1, A35).
* MIT_REPLY: myactuator-v4.md §5.3 (= hollow.md §4.5), id 8, p 16, v 12, t 12 (6 bytes).
* HOLLOW_EXT_REPLY: hollow.md §5.3, id 8, x int32 split D1-D2 = x[15:0], D6-D7 = x[31:16], v 12, t 12.
* HOLLOW_FD_COMMAND / HOLLOW_FD_REPLY: hollow.md §7.2 / §7.3, 16 bytes, big-endian signed 40/32/16-bit
  pos/vel/cur then five bytes (the reply's D14 temperature is int8).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

__all__ = [
    "LAYOUTS",
    "SPECIAL_COMMAND_CODES",
    "PackError",
    "RefLayout",
    "Scale",
    "code_range",
    "decode",
    "encode",
    "is_special_command",
    "pack",
    "round_half_away_from_zero",
    "unpack",
    "unpack_codes",
]

ErrorKind = Literal["nan", "range"]


class Scale(Protocol):
    """What the oracle needs of a field scale (servobus.core.FieldScale has these attributes)."""

    @property
    def lo(self) -> float: ...
    @property
    def hi(self) -> float: ...
    @property
    def origin(self) -> float: ...
    @property
    def codes(self) -> float: ...
    @property
    def span(self) -> float: ...


class PackError(ValueError):
    """A value that cannot be packed: where it is (frame, field), what it is and why (kind)."""

    def __init__(self, frame: int, field: int, value: float, kind: ErrorKind) -> None:
        super().__init__(f"frame {frame} field {field}: {value!r} ({kind})")
        self.frame = frame
        self.field = field
        self.value = value
        self.kind: ErrorKind = kind

    def key(self) -> tuple[int, int, ErrorKind]:
        return (self.frame, self.field, self.kind)


class _FieldError(Exception):
    def __init__(self, kind: ErrorKind) -> None:
        self.kind: ErrorKind = kind


# ---- scaling ----


def round_half_away_from_zero(v: float) -> float | int:
    """C's round(): nearest integer, ties away from zero. ±inf come back unchanged.

    ``magnitude - math.floor(magnitude)`` is exact: below 2**52 the floor only clears fraction bits of
    the same binade, and from 2**52 up every double is an integer, so the fraction is exactly 0.
    """
    if math.isinf(v):
        return v
    magnitude = abs(v)
    whole = math.floor(magnitude)
    if magnitude - whole >= 0.5:
        whole += 1
    return whole if v >= 0 else -whole


def code_range(bits: int) -> tuple[int, int]:
    """Smallest and largest code of a field; negative ``bits`` means two's complement."""
    if bits < 0:
        top = 1 << (-bits - 1)
        return -top, top - 1
    return 0, (1 << bits) - 1


def encode(scale: Scale, x: float, bits: int, *, saturate: bool = False) -> int:
    """One value to its code, or _FieldError("nan" / "range")."""
    x = float(x)
    lo, hi = float(scale.lo), float(scale.hi)
    if math.isnan(x):
        raise _FieldError("nan")
    if not lo <= x <= hi:
        if not saturate:
            raise _FieldError("range")
        x = lo if x < lo else hi
    real = (x - float(scale.origin)) * float(scale.codes) / float(scale.span)
    code = round_half_away_from_zero(real)
    cmin, cmax = code_range(bits)
    if code <= cmin:
        return cmin
    if code >= cmax:
        return cmax
    return int(code)


def decode(scale: Scale, code: int) -> float:
    """One code back to its physical value."""
    return float(code) * float(scale.span) / float(scale.codes) + float(scale.origin)


# ---- byte layouts ----

SPECIAL_COMMAND_CODES = range(0xF9, 0xFF)  # F9 torque, FA speed, FB position, FC start, FD stop, FE zero


def is_special_command(frame: bytes) -> bool:
    """True for the hollow normal-mode special commands FF FF FF FF FF FF FF F9..FE (hollow.md §4.1)."""
    return len(frame) == 8 and frame[:7] == b"\xff" * 7 and frame[7] in SPECIAL_COMMAND_CODES


def _put_mit_command(c: Sequence[int]) -> bytes:
    p, v, kp, kd, t = c
    # myactuator-v4.md §5.2 "In code" line, identical to the hollow manual's C routine (hollow.md §4.2).
    return bytes(
        [
            p >> 8,
            p & 0xFF,
            v >> 4,
            ((v & 0xF) << 4) | (kp >> 8),
            kp & 0xFF,
            kd >> 4,
            ((kd & 0xF) << 4) | (t >> 8),
            t & 0xFF,
        ]
    )


def _get_mit_command(b: bytes) -> list[int]:
    return [
        (b[0] << 8) | b[1],
        (b[2] << 4) | (b[3] >> 4),
        ((b[3] & 0xF) << 8) | b[4],
        (b[5] << 4) | (b[6] >> 4),
        ((b[6] & 0xF) << 8) | b[7],
    ]


def _put_hollow_setpoint(c: Sequence[int]) -> bytes:
    frame = _put_mit_command(c)
    if is_special_command(frame):
        # Only P = 0xFFFF gives D0 = D1 = FF; one position code down is the smallest change that
        # leaves the special pattern (hollow.md §4.1 "clamp P to <= 0xFFFE").
        frame = _put_mit_command([0xFFFE, *c[1:]])
    return frame


def _put_mit_reply(c: Sequence[int]) -> bytes:
    motor_id, p, v, t = c
    return bytes([motor_id, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF])


def _get_mit_reply(b: bytes) -> list[int]:
    return [b[0], (b[1] << 8) | b[2], (b[3] << 4) | (b[4] >> 4), ((b[4] & 0xF) << 8) | b[5]]


def _put_hollow_ext_reply(c: Sequence[int]) -> bytes:
    motor_id, x, v, t = c
    xb = x.to_bytes(4, "big", signed=True)  # X31..X24, X23..X16, X15..X8, X7..X0
    return bytes([motor_id, xb[2], xb[3], v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF, xb[0], xb[1]])


def _get_hollow_ext_reply(b: bytes) -> list[int]:
    # hollow.md §5.3: X = int32((D6<<24) | (D7<<16) | (D1<<8) | D2)
    x = int.from_bytes(bytes([b[6], b[7], b[1], b[2]]), "big", signed=True)
    return [b[0], x, (b[3] << 4) | (b[4] >> 4), ((b[4] & 0xF) << 8) | b[5]]


def _fd_putter(byte14_signed: bool) -> Callable[[Sequence[int]], bytes]:
    def put(c: Sequence[int]) -> bytes:
        head = c[0].to_bytes(5, "big", signed=True) + c[1].to_bytes(4, "big", signed=True)
        head += c[2].to_bytes(2, "big", signed=True)
        tail = b"".join(
            code.to_bytes(1, "big", signed=(byte14_signed and k == 6)) for k, code in enumerate(c) if k >= 3
        )
        return head + tail

    return put


def _fd_getter(byte14_signed: bool) -> Callable[[bytes], list[int]]:
    def get(b: bytes) -> list[int]:
        codes = [
            int.from_bytes(b[0:5], "big", signed=True),
            int.from_bytes(b[5:9], "big", signed=True),
            int.from_bytes(b[9:11], "big", signed=True),
        ]
        codes += [
            int.from_bytes(b[k + 8 : k + 9], "big", signed=(byte14_signed and k == 6)) for k in range(3, 8)
        ]
        return codes

    return get


@dataclass(frozen=True)
class RefLayout:
    """A layout as the specs give it: size in bytes, field widths (negative = signed), byte placement."""

    name: str
    size: int
    bits: tuple[int, ...]
    put: Callable[[Sequence[int]], bytes]
    get: Callable[[bytes], list[int]]


LAYOUTS: dict[str, RefLayout] = {
    lay.name: lay
    for lay in (
        RefLayout("MIT_COMMAND", 8, (16, 12, 12, 12, 12), _put_mit_command, _get_mit_command),
        RefLayout("HOLLOW_SETPOINT", 8, (16, 12, 12, 12, 12), _put_hollow_setpoint, _get_mit_command),
        RefLayout("MIT_REPLY", 6, (8, 16, 12, 12), _put_mit_reply, _get_mit_reply),
        RefLayout("HOLLOW_EXT_REPLY", 8, (8, -32, 12, 12), _put_hollow_ext_reply, _get_hollow_ext_reply),
        RefLayout(
            "HOLLOW_FD_COMMAND", 16, (-40, -32, -16, 8, 8, 8, 8, 8), _fd_putter(False), _fd_getter(False)
        ),
        RefLayout("HOLLOW_FD_REPLY", 16, (-40, -32, -16, 8, 8, 8, -8, 8), _fd_putter(True), _fd_getter(True)),
    )
}


# ---- batch entry points ----


def pack(
    layout: str,
    scales: Sequence[Scale],
    rows: Sequence[Sequence[float]],
    *,
    stride: int | None = None,
    saturate: bool = False,
) -> bytes:
    """Pack rows (one value per field) into frames ``stride`` bytes apart, zero padded.

    Raises:
        PackError: for the first bad value in row-major order (frame, then field).
    """
    lay = LAYOUTS[layout]
    stride = lay.size if stride is None else stride
    if stride < lay.size or len(scales) != len(lay.bits):
        raise ValueError("bad stride or number of scales")
    out = bytearray()
    for i, row in enumerate(rows):
        if len(row) != len(lay.bits):
            raise ValueError(f"row {i} has {len(row)} values")
        codes = []
        for k, (scale, bits, x) in enumerate(zip(scales, lay.bits, row, strict=True)):
            try:
                codes.append(encode(scale, x, bits, saturate=saturate))
            except _FieldError as exc:
                raise PackError(i, k, float(x), exc.kind) from None
        frame = lay.put(codes)
        assert len(frame) == lay.size
        out += frame + bytes(stride - lay.size)
    return bytes(out)


def unpack_codes(layout: str, frame: bytes) -> list[int]:
    """The raw field codes of one frame."""
    return LAYOUTS[layout].get(bytes(frame))


def unpack(
    layout: str, scales: Sequence[Scale], data: bytes, *, stride: int | None = None
) -> list[tuple[float, ...]]:
    """Decode every whole ``stride``-byte slot of ``data`` (every bit pattern decodes)."""
    lay = LAYOUTS[layout]
    stride = lay.size if stride is None else stride
    data = bytes(data)
    rows = []
    for start in range(0, len(data) - stride + 1, stride):
        codes = lay.get(data[start : start + lay.size])
        rows.append(tuple(decode(scale, code) for scale, code in zip(scales, codes, strict=True)))
    return rows

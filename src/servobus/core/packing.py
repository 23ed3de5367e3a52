"""Float <-> integer field scaling and the bit layouts of MIT-style and hollow frames (C core).

A :class:`Layout` says where each field's bits go (fixed by the manuals); a :class:`FieldScale`
says how a physical value becomes a code (it changes with firmware revision and motor model, so
the family codecs supply it); a :class:`Packer` joins one layout with one scale per field and
packs or unpacks one frame or a whole batch per C call::

    p = Packer(MIT_COMMAND, [FieldScale.linear("position_rad", -12.5, 12.5, 16), ...])
    p.pack([10.0, 1.0, 10.0, 1.0, 10.0])        # one frame
    p.pack_many(rows)                          # a control tick over many motors, one C call

Scaling, exactly as the C core computes it (tests/reference holds the same in Python)::

    code = round_half_away_from_zero((x - origin) * codes / span)
    x    = code * span / codes + origin

A value outside [lo, hi] raises ValueError naming the field, the value and the limits, unless
``saturate=True`` is passed, which clamps it. NaN always raises. Arguments of the wrong type raise
TypeError, of the right type but unusable ValueError; the C core checks the same again (capacities,
field scales, layouts) and answers with a status, never undefined behaviour.
"""

from __future__ import annotations

import math
import numbers
import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, cast

from servobus.core._lib import Buffer, as_cbuffer, ffi, is_buffer, lib, raise_status, writable_cbuffer
from servobus.errors import ProtocolError

__all__ = [
    "HOLLOW_EXT_REPLY",
    "HOLLOW_FD_COMMAND",
    "HOLLOW_FD_REPLY",
    "HOLLOW_SETPOINT",
    "LAYOUTS",
    "MIT_COMMAND",
    "MIT_REPLY",
    "FieldScale",
    "Layout",
    "Packer",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class FieldScale:
    """How one field's physical value maps to its integer code.

    Attributes:
        name: the field's name with its unit (``position_rad``); errors quote it.
        lo, hi: the accepted physical range, inclusive.
        origin: the physical value of code 0.
        codes, span: ``span`` physical units are ``codes`` codes.

    Raises:
        TypeError: ``name`` is not a str, or a parameter is not a real number.
        ValueError: non-finite parameters, ``lo > hi``, or non-positive ``codes``/``span``.
    """

    name: str
    lo: float
    hi: float
    origin: float = 0.0
    codes: float = 1.0
    span: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise TypeError(f"FieldScale name must be a str, not {type(self.name).__name__}")
        for attr in ("lo", "hi", "origin", "codes", "span"):
            value = getattr(self, attr)
            if not isinstance(value, numbers.Real):
                kind = type(value).__name__
                raise TypeError(f"FieldScale {self.name!r}: {attr} must be a real number, not {kind}")
            try:
                finite = math.isfinite(value)
            except OverflowError:  # an int past the float range
                finite = False
            if not finite:
                raise ValueError(f"FieldScale {self.name!r}: {attr} must be finite")
        if self.lo > self.hi:
            raise ValueError(f"FieldScale {self.name!r}: lo={self.lo} exceeds hi={self.hi}")
        if self.codes <= 0 or self.span <= 0:
            raise ValueError(f"FieldScale {self.name!r}: codes and span must be positive")

    @classmethod
    def linear(cls, name: str, lo: float, hi: float, bits: int) -> FieldScale:
        """[lo, hi] onto [0, 2**bits - 1], both ends included: the MIT motion-mode mapping
        (myactuator-v4.md §5.4)."""
        return cls(name=name, lo=lo, hi=hi, origin=lo, codes=(1 << bits) - 1, span=hi - lo)

    @classmethod
    def offset_binary(cls, name: str, full_scale: float, bits: int) -> FieldScale:
        """Code 2**(bits-1) is zero and 2**bits codes span ±full_scale: the hollow normal-mode
        mapping (hollow.md §4.3). +full_scale is one code past the last and saturates there."""
        return cls(
            name=name, lo=-full_scale, hi=full_scale, origin=-full_scale, codes=1 << bits, span=2 * full_scale
        )

    @classmethod
    def integer(cls, name: str, lo: int, hi: int) -> FieldScale:
        """A raw integer field accepting lo..hi (gains, mode bytes, ids)."""
        return cls(name=name, lo=lo, hi=hi)

    @classmethod
    def twos_complement(cls, name: str, bits: int, *, codes: float = 1.0, span: float = 1.0) -> FieldScale:
        """A signed field of ``bits`` bits whose full code range is accepted; ``span`` units are
        ``codes`` codes (hollow CAN FD position, velocity and current)."""
        top = 1 << (bits - 1)
        return cls(name=name, lo=-top * span / codes, hi=(top - 1) * span / codes, codes=codes, span=span)

    def _code(self, x: float) -> float:
        return (x - self.origin) * self.codes / self.span

    def check_fits(self, bits: int, where: str) -> None:
        """Refuse a range that maps past a field of ``bits`` bits (negative: signed) of ``where``:
        it would silently saturate good values.

        Compared before rounding, with the slack that rounding and clamping absorb: half a code at
        the bottom, and one and a half at the top, where offset-binary fields put +full scale one
        code past the last (hollow.md §4.3). Anything further would clamp values the scale claims
        to carry.

        Raises:
            ValueError: the range does not fit (or overflows the codes).
        """
        width = abs(bits)
        cmin, cmax = (-(1 << (width - 1)), (1 << (width - 1)) - 1) if bits < 0 else (0, (1 << width) - 1)
        low, high = self._code(self.lo), self._code(self.hi)
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ValueError(f"{where}: {self.name} range [{self.lo}, {self.hi}] overflows its codes")
        if low < cmin - 0.5 or high > cmax + 1.5:
            raise ValueError(
                f"{where}: {self.name} range [{self.lo}, {self.hi}] maps to codes {low:g}..{high:g}, "
                f"beyond the {width}-bit field's {cmin}..{cmax}"
            )


@dataclass(frozen=True, slots=True)
class Layout:
    """Where each field's bits sit in a frame. ``bits`` are negative for signed fields."""

    name: str
    id: int
    size: int
    fields: tuple[str, ...]
    bits: tuple[int, ...]


def _layout(name: str, layout_id: int, fields: tuple[str, ...]) -> Layout:
    # Sizes and widths come from the C core, so Python cannot drift from what C packs.
    if lib.sb_layout_fields(layout_id) != len(fields):
        raise ImportError(f"servobus._core layout {name} has {lib.sb_layout_fields(layout_id)} fields")
    bits = tuple(lib.sb_layout_field_bits(layout_id, k) for k in range(len(fields)))
    return Layout(name, layout_id, lib.sb_layout_size(layout_id), fields, bits)


MIT_COMMAND = _layout("MIT_COMMAND", lib.SB_LAYOUT_MIT_COMMAND, ("p", "v", "kp", "kd", "t"))
HOLLOW_SETPOINT = _layout("HOLLOW_SETPOINT", lib.SB_LAYOUT_HOLLOW_SETPOINT, ("p", "v", "kp", "kd", "t"))
MIT_REPLY = _layout("MIT_REPLY", lib.SB_LAYOUT_MIT_REPLY, ("motor_id", "p", "v", "t"))
HOLLOW_EXT_REPLY = _layout("HOLLOW_EXT_REPLY", lib.SB_LAYOUT_HOLLOW_EXT_REPLY, ("motor_id", "x", "v", "t"))
HOLLOW_FD_COMMAND = _layout(
    "HOLLOW_FD_COMMAND",
    lib.SB_LAYOUT_HOLLOW_FD_COMMAND,
    ("position", "velocity", "current", "mode", "run", "kp", "kd", "zero"),
)
HOLLOW_FD_REPLY = _layout(
    "HOLLOW_FD_REPLY",
    lib.SB_LAYOUT_HOLLOW_FD_REPLY,
    ("position", "velocity", "current", "mode", "run", "reserved", "temperature", "slave_id"),
)
LAYOUTS = (MIT_COMMAND, HOLLOW_SETPOINT, MIT_REPLY, HOLLOW_EXT_REPLY, HOLLOW_FD_COMMAND, HOLLOW_FD_REPLY)


def _flags(saturate: bool) -> int:
    return lib.SB_PACK_SATURATE if saturate else 0


def _double_buffer(values: Buffer, what: str) -> Any:
    try:
        view = memoryview(values)
    except TypeError:
        raise TypeError(f"{what} must be a float64 buffer, not {type(values).__name__}") from None
    if view.format not in ("d", "<d", "=d") or not view.c_contiguous:
        raise TypeError(
            f"{what} must be a contiguous float64 buffer (array('d'), numpy float64), got {view.format!r}"
        )
    return ffi.from_buffer("double[]", values, require_writable=False)


def _new_doubles(values: Any, what: str) -> Any:
    """ffi.new("double[]", values) with servobus' exceptions: TypeError for a non-number, ValueError
    for an int too large for a float (cffi says OverflowError)."""
    try:
        return ffi.new("double[]", values)
    except TypeError as exc:
        raise TypeError(f"{what} must be real numbers: {exc}") from None
    except OverflowError:
        raise ValueError(f"{what} holds an int too large for a float") from None


# A frame slot is a few bytes (CAN FD carries 64); a stride past this is a mistake, not a frame.
_MAX_STRIDE = 1 << 16


class Packer:
    """One layout with one FieldScale per field: packs and unpacks single frames or batches.

    Not safe for concurrent use from several threads (it reuses scratch buffers); asyncio code
    on one loop is fine.

    Args:
        layout: one of the module's layouts.
        scales: one FieldScale per layout field, in the layout's field order.
        stride: bytes per frame slot (default: the layout size). Bytes past the layout are zero;
            MyActuator's motion reply, for example, is MIT_REPLY with stride 8.

    Raises:
        TypeError: layout is not a :class:`Layout`, a scale is not a :class:`FieldScale`, or
            stride is not an int.
        ValueError: a layout that is not one of :data:`LAYOUTS`, wrong number of scales, a scale
            whose range does not fit the field's bits, or a stride smaller than the layout (or
            past 64 KiB).
    """

    __slots__ = ("_err", "_fields", "_frame", "_nf", "_row", "layout", "scales", "stride")

    def __init__(self, layout: Layout, scales: Sequence[FieldScale], *, stride: int | None = None) -> None:
        if not isinstance(layout, Layout):
            raise TypeError(f"layout must be a servobus.core Layout, not {type(layout).__name__}")
        if layout not in LAYOUTS:  # the C core knows only these; a look-alike would lie about sizes
            raise ValueError(f"layout {layout.name!r} (id {layout.id}) is not one of servobus.core.LAYOUTS")
        scales = tuple(scales)
        for scale in scales:
            if not isinstance(scale, FieldScale):
                raise TypeError(f"scales must be FieldScale objects, not {type(scale).__name__}")
        if len(scales) != len(layout.fields):
            raise ValueError(f"{layout.name} has {len(layout.fields)} fields, got {len(scales)} scales")
        for scale, bits in zip(scales, layout.bits, strict=True):
            scale.check_fits(bits, layout.name)
        self.layout = layout
        self.scales = scales
        try:
            self.stride = layout.size if stride is None else operator.index(stride)
        except TypeError:
            raise TypeError(f"stride must be an int, not {type(stride).__name__}") from None
        if self.stride < layout.size:
            raise ValueError(f"stride {self.stride} is smaller than {layout.name}'s {layout.size} bytes")
        if self.stride > _MAX_STRIDE:
            raise ValueError(f"stride {self.stride} is past {_MAX_STRIDE} bytes; no frame is that long")
        self._nf = len(scales)
        self._fields = ffi.new("sb_field[]", [(s.lo, s.hi, s.origin, s.codes, s.span) for s in scales])
        self._row = ffi.new("double[]", self._nf)
        self._frame = ffi.new("uint8_t[]", self.stride)
        self._err = ffi.new("sb_pack_error *")

    def __repr__(self) -> str:
        return f"Packer({self.layout.name}, [{', '.join(s.name for s in self.scales)}], stride={self.stride})"

    # ---- packing ----

    def pack(self, values: Sequence[float], *, saturate: bool = False) -> bytes:
        """Pack one frame from one value per field (in layout order).

        Raises:
            ValueError: a value is NaN or outside its field's range (and saturate is False).
        """
        if len(values) != self._nf:
            raise ValueError(f"{self.layout.name} takes {self._nf} values, got {len(values)}")
        try:
            self._row[0 : self._nf] = values
        except TypeError as exc:
            raise TypeError(f"{self.layout.name} values must be real numbers: {exc}") from None
        except OverflowError:
            raise ValueError(f"{self.layout.name} values hold an int too large for a float") from None
        status = lib.sb_pack(
            self.layout.id,
            self._fields,
            self._row,
            1,
            self.stride,
            _flags(saturate),
            self._frame,
            self.stride,
            self._err,
        )
        if status:
            self._raise(status, batch=False)
        frame: bytes = ffi.buffer(self._frame)[:]
        return frame

    def pack_many(self, rows: Iterable[Sequence[float]] | Buffer, *, saturate: bool = False) -> bytes:
        """Pack a batch: rows of values, or a flat float64 buffer of n x fields values.

        Returns:
            n frames, each ``stride`` bytes, back to back.

        Raises:
            ValueError: as :meth:`pack`; the message names the frame index. Nothing is returned.
        """
        if is_buffer(rows):
            values = _double_buffer(cast(Buffer, rows), "rows")
        else:
            flat: list[float] = []
            for i, row in enumerate(cast(Iterable[Sequence[float]], rows)):
                if len(row) != self._nf:
                    raise ValueError(f"{self.layout.name} row {i} has {len(row)} values, needs {self._nf}")
                flat.extend(row)
            values = _new_doubles(flat, f"{self.layout.name} rows")
        n, extra = divmod(len(values), self._nf)
        if extra:
            raise ValueError(f"{len(values)} values is not a whole number of {self._nf}-field rows")
        out = ffi.new("uint8_t[]", n * self.stride)
        self._pack_raw(values, n, out, len(out), saturate)
        frames: bytes = ffi.buffer(out)[:]
        return frames

    def pack_into(self, values: Buffer, out: Buffer, *, saturate: bool = False) -> int:
        """Zero-allocation batch pack for control loops: float64 ``values`` (n x fields) into the
        writable buffer ``out`` (at least n x stride bytes). Returns n.

        Raises:
            ValueError: as :meth:`pack`, or ``out`` too small.
            TypeError: ``values`` is not a float64 buffer.
        """
        src = _double_buffer(values, "values")
        n, extra = divmod(len(src), self._nf)
        if extra:
            raise ValueError(f"{len(src)} values is not a whole number of {self._nf}-field rows")
        dst = writable_cbuffer("uint8_t[]", out, "out")
        if len(dst) < n * self.stride:
            raise ValueError(f"out holds {len(dst)} bytes, {n} frames need {n * self.stride}")
        self._pack_raw(src, n, dst, len(dst), saturate)
        return n

    def _pack_raw(self, values: Any, n: int, out: Any, out_cap: int, saturate: bool) -> None:
        status = lib.sb_pack(
            self.layout.id, self._fields, values, n, self.stride, _flags(saturate), out, out_cap, self._err
        )
        if status:
            self._raise(status, batch=True)

    def _raise(self, status: int, *, batch: bool) -> None:
        if status in (lib.SB_E_RANGE, lib.SB_E_NAN):
            scale = self.scales[self._err.field]
            where = f" (frame {self._err.frame})" if batch else ""
            if status == lib.SB_E_NAN:
                raise ValueError(f"{scale.name} is NaN{where}")
            raise ValueError(
                f"{scale.name}={self._err.value!r} is outside [{scale.lo!r}, {scale.hi!r}]{where}"
            )
        raise_status(status, self.layout.name)

    # ---- unpacking ----

    def unpack(self, frame: Buffer) -> tuple[float, ...]:
        """Decode one frame into one value per field (in layout order).

        Raises:
            ProtocolError: the frame is shorter than the layout.
        """
        buf = as_cbuffer(frame, "frame")
        if len(buf) < self.layout.size:
            raise ProtocolError(
                f"{self.layout.name} needs {self.layout.size} bytes, got {len(buf)}", raw=bytes(frame)
            )
        status = lib.sb_unpack(self.layout.id, self._fields, buf, 1, self.layout.size, self._row, self._nf)
        if status:
            raise_status(status, self.layout.name)
        return tuple(self._row[0 : self._nf])

    def unpack_many(self, frames: Buffer) -> list[tuple[float, ...]]:
        """Decode n frames laid out every ``stride`` bytes into n tuples.

        Raises:
            ProtocolError: the buffer is not a whole number of ``stride``-byte slots.
        """
        buf = as_cbuffer(frames, "frames")
        n = self._count_frames(buf, frames)
        out = ffi.new("double[]", n * self._nf)
        status = lib.sb_unpack(self.layout.id, self._fields, buf, n, self.stride, out, len(out))
        if status:
            raise_status(status, self.layout.name)
        flat = ffi.unpack(out, n * self._nf)
        k = self._nf
        return [tuple(flat[i : i + k]) for i in range(0, n * k, k)]

    def unpack_into(self, frames: Buffer, out: Buffer) -> int:
        """Zero-allocation batch decode into a writable float64 buffer of n x fields. Returns n.

        Raises:
            ProtocolError: ``frames`` is not a whole number of ``stride``-byte slots.
            ValueError: ``out`` too small.
        """
        buf = as_cbuffer(frames, "frames")
        n = self._count_frames(buf, frames)
        if not is_buffer(out) or memoryview(out).format not in ("d", "<d", "=d"):
            raise TypeError("out must be a writable float64 buffer")
        dst = writable_cbuffer("double[]", out, "out")
        if len(dst) < n * self._nf:
            raise ValueError(f"out holds {len(dst)} values, {n} frames need {n * self._nf}")
        status = lib.sb_unpack(self.layout.id, self._fields, buf, n, self.stride, dst, len(dst))
        if status:
            raise_status(status, self.layout.name)
        return n

    def _count_frames(self, buf: Any, frames: Buffer) -> int:
        n, extra = divmod(len(buf), self.stride)
        if extra:
            raise ProtocolError(
                f"{len(buf)} bytes is not a whole number of {self.stride}-byte {self.layout.name} frames",
                raw=bytes(frames)[:64],
            )
        return n

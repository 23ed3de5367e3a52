"""MyActuator hot-path decoders, derived from the classes' own layouts (private; see protocols/_fast.py).

:func:`compile_fixed` turns a :class:`~servobus.protocols.myactuator._layout.Fixed` class's ``FIELDS``
into one ``struct.Struct`` and a list of per-field conversions, so the fast decoder cannot drift from the
layout it was made from. Classes with fields it does not know (text, floats) or with checks of their own
(an overridden ``__post_init__``) get no fast decoder: the full one serves them.

:func:`motion_reply_decoder` does the MIT reply's 8/16/12/12-bit unpacking in Python with the C core's
formula (``code * span / codes + origin``, then the clamp MotionReply.decode applies): one frame in
Python costs less than one call into C.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from enum import IntEnum, IntFlag
from math import copysign, floor
from typing import Any

from servobus.protocols._fast import Slow, maker
from servobus.protocols._fields import IntField, ScaledField, _int_limits, round_half_away
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator._layout import (
    PAYLOAD_SIZE,
    BoolField,
    EnumField,
    Fixed,
    FlagsField,
    StepField,
)
from servobus.protocols.myactuator.motion import (
    MotionCommand,
    MotionReply,
    MotionScales,
    command_packer,
    reply_packer,
)

__all__ = ["compile_fixed", "compile_fixed_encoder", "motion_command_encoder", "motion_reply_decoder"]

_FORMATS = {(1, True): "b", (1, False): "B", (2, True): "h", (2, False): "H", (4, True): "i", (4, False): "I"}

Convert = Callable[[int], Any]


def _converter(spec: Any) -> tuple[str, Convert | None, tuple[float, float] | None] | None:
    """(struct code, conversion or None, range to check or None) for one field, or None if unknown."""
    kind = type(spec)
    if kind is SpecialZero:
        fmt = _FORMATS.get((spec.size, spec.signed))
        if fmt is None:
            return None
        from_code = spec.from_code
        limits = getattr(spec.inner, "limits", None)  # the plain field's own range still holds

        def special(code: int) -> Any:
            try:
                value = from_code(code)
            except ValueError:  # an undefined raw value: the full decoder reports it
                raise Slow from None
            if value is not None and limits is not None and not limits[0] <= value <= limits[1]:
                raise Slow
            return value

        return fmt, special, None
    if kind is IntField:
        fmt = _FORMATS.get((spec.size, spec.signed))
        full = _int_limits(spec.size, spec.signed)
        return (fmt, None, None if spec.limits == full else spec.limits) if fmt else None
    if kind is ScaledField:
        fmt = _FORMATS.get((spec.size, spec.signed))
        if fmt is None:
            return None
        cpu = spec.counts_per_unit
        lo, hi = _int_limits(spec.size, spec.signed)
        narrowed = spec.limits != (lo / cpu, hi / cpu)
        return fmt, (lambda code, cpu=cpu: code / cpu), spec.limits if narrowed else None
    if kind is EnumField:
        members: dict[int, IntEnum] = {int(m): m for m in spec.enum}
        return _FORMATS[(spec.size, False)], _lookup(members), None
    if kind is FlagsField:
        flags: type[IntFlag] = spec.flags
        return _FORMATS[(spec.size, False)], flags, None
    if kind is BoolField and spec.size == 1:
        return "B", _lookup({0: False, 1: True}), None
    if kind is StepField:
        fmt = _FORMATS.get((spec.size, False))
        step: int = spec.step
        return (fmt, (lambda code: code * step), None) if fmt else None
    return None


def _lookup(table: dict[int, Any]) -> Convert:
    get = table.get

    def convert(code: int) -> Any:
        value = get(code)
        if value is None:
            raise Slow
        return value

    return convert


def compile_fixed(cls: type[Fixed]) -> Callable[[bytes], Any] | None:
    """A fast decoder of ``cls``'s 8-byte payloads (raising :class:`Slow` when in doubt), or None.

    The caller dispatches on DATA[0] first; the decoder checks the length and the layout constants.
    """
    if cls.__post_init__ is not Fixed.__post_init__ or cls.decode.__func__ is not Fixed.decode.__func__:  # type: ignore[attr-defined]
        return None
    fmt = ["x"] * PAYLOAD_SIZE
    names: list[str] = []
    steps: list[tuple[Convert | None, tuple[float, float] | None]] = []
    for offset, spec in sorted(cls.FIELDS, key=lambda item: item[0]):
        found = _converter(spec)
        if found is None:
            return None
        code, convert, limits = found
        fmt[offset] = code
        for covered in range(offset + 1, offset + spec.size):
            fmt[covered] = ""
        names.append(spec.name)
        steps.append((convert, limits))
    unpack = struct.Struct("<" + "".join(fmt)).unpack
    constants = tuple(cls.CONSTANTS)
    try:
        make = maker(cls, tuple(names))
    except TypeError:
        return None
    plain = all(convert is None and limits is None for convert, limits in steps)

    def decode(data: bytes) -> Any:
        if len(data) != PAYLOAD_SIZE:
            raise Slow
        for offset, byte in constants:
            if data[offset] != byte:
                raise Slow
        raw = unpack(data)
        if plain:
            return make(*raw)
        values = []
        for value, (convert, limits) in zip(raw, steps, strict=True):
            if convert is not None:
                value = convert(value)
            if limits is not None and not limits[0] <= value <= limits[1]:
                raise Slow
            values.append(value)
        return make(*values)

    # The R2 status reply (5 fields, the hottest frame) gets a straight-line version.
    if [type(s) for _, s in cls.FIELDS] == [
        EnumField,
        IntField,
        ScaledField,
        ScaledField,
        ScaledField,
    ] and not (any(limits for _, limits in steps[1:])):
        # (the steps written out, as _converter makes them: no call per field)
        mode, _, iq, speed, angle = (spec for _, spec in sorted(cls.FIELDS, key=lambda item: item[0]))
        assert type(mode) is EnumField and type(iq) is type(speed) is type(angle) is ScaledField
        to_command = {int(m): m for m in mode.enum}.get
        iq_cpu, speed_cpu, angle_cpu = iq.counts_per_unit, speed.counts_per_unit, angle.counts_per_unit

        def decode_r2(data: bytes) -> Any:
            if len(data) != PAYLOAD_SIZE:
                raise Slow
            c, t, i, s, a = unpack(data)
            command = to_command(c)
            if command is None:
                raise Slow  # (an undefined raw value: the full decoder reports it)
            return make(command, t, i / iq_cpu, s / speed_cpu, a / angle_cpu)

        return decode_r2
    return decode


def motion_reply_decoder(scales: MotionScales, motor_id: int) -> Callable[[bytes], Any]:
    """A fast decoder of motor ``motor_id``'s 0x500+ID payloads (raising :class:`Slow` when in doubt)."""
    packer = reply_packer(scales)
    _, p, v, t = packer.scales
    make = maker(MotionReply, ("motor_id", "position_rad", "velocity_rad_s", "torque_nm", "scales"))
    p_span, p_codes, p_origin, p_lo, p_hi = p.span, p.codes, p.origin, p.lo, p.hi
    v_span, v_codes, v_origin, v_lo, v_hi = v.span, v.codes, v.origin, v.lo, v.hi
    t_span, t_codes, t_origin, t_lo, t_hi = t.span, t.codes, t.origin, t.lo, t.hi

    def decode(data: bytes) -> Any:
        if len(data) != PAYLOAD_SIZE or data[0] != motor_id:
            raise Slow
        pc = (data[1] << 8) | data[2]
        vc = (data[3] << 4) | (data[4] >> 4)
        tc = ((data[4] & 0x0F) << 8) | data[5]
        pos = pc * p_span / p_codes + p_origin
        vel = vc * v_span / v_codes + v_origin
        tor = tc * t_span / t_codes + t_origin
        return make(
            data[0],
            p_lo if pos < p_lo else p_hi if pos > p_hi else pos,
            v_lo if vel < v_lo else v_hi if vel > v_hi else vel,
            t_lo if tor < t_lo else t_hi if tor > t_hi else tor,
            scales,
        )

    return decode


def _encoder_step(spec: Any) -> tuple[str, Callable[[Any], int]] | None:
    """(struct code, value -> code) for one field of an already validated message, or None."""
    kind = type(spec)
    if kind is SpecialZero:
        inner = _encoder_step(spec.inner)
        if inner is None:
            return None
        code, convert = inner
        raw = spec.raw
        return code, lambda value: raw if value is None else convert(value)
    fmt = _FORMATS.get((spec.size, getattr(spec, "signed", False)))
    if fmt is None:
        return None
    if kind is IntField:
        return fmt, int
    if kind is ScaledField:
        cpu = spec.counts_per_unit
        return fmt, lambda value: round_half_away(value * cpu)
    if kind in (EnumField, FlagsField, BoolField):
        return fmt, int
    if kind is StepField:
        step = spec.step
        return fmt, lambda value: round_half_away(value / step)
    return None


def compile_fixed_encoder(cls: type[Fixed]) -> Callable[[Any], bytes] | None:
    """``message.encode()`` for ``cls`` by one ``struct.pack``, or None where Fixed.encode must serve.

    A message is validated when built and frozen after, so encoding does not check it again.
    """
    if cls.encode is not Fixed.encode or cls.CODE is None:
        return None
    fmt = ["x"] * PAYLOAD_SIZE
    fixed: dict[int, int] = {0: cls.CODE, **dict(cls.CONSTANTS)}
    for offset in fixed:
        fmt[offset] = "B"
    names: list[str] = []
    converts: list[Callable[[Any], int]] = []
    for offset, spec in cls.FIELDS:
        found = _encoder_step(spec)
        if found is None or offset in fixed:
            return None
        fmt[offset] = found[0]
        for covered in range(offset + 1, offset + spec.size):
            fmt[covered] = ""
        names.append(spec.name)
        converts.append(found[1])
    slots = sorted([*fixed, *(offset for offset, _ in cls.FIELDS)])
    by_offset = {offset: spec.name for offset, spec in cls.FIELDS}
    order = [fixed[o] if o in fixed else by_offset[o] for o in slots]
    pack = struct.Struct("<" + "".join(fmt)).pack
    if not names:
        payload = pack(*order)
        return lambda message: payload
    # A scaled or stepped field is rounded in the encoder's own code (round_half_away written out:
    # two calls less per field, on every command of a control loop); the others through their step.
    specs: dict[str, Any] = {spec.name: spec for _, spec in cls.FIELDS}
    namespace: dict[str, Any] = {"_pack": pack, **{f"_c{i}": c for i, c in enumerate(converts)}}
    namespace.update(_int=int, _abs=abs, _floor=floor, _copysign=copysign)
    lines: list[str] = []
    args: list[str] = []
    for item in order:
        if isinstance(item, int):
            args.append(repr(item))
            continue
        index = names.index(item)
        field = specs[item]
        if type(field) is ScaledField:
            namespace[f"_k{index}"] = field.counts_per_unit
            lines.append(f"    v{index} = m.{item} * _k{index}\n")
        elif type(field) is StepField:
            namespace[f"_k{index}"] = field.step
            lines.append(f"    v{index} = m.{item} / _k{index}\n")
        else:
            args.append(f"_c{index}(m.{item})")
            continue
        args.append(f"_int(_copysign(_floor(_abs(v{index}) + 0.5), v{index}))")
    exec(f"def encode(m):\n{''.join(lines)}    return _pack({', '.join(args)})\n", namespace)
    encode: Callable[[Any], bytes] = namespace["encode"]
    return encode


def motion_command_encoder(scales: MotionScales) -> Callable[[MotionCommand], bytes]:
    """MIT_COMMAND packing of a validated MotionCommand in Python, with the C core's arithmetic:
    ``round((x - origin) * codes / span)`` (x >= origin here, so round is floor + a half-step test),
    then the 16/12/12/12/12-bit big-endian placement."""
    fields = [(s.origin, s.codes, s.span) for s in command_packer(scales).scales]
    (po, pc, ps), (vo, vc, vs), (ko, kc, ks), (do, dc, ds), (to, tc, ts) = fields

    # Validated values lie in [lo, hi] with lo = origin and codes = 2**bits - 1, so y is in [0, codes]
    # and no clamp is needed; each field is written out because a call per field costs 0.15 µs.
    def encode(m: MotionCommand) -> bytes:
        y = (m.position_rad - po) * pc / ps
        p = floor(y)
        p += y - p >= 0.5
        y = (m.velocity_rad_s - vo) * vc / vs
        v = floor(y)
        v += y - v >= 0.5
        y = (m.kp - ko) * kc / ks
        kp = floor(y)
        kp += y - kp >= 0.5
        y = (m.kd - do) * dc / ds
        kd = floor(y)
        kd += y - kd >= 0.5
        y = (m.torque_ff_nm - to) * tc / ts
        t = floor(y)
        t += y - t >= 0.5
        return bytes(
            (
                p >> 8,
                p & 0xFF,
                v >> 4,
                ((v & 0xF) << 4) | (kp >> 8),
                kp & 0xFF,
                kd >> 4,
                ((kd & 0xF) << 4) | (t >> 8),
                t & 0xFF,
            )
        )

    return encode

"""The C field scaling and bit packing (csrc/bitpack.c) against tests/reference/packing.py.

Hypothesis draws the shape of each case (layout, stride, batch size, flags) and a seed; the scales and
values come from that seed through ``random_scale``/``random_value``, which aim at the edges on purpose.
Drawing every float through Hypothesis strategies costs about ten times as much per example, and the
edge cases are what matters here. A failing case prints its Packer, scales and rows (``note``).
"""

from __future__ import annotations

import math
import random
import struct
from array import array
from collections.abc import Sequence

import pytest
from hypothesis import given, note
from hypothesis import strategies as st

from reference import packing as ref
from reference.settings import oracle_settings
from servobus.core import (
    HOLLOW_EXT_REPLY,
    HOLLOW_FD_COMMAND,
    HOLLOW_FD_REPLY,
    HOLLOW_SETPOINT,
    LAYOUTS,
    MIT_COMMAND,
    MIT_REPLY,
    FieldScale,
    Layout,
    Packer,
)
from servobus.errors import ProtocolError

LAYOUT_IDS = [layout.name for layout in LAYOUTS]
INF = math.inf
NAN = math.nan

# Full scales and code counts that turn up in the manuals (hollow.md §4.3, §7.4; myactuator-v4.md §5.5).
TYPICAL_SPANS = [12.5, 12.566, 45.0, 500.0, 50.0, 5.0, 24.0, 200.0, 4.0, 360.0, 1.0, 0.001]
TYPICAL_CODES = [1.0, 8388.608, 1048576.0 / 360.0, 1000.0, 65535.0, 4095.0, 32768.0, 2048.0]


# ---- case generation ----


def _magnitude(rng: random.Random) -> float:
    """A positive float between 1e-3 and 1e6, log-uniform."""
    return 10 ** rng.uniform(-3, 6)


def _fits(scale: FieldScale, bits: int) -> bool:
    """Packer's own admission rule (FieldScale.check_fits): before rounding, lo and hi
    map no further than half a code below the field and one and a half above it (offset binary puts
    +full scale one code past the top). Used to pick scales, not tested."""
    cmin, cmax = ref.code_range(bits)
    return scale._code(scale.lo) >= cmin - 0.5 and scale._code(scale.hi) <= cmax + 1.5


def random_scale(rng: random.Random, bits: int, name: str) -> FieldScale:
    """A FieldScale that fits a field of ``bits`` (negative = signed): every constructor, and generic
    origin/codes/span combinations whose [lo, hi] maps into the field's codes."""
    cmin, cmax = ref.code_range(bits)
    width = abs(bits)
    kinds = (
        ["integer", "generic", "twos_complement"] if bits < 0 else ["integer", "generic", "linear", "offset"]
    )
    for _ in range(100):
        kind = rng.choice(kinds)
        if kind == "integer":
            first = rng.choice([cmin, rng.randint(cmin, cmax)])
            scale = FieldScale.integer(name, first, rng.choice([cmax, rng.randint(first, cmax)]))
        elif kind == "linear":
            bottom = rng.choice([-rng.choice(TYPICAL_SPANS), rng.uniform(-1e6, 1e6)])
            top = bottom + rng.choice([rng.choice(TYPICAL_SPANS), _magnitude(rng)])
            if not top > bottom:
                continue
            scale = FieldScale.linear(name, bottom, top, rng.choice([width, rng.randint(1, width)]))
        elif kind == "offset":
            full_scale = rng.choice([rng.choice(TYPICAL_SPANS), _magnitude(rng)])
            scale = FieldScale.offset_binary(name, full_scale, rng.choice([width, rng.randint(1, width)]))
        elif kind == "twos_complement":
            codes = rng.choice([rng.choice(TYPICAL_CODES), _magnitude(rng)])
            span = rng.choice([1.0, 360.0, 1000.0, _magnitude(rng)])
            scale = FieldScale.twos_complement(
                name, rng.choice([width, rng.randint(2, width)]), codes=codes, span=span
            )
        else:
            codes = rng.choice([rng.choice(TYPICAL_CODES), _magnitude(rng)])
            span = rng.choice([rng.choice(TYPICAL_SPANS), _magnitude(rng)])
            origin = rng.choice([0.0, rng.uniform(-1e6, 1e6), -rng.choice(TYPICAL_SPANS)])
            code_lo: float = rng.choice([cmin, cmin - 0.5, rng.uniform(cmin, cmax)])
            code_hi: float = rng.choice([cmax, cmax + 1, cmax + 0.5, rng.uniform(code_lo, cmax + 1)])
            lo, hi = origin + code_lo * span / codes, origin + code_hi * span / codes
            scale = FieldScale(name=name, lo=lo, hi=max(lo, hi), origin=origin, codes=codes, span=span)
        if _fits(scale, bits):
            return scale
    raise AssertionError("no fitting scale in 100 tries")  # pragma: no cover


def random_value(rng: random.Random, scale: FieldScale, bits: int, *, wild: bool) -> float:
    """One value for a field: on and just past the edges, inside, exact codes and their neighbours,
    rounding ties (exact for integer scales), the field's end codes. ``wild`` adds NaN, ±inf, values
    outside [lo, hi] and arbitrary doubles; otherwise the value lies in [lo, hi]."""
    lo, hi, origin = scale.lo, scale.hi, scale.origin
    step = scale.span / scale.codes
    cmin, cmax = ref.code_range(bits)
    pick = rng.randrange(9 if wild else 6)
    if pick == 0:
        x = rng.choice([lo, hi, math.nextafter(lo, INF), math.nextafter(hi, -INF), origin, 0.0, -0.0])
    elif pick == 1:
        x = rng.uniform(lo, hi)
    elif pick == 2:  # rounding ties: origin + (k + 1/2) step
        x = origin + (rng.randint(cmin - 2, cmax + 1) + 0.5) * step
    elif pick == 3:  # exact codes and their neighbours, weighted to the ends of the field
        k = rng.choice([cmin - 1, cmin, cmin + 1, cmax - 1, cmax, cmax + 1, rng.randint(cmin, cmax)])
        x = origin + k * step
        x = rng.choice([x, math.nextafter(x, -INF), math.nextafter(x, INF)])
    elif pick == 4:  # small values around the origin and zero
        x = rng.choice([origin, 0.0]) + rng.uniform(-4, 4) * step
    elif pick == 5:
        x = rng.uniform(lo - step, hi + step)
    elif pick == 6:
        x = rng.choice([NAN, -NAN, INF, -INF, 1e308, -1e308, 5e-324, math.nextafter(lo, -INF)])
    elif pick == 7:  # slightly outside
        x = rng.choice([lo - rng.random() * 3 * step, hi + rng.random() * 3 * step, math.nextafter(hi, INF)])
    else:  # any double, NaNs with payloads included
        x = struct.unpack("<d", rng.getrandbits(64).to_bytes(8, "little"))[0]
    if not wild and not lo <= x <= hi:
        x = rng.choice([lo, hi, rng.uniform(lo, hi)])
    return x


def random_rows(rng: random.Random, packer: Packer, n: int, mode: str) -> list[list[float]]:
    """n rows: all in range ("clean"), in range but for a rare bad value ("sparse"), or "wild"."""
    layout = packer.layout
    fields = list(zip(packer.scales, layout.bits, strict=True))
    bad_chance = {"clean": 0.0, "sparse": 1.0 / (2 * n * len(fields)), "wild": 1.0}[mode]
    return [
        [random_value(rng, s, bits, wild=rng.random() < bad_chance) for s, bits in fields] for _ in range(n)
    ]


def random_packer(rng: random.Random, layout: Layout, stride: int) -> Packer:
    """A Packer with fields named f0, f1, ... so that error messages identify the field."""
    return Packer(
        layout, [random_scale(rng, bits, f"f{k}") for k, bits in enumerate(layout.bits)], stride=stride
    )


def random_frames(rng: random.Random, size: int, n: int) -> bytes:
    """n frames of ``size`` bytes, rich in the bytes at the edges of signed and unsigned fields."""
    edges = [0x00, 0xFF, 0x80, 0x7F, 0x01, 0xFE, 0x0F, 0xF0, 0x08]
    return bytes(rng.choice([rng.getrandbits(8), rng.choice(edges)]) for _ in range(size * n))


# ---- checks ----


def _same_floats(a: Sequence[float], b: Sequence[float]) -> bool:
    """Bit-for-bit equality of two float sequences (tells 0.0 from -0.0)."""
    return len(a) == len(b) and struct.pack(f"<{len(a)}d", *a) == struct.pack(f"<{len(b)}d", *b)


def _expected_message(packer: Packer, err: ref.PackError, *, batch: bool) -> str:
    """What Packer raises for the oracle's error: it names the field, the value, the limits, the frame."""
    scale = packer.scales[err.field]
    where = f" (frame {err.frame})" if batch else ""
    if err.kind == "nan":
        return f"{scale.name} is NaN{where}"
    return f"{scale.name}={err.value!r} is outside [{scale.lo!r}, {scale.hi!r}]{where}"


def _reference_pack(packer: Packer, rows: Sequence[Sequence[float]], saturate: bool) -> bytes | ref.PackError:
    try:
        return ref.pack(packer.layout.name, packer.scales, rows, stride=packer.stride, saturate=saturate)
    except ref.PackError as err:
        return err


def _check_roundtrip(packer: Packer, row: Sequence[float], frame: bytes, saturate: bool) -> None:
    """unpack(pack(x)) is within half a code step of x, once x is clamped into [lo, hi] (saturate)
    and into what the field's codes represent (+full scale of an offset-binary field is one code past
    the top). A hollow setpoint stepped off a special command may be one more step away in p."""
    layout = packer.layout
    decoded = packer.unpack(frame)
    codes = ref.unpack_codes(layout.name, frame[: layout.size])
    for k, (scale, bits, x, got) in enumerate(zip(packer.scales, layout.bits, row, decoded, strict=True)):
        cmin, cmax = ref.code_range(bits)
        if saturate:
            x = min(max(x, scale.lo), scale.hi)
        x = min(max(x, ref.decode(scale, cmin)), ref.decode(scale, cmax))
        step = scale.span / scale.codes
        allowed = 0.5 * step
        if layout is HOLLOW_SETPOINT and k == 0 and codes[:4] == [0xFFFE, 0xFFF, 0xFFF, 0xFFF]:
            allowed += step if 0xFF9 <= codes[4] <= 0xFFE else 0.0
        slack = 1e-9 * step + 1e-12 * (abs(x) + abs(scale.origin) + abs(got))
        assert abs(got - x) <= allowed + slack, f"field {k}: {x!r} came back as {got!r} (step {step!r})"


# ---- layout metadata ----


@pytest.mark.parametrize("layout", LAYOUTS, ids=LAYOUT_IDS)
def test_layout_tables_match_specs(layout: Layout) -> None:
    """Sizes and field widths the C core reports are those of the specs' byte tables."""
    expected = ref.LAYOUTS[layout.name]
    assert (layout.size, layout.bits) == (expected.size, expected.bits)


# ---- golden frames from the specs ----

MIT_V43 = [  # myactuator-v4.md §5.5, [002] V4.3 ranges
    FieldScale.linear("position_rad", -12.5, 12.5, 16),
    FieldScale.linear("velocity_rad_s", -45.0, 45.0, 12),
    FieldScale.linear("kp", 0.0, 500.0, 12),
    FieldScale.linear("kd", 0.0, 5.0, 12),
    FieldScale.linear("torque_ff_nm", -24.0, 24.0, 12),
]
HOLLOW_H1 = [  # hollow.md §4.6: Pmax 1 turn = 360°, ω_fs 200 rad/s, I_fs 4 A
    FieldScale.offset_binary("p_deg", 360.0, 16),
    FieldScale.offset_binary("v_rad_s", 200.0, 12),
    FieldScale.integer("kp", 0, 4095),
    FieldScale.integer("kd", 0, 4095),
    FieldScale.offset_binary("i_a", 4.0, 12),
]
RAW_MIT = [FieldScale.integer(f"c{k}", 0, (1 << bits) - 1) for k, bits in enumerate(MIT_COMMAND.bits)]


def test_myactuator_mit_worked_example() -> None:
    """myactuator-v4.md §5.6: E6 66 82 E0 52 33 3B 55 decodes to the printed codes, and p = 10 rad
    (58981.5, a tie), kp = 10, kd = 1, t = 10 N·m re-encode to the same bytes (ties round up)."""
    frame = bytes.fromhex("E66682E052333B55")
    assert ref.unpack_codes("MIT_COMMAND", frame) == [0xE666, 0x82E, 0x052, 0x333, 0xB55]
    packer = Packer(MIT_COMMAND, MIT_V43)
    decoded = packer.unpack(frame)
    assert _same_floats(decoded, ref.unpack("MIT_COMMAND", MIT_V43, frame)[0])
    assert decoded[0] == pytest.approx(10.0002, abs=1e-4)
    values = [10.0, decoded[1], 10.0, 1.0, 10.0]  # v_des = 2094 is not the image of a round value
    assert packer.pack(values) == ref.pack("MIT_COMMAND", MIT_V43, [values]) == frame


def test_hollow_setpoint_worked_examples() -> None:
    """hollow.md §4.6 [H1] and §4.7 [H2] setpoints, in both the scaled and the raw-code form."""
    packer = Packer(HOLLOW_SETPOINT, HOLLOW_H1)
    assert packer.pack([180.0, 100.0, 0x100, 0x020, 2.0]) == bytes.fromhex("C000C00100020C00")
    raw = Packer(HOLLOW_SETPOINT, RAW_MIT)
    assert raw.pack([0x8000, 0x900, 0x800, 0x800, 0x900]) == bytes.fromhex("8000900800800900")
    assert ref.pack("HOLLOW_SETPOINT", RAW_MIT, [[0x8000, 0x900, 0x800, 0x800, 0x900]]) == raw.pack(
        [0x8000, 0x900, 0x800, 0x800, 0x900]
    )


def test_hollow_reply_examples() -> None:
    """hollow.md §4.5 and §5.3 illustrative replies, and the FD reply inside [H13] (pos 34, 30 °C, id 1)."""
    normal = Packer(MIT_REPLY, [FieldScale.integer("id", 0, 255), *HOLLOW_H1[:2], HOLLOW_H1[4]])
    assert normal.unpack(bytes.fromhex("01C000800800")) == (1.0, 180.0, 0.0, 0.0)
    raw_ext = Packer(
        HOLLOW_EXT_REPLY,
        [FieldScale.integer("id", 0, 255), FieldScale.twos_complement("x", 32)]
        + [FieldScale.integer(n, 0, 4095) for n in ("v", "t")],
    )
    assert raw_ext.unpack(bytes.fromhex("010000800800" + "0008")) == (1.0, 0x00080000, 0x800, 0x800)
    assert raw_ext.unpack(bytes.fromhex("01FFFF800800FFFF")) == (1.0, -1.0, 0x800, 0x800)
    assert raw_ext.pack([1, -1, 0x800, 0x800]) == bytes.fromhex("01FFFF800800FFFF")
    fd_scales = [FieldScale.twos_complement(n, -b) for n, b in zip("pvc", (-40, -32, -16), strict=True)]
    fd_reply = Packer(
        HOLLOW_FD_REPLY,
        fd_scales
        + [FieldScale.integer("m", 0, 255)] * 2
        + [
            FieldScale.integer("r", 0, 255),
            FieldScale.integer("temp", -128, 127),
            FieldScale.integer("id", 0, 255),
        ],
    )
    payload = bytes.fromhex("0000000022" + "00" * 9 + "1E01")
    assert fd_reply.unpack(payload) == (34.0, 0.0, 0.0, 0.0, 0.0, 0.0, 30.0, 1.0)
    assert fd_reply.unpack(payload[:14] + b"\xf6\x01")[6] == -10.0  # D14 is int8 in the reply ...
    fd_command = Packer(HOLLOW_FD_COMMAND, fd_scales + [FieldScale.integer("b", 0, 255)] * 5)
    assert fd_command.unpack(payload[:14] + b"\xf6\x01")[6] == 246.0  # ... and Kd, unsigned, in the request


def test_special_command_pattern_is_stepped_off() -> None:
    """P = 0xFFFF, V = KP = KD = 0xFFF, T = 0xFF9..0xFFE would be FF x7 + F9..FE, a special command
    (hollow.md §4.1): HOLLOW_SETPOINT sends P = 0xFFFE instead; MIT_COMMAND does not care."""
    hollow, mit = Packer(HOLLOW_SETPOINT, RAW_MIT), Packer(MIT_COMMAND, RAW_MIT)
    for t in range(0xFF8, 0x1000):
        row = [0xFFFF, 0xFFF, 0xFFF, 0xFFF, t]
        assert mit.pack(row) == b"\xff" * 6 + bytes([0xF0 | (t >> 8 & 0xF), t & 0xFF])
        stepped = 0xF9 <= (t & 0xFF) <= 0xFE
        assert hollow.pack(row) == (b"\xff\xfe" if stepped else b"\xff\xff") + mit.pack(row)[2:]
        assert hollow.pack(row) == ref.pack("HOLLOW_SETPOINT", RAW_MIT, [row])
        assert not ref.is_special_command(hollow.pack(row))


# ---- rounding and clamping, by hand ----


def test_ties_round_half_away_from_zero() -> None:
    """x.5 codes round away from zero in both directions (C round()), not to even (Python round())."""
    signed = Packer(
        HOLLOW_FD_COMMAND,
        [FieldScale.twos_complement(f"f{k}", -b) for k, b in enumerate((-40, -32, -16))]
        + [FieldScale.integer(f"b{k}", 0, 255) for k in range(5)],
    )
    ties = [(0.5, 1), (-0.5, -1), (1.5, 2), (2.5, 3), (-2.5, -3), (-3.5, -4), (0.49999999999999994, 0)]
    for x, code in ties:
        frame = signed.pack([x, 0, 0, 0, 0, 0, 0, 0])
        assert int.from_bytes(frame[:5], "big", signed=True) == code, x
        assert ref.round_half_away_from_zero(x) == code
    unsigned = Packer(MIT_REPLY, [FieldScale.integer("id", 0, 255), *RAW_MIT[:1], *RAW_MIT[1:3]])
    assert unsigned.pack([2.5, 4.5, 0.5, 254.5])[:3] == bytes([3, 0, 5])


def test_offset_binary_top_clamps_to_last_code() -> None:
    """+full scale of an offset-binary field is code 2**n, sent as 2**n - 1 (hollow.md §4.3)."""
    packer = Packer(HOLLOW_SETPOINT, HOLLOW_H1)
    assert packer.pack([360.0, 200.0, 4095, 4095, 4.0]) == bytes.fromhex("FFFFFFFFFFFFFFFF")
    assert packer.pack([-360.0, -200.0, 0, 0, -4.0]) == bytes(8)


def test_range_and_nan_errors() -> None:
    """Out of range raises (even by one ulp) unless saturating; NaN raises even when saturating."""
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(ValueError, match=r"^position_rad=12\.500000000000002 is outside \[-12\.5, 12\.5\]$"):
        packer.pack([math.nextafter(12.5, INF), 0, 0, 0, 0])
    assert packer.pack([INF, -INF, 1e9, -1.0, 0.0], saturate=True) == bytes.fromhex("FFFF000FFF000800")
    with pytest.raises(ValueError, match=r"^kd is NaN \(frame 1\)$"):
        packer.pack_many([[0, 0, 0, 0, 0], [0, 0, 0, NAN, NAN]], saturate=True)


def test_bad_arguments() -> None:
    """Wrong row lengths, short or ragged frames, small outputs and non-float64 buffers are refused."""
    packer = Packer(MIT_REPLY, [FieldScale.integer(f"f{k}", 0, 255) for k in range(4)], stride=8)
    with pytest.raises(ValueError):
        packer.pack([1, 2, 3])
    with pytest.raises(ValueError):
        packer.pack_many([[1, 2, 3, 4], [1, 2, 3]])
    with pytest.raises(ProtocolError):
        packer.unpack(bytes(5))
    assert packer.unpack(bytes(7)) == (0.0, 0.0, 0.0, 0.0)  # one frame: only the 6 layout bytes count
    with pytest.raises(ProtocolError):
        packer.unpack_many(bytes(12))  # stride 8: not a whole number of slots
    with pytest.raises(ValueError):
        packer.pack_into(array("d", [1, 2, 3, 4] * 2), bytearray(15))
    with pytest.raises(TypeError):
        packer.pack_into(array("f", [1, 2, 3, 4]), bytearray(8))
    with pytest.raises(ValueError):
        packer.unpack_into(bytes(16), array("d", [0.0] * 7))
    with pytest.raises(ValueError):
        Packer(MIT_REPLY, [FieldScale.integer(f"f{k}", 0, 257) for k in range(4)])  # 256 is admitted
    with pytest.raises(ValueError):
        Packer(MIT_REPLY, [FieldScale.integer(f"f{k}", 0, 255) for k in range(4)], stride=5)


# ---- against the oracle ----


@pytest.mark.parametrize("layout", LAYOUTS, ids=LAYOUT_IDS)
@oracle_settings
@given(
    seed=st.integers(0, 2**64 - 1),
    extra_stride=st.sampled_from([0, 0, 0, 1, 2, 8]),
    n=st.sampled_from([1, 1, 2, 3, 5, 8, 50]),
    mode=st.sampled_from(["clean", "sparse", "wild"]),
    saturate=st.booleans(),
    as_buffer=st.booleans(),
)
def test_pack_matches_reference(
    layout: Layout, seed: int, extra_stride: int, n: int, mode: str, saturate: bool, as_buffer: bool
) -> None:
    """pack, pack_many (rows or a float64 buffer) and pack_into give the oracle's bytes, zero padded to
    the stride and nothing past n * stride, or raise the ValueError for the oracle's first bad
    (frame, field, value); single frames round-trip within half a code step."""
    rng = random.Random(seed)
    packer = random_packer(rng, layout, layout.size + extra_stride)
    rows = random_rows(rng, packer, n, mode)
    note(f"{packer!r}\nscales={packer.scales!r}\nrows={rows!r}")
    expected = _reference_pack(packer, rows, saturate)
    stride = packer.stride

    for i, row in enumerate(rows[:3]):  # pack(): one frame, errors without a frame index
        single = _reference_pack(packer, [row], saturate)
        if isinstance(single, ref.PackError):
            with pytest.raises(ValueError) as info:
                packer.pack(row, saturate=saturate)
            assert str(info.value) == _expected_message(packer, single, batch=False)
        else:
            frame = packer.pack(row, saturate=saturate)
            assert frame == single
            if isinstance(expected, bytes):
                assert expected[i * stride : (i + 1) * stride] == frame
            _check_roundtrip(packer, row, frame, saturate)

    flat = array("d", [x for row in rows for x in row])
    out = bytearray(b"\xa5" * (n * stride + 7))
    batch: object = flat if as_buffer else rows
    if isinstance(expected, ref.PackError):
        message = _expected_message(packer, expected, batch=True)
        with pytest.raises(ValueError) as info:
            packer.pack_many(batch, saturate=saturate)  # type: ignore[arg-type]
        assert str(info.value) == message
        with pytest.raises(ValueError) as info:
            packer.pack_into(flat, out, saturate=saturate)
        assert str(info.value) == message
    else:
        assert packer.pack_many(batch, saturate=saturate) == expected  # type: ignore[arg-type]
        assert packer.pack_into(flat, out, saturate=saturate) == n
        assert out == expected + b"\xa5" * 7


@oracle_settings
@given(seed=st.integers(0, 2**64 - 1), extra_stride=st.sampled_from([0, 0, 0, 1, 2, 8]))
def test_unpack_matches_reference(seed: int, extra_stride: int) -> None:
    """For every layout (all six in each example), unpack, unpack_many and unpack_into decode any bytes
    exactly as the oracle does, bit for bit, ignoring the padding past the layout in each stride slot."""
    rng = random.Random(seed)
    for layout in LAYOUTS:
        packer = random_packer(rng, layout, layout.size + extra_stride)
        n = rng.choice([0, 1, 1, 2, 3, 5, 8, 50])
        data = random_frames(rng, packer.stride, n)
        note(f"{packer!r}\nscales={packer.scales!r}\ndata={data.hex()}")
        expected = ref.unpack(layout.name, packer.scales, data, stride=packer.stride)
        assert len(expected) == n

        many = packer.unpack_many(data)
        assert len(many) == n
        for got, want in zip(many, expected, strict=True):
            assert _same_floats(got, want)
            assert not any(map(math.isnan, got))  # every bit pattern decodes to a number
        for i in range(min(n, 2)):  # unpack(): one frame, from a memoryview at any offset
            assert _same_floats(packer.unpack(memoryview(data)[i * packer.stride :]), expected[i])
        width = len(layout.bits)
        out = array("d", [NAN] * (n * width + 3))
        assert packer.unpack_into(bytearray(data), out) == n
        assert _same_floats(out[: n * width], [x for row in expected for x in row])
        assert all(math.isnan(x) for x in out[n * width :])  # nothing written past n rows


@oracle_settings
@given(seed=st.integers(0, 2**64 - 1), saturate=st.booleans(), generic=st.booleans())
def test_hollow_setpoint_never_emits_a_special_command(seed: int, saturate: bool, generic: bool) -> None:
    """Values at and near the top of every field: HOLLOW_SETPOINT output is never FF x7 + F9..FE, it
    differs from MIT_COMMAND's only by P = FFFE where MIT_COMMAND's is such a frame, and matches the
    oracle."""
    rng = random.Random(seed)
    kinds = ["linear", "offset", "integer", "generic"] if generic else ["linear", "offset", "integer"]
    scales = []
    for k, bits in enumerate(HOLLOW_SETPOINT.bits):
        kind = rng.choice(kinds)
        if kind == "linear":
            lo = rng.uniform(-100, 0)
            scales.append(FieldScale.linear(f"f{k}", lo, lo + _magnitude(rng), bits))
        elif kind == "offset":
            scales.append(FieldScale.offset_binary(f"f{k}", _magnitude(rng), bits))
        elif kind == "integer":
            scales.append(FieldScale.integer(f"f{k}", 0, (1 << bits) - 1))
        else:
            scales.append(random_scale(rng, bits, f"f{k}"))
    hollow, mit = Packer(HOLLOW_SETPOINT, scales), Packer(MIT_COMMAND, scales)
    rows = []
    for _ in range(4):
        row = []
        for scale in scales:
            step = scale.span / scale.codes
            top = scale.hi + (rng.random() * step if saturate else 0.0)
            row.append(
                rng.choice(
                    [
                        top,
                        math.nextafter(top, -INF),
                        top - rng.randint(0, 8) * step,
                        top - rng.random() * step,
                    ]
                )
            )
        rows.append(
            [min(max(x, s.lo), s.hi) if not saturate else x for x, s in zip(row, scales, strict=True)]
        )
    note(f"scales={scales!r}\nrows={rows!r}")
    frames = hollow.pack_many(rows, saturate=saturate)
    assert frames == ref.pack("HOLLOW_SETPOINT", scales, rows, saturate=saturate)
    for i, row in enumerate(rows):
        frame, plain = frames[8 * i : 8 * i + 8], mit.pack(row, saturate=saturate)
        assert not ref.is_special_command(frame)
        assert frame == (b"\xff\xfe" + plain[2:] if ref.is_special_command(plain) else plain)


@pytest.mark.parametrize("layout", LAYOUTS, ids=LAYOUT_IDS)
def test_single_value_sweep_matches_reference(layout: Layout) -> None:
    """Deterministic sweep: every field of a typical scale over 2001 evenly spaced values across and past
    its range, with saturation, so every code region is hit whatever Hypothesis draws."""
    rng = random.Random(layout.id)
    packer = random_packer(rng, layout, layout.size)
    rows = []
    for t in range(-1000, 1001):
        row = []
        for scale in packer.scales:
            mid, half = (scale.lo + scale.hi) / 2, (scale.hi - scale.lo) / 2
            row.append(mid + half * t / 900)
        rows.append(row)
    assert packer.pack_many(rows, saturate=True) == ref.pack(layout.name, packer.scales, rows, saturate=True)

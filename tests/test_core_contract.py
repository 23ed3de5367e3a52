"""The C core's contract is enforced, not assumed (csrc/servobus_core.h).

Each precondition is exercised through the Python API (TypeError or ValueError, never BufferError,
OverflowError or a cffi error) and, where the wrapper would catch it first, through
``servobus._core.lib`` directly: the C function must answer with a status code, never undefined
behaviour. .ci/sanitize runs this file under ASan+UBSan.
"""

from __future__ import annotations

import math
import re
from array import array
from pathlib import Path
from typing import Any

import pytest

from _scales import MIT_V43
from servobus.core import (
    HOLLOW_FD_REPLY,
    LAYOUTS,
    MIT_COMMAND,
    MIT_REPLY,
    Deframer,
    FieldScale,
    HollowTransparentDeframer,
    Layout,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
    Packer,
    _lib,
    crc16_modbus,
    crc32_ieee,
)
from servobus.core._lib import ffi, lib

CSRC = Path(__file__).resolve().parents[1] / "csrc"
GOOD_FIELD = (-12.5, 12.5, -12.5, 65535.0, 25.0)  # lo, hi, origin, codes, span


def _fields(layout: Layout, bad: tuple[float, ...] | None = None, at: int = 0) -> Any:
    rows: list[tuple[float, ...]] = [GOOD_FIELD] * len(layout.fields)
    if bad is not None:
        rows[at] = bad
    return ffi.new("sb_field[]", rows)


def _raises_clean(call: Any, *args: Any, **kwargs: Any) -> Exception:
    """The call fails with TypeError or ValueError, and not with one of the types they hide."""
    with pytest.raises((TypeError, ValueError)) as info:
        call(*args, **kwargs)
    assert not isinstance(info.value, (BufferError, OverflowError, ffi.error)), repr(info.value)
    return info.value


# ---- 1. bad field scales ----

BAD_FIELDS = {
    "zero codes": (0.0, 1.0, 0.0, 0.0, 1.0),
    "zero span": (0.0, 1.0, 0.0, 1.0, 0.0),
    "negative codes": (0.0, 1.0, 0.0, -1.0, 1.0),
    "negative span": (0.0, 1.0, 0.0, 1.0, -1.0),
    "lo > hi": (2.0, 1.0, 0.0, 1.0, 1.0),
    "nan lo": (math.nan, 1.0, 0.0, 1.0, 1.0),
    "inf hi": (0.0, math.inf, 0.0, 1.0, 1.0),
    "inf origin": (0.0, 1.0, -math.inf, 1.0, 1.0),
    "nan codes": (0.0, 1.0, 0.0, math.nan, 1.0),
    "inf span": (0.0, 1.0, 0.0, 1.0, math.inf),
}


@pytest.mark.parametrize("bad", BAD_FIELDS.values(), ids=BAD_FIELDS.keys())
def test_c_refuses_a_bad_field(bad: tuple[float, ...]) -> None:
    """Zero codes/span would make NaN codes, and casting NaN to an integer is undefined behaviour."""
    values = ffi.new("double[]", [0.5] * 5)
    out = ffi.new("uint8_t[]", 8)
    for at in (0, 4):
        fields = _fields(MIT_COMMAND, bad, at)
        assert lib.sb_pack(MIT_COMMAND.id, fields, values, 1, 8, 0, out, 8, ffi.NULL) == lib.SB_E_ARG
        assert lib.sb_pack(MIT_COMMAND.id, fields, values, 1, 8, 1, out, 8, ffi.NULL) == lib.SB_E_ARG
        assert lib.sb_unpack(MIT_COMMAND.id, fields, out, 1, 8, values, 5) == lib.SB_E_ARG


@pytest.mark.parametrize("bad", BAD_FIELDS.values(), ids=BAD_FIELDS.keys())
def test_python_refuses_a_bad_field_first(bad: tuple[float, ...]) -> None:
    lo, hi, origin, codes, span = bad
    exc = _raises_clean(FieldScale, name="f", lo=lo, hi=hi, origin=origin, codes=codes, span=span)
    assert isinstance(exc, ValueError) and "'f'" in str(exc)


def test_bad_field_status_maps_to_value_error() -> None:
    with pytest.raises(ValueError, match=r"^MIT_COMMAND: bad argument"):
        _lib.raise_status(lib.SB_E_ARG, "MIT_COMMAND")


# ---- 1. NULL with a non-zero length ----


def test_crc_null_with_length_is_an_error_and_null_without_is_the_start_value() -> None:
    assert lib.sb_crc16_modbus(ffi.NULL, 5, 0xFFFF) == lib.SB_E_ARG
    assert lib.sb_crc32_ieee(ffi.NULL, 5, 0) == lib.SB_E_ARG
    assert lib.sb_crc16_modbus(ffi.NULL, 0, 0x1234) == 0x1234
    assert lib.sb_crc32_ieee(ffi.NULL, 0, 0xDEADBEEF) == 0xDEADBEEF
    # The wider return types carry every CRC value unchanged.
    assert lib.sb_crc32_ieee(b"123456789", 9, 0) == 0xCBF43926
    assert crc32_ieee(b"\xff" * 4) == 0xFFFFFFFF


def test_pack_and_unpack_refuse_null_pointers() -> None:
    fields, values = _fields(MIT_COMMAND), ffi.new("double[]", 5)
    out = ffi.new("uint8_t[]", 8)
    pack, unpack, null = lib.sb_pack, lib.sb_unpack, ffi.NULL
    assert pack(MIT_COMMAND.id, null, values, 1, 8, 0, out, 8, null) == lib.SB_E_ARG
    assert pack(MIT_COMMAND.id, fields, null, 1, 8, 0, out, 8, null) == lib.SB_E_ARG
    assert pack(MIT_COMMAND.id, fields, values, 1, 8, 0, null, 8, null) == lib.SB_E_ARG
    assert unpack(MIT_COMMAND.id, null, out, 1, 8, values, 5) == lib.SB_E_ARG
    assert unpack(MIT_COMMAND.id, fields, null, 1, 8, values, 5) == lib.SB_E_ARG
    assert unpack(MIT_COMMAND.id, fields, out, 1, 8, null, 5) == lib.SB_E_ARG
    # No frames: nothing is read or written, so NULL is fine.
    assert pack(MIT_COMMAND.id, null, null, 0, 8, 0, null, 0, null) == lib.SB_OK
    assert unpack(MIT_COMMAND.id, null, null, 0, 8, null, 0) == lib.SB_OK


def test_deframer_functions_refuse_null_pointers() -> None:
    state = ffi.new("sb_deframer *")
    assert lib.sb_deframer_init(state, lib.SB_DEFRAME_MYACTUATOR_RS485, 8) == lib.SB_OK
    out, lens, consumed = ffi.new("uint8_t[]", 64), ffi.new("uint16_t[]", 4), ffi.new("size_t *")
    feed, null = lib.sb_deframer_feed, ffi.NULL
    assert feed(state, null, 5, consumed, out, 64, lens, 4) == lib.SB_E_ARG
    assert consumed[0] == 0 and state.len == 0
    assert feed(state, b"\x3e", 1, null, out, 64, lens, 4) == lib.SB_E_ARG
    assert feed(state, b"\x3e", 1, consumed, null, 64, lens, 4) == lib.SB_E_ARG
    assert feed(state, b"\x3e", 1, consumed, out, 64, null, 4) == lib.SB_E_ARG
    assert feed(null, b"\x3e", 1, consumed, out, 64, lens, 4) == lib.SB_E_ARG
    assert feed(state, null, 0, consumed, out, 64, lens, 4) == 0  # an empty feed may pass NULL
    assert lib.sb_deframer_idle(state, null, 64, lens, 4) == lib.SB_E_ARG
    assert lib.sb_deframer_idle(state, out, 64, null, 4) == lib.SB_E_ARG
    assert lib.sb_deframer_idle(null, out, 64, lens, 4) == lib.SB_E_ARG
    assert lib.sb_deframer_init(null, lib.SB_DEFRAME_MYACTUATOR_RS485, 8) == lib.SB_E_ARG
    assert lib.sb_deframer_reset(null) == lib.SB_E_ARG
    assert lib.sb_deframer_max_frame(null) == 0


# ---- 1 and 2. output capacity ----


def test_pack_checks_its_output_capacity_and_writes_nothing_past_it() -> None:
    stride = 8
    fields = _fields(MIT_REPLY)
    values = ffi.new("double[]", [0.5] * 8)
    out = ffi.new("uint8_t[]", [0xAA] * 2 * stride)
    for cap in (0, 6, stride, 2 * stride - 1):  # two frames need the whole second slot
        assert lib.sb_pack(MIT_REPLY.id, fields, values, 2, stride, 0, out, cap, ffi.NULL) == lib.SB_E_ARG
        assert bytes(ffi.buffer(out)) == b"\xaa" * 2 * stride
    assert lib.sb_pack(MIT_REPLY.id, fields, values, 2, stride, 0, out, 2 * stride, ffi.NULL) == lib.SB_OK
    assert bytes(ffi.buffer(out))[6:8] == b"\x00\x00"
    # n * stride would wrap around: still refused, by division.
    huge = ffi.cast("size_t", -1)
    assert lib.sb_pack(MIT_REPLY.id, fields, values, huge, stride, 0, out, 16, ffi.NULL) == lib.SB_E_ARG
    # A stride below the layout size overlaps frames.
    assert lib.sb_pack(MIT_REPLY.id, fields, values, 1, 5, 0, out, 16, ffi.NULL) == lib.SB_E_ARG


def test_unpack_checks_its_output_capacity_in_values() -> None:
    fields = _fields(MIT_COMMAND)
    frames = ffi.new("uint8_t[]", 16)
    values = ffi.new("double[]", [7.0] * 10)
    for cap in (0, 5, 9):
        assert lib.sb_unpack(MIT_COMMAND.id, fields, frames, 2, 8, values, cap) == lib.SB_E_ARG
        assert list(values) == [7.0] * 10
    assert lib.sb_unpack(MIT_COMMAND.id, fields, frames, 2, 8, values, 10) == lib.SB_OK
    huge = ffi.cast("size_t", -1)
    assert lib.sb_unpack(MIT_COMMAND.id, fields, frames, huge, 8, values, 10) == lib.SB_E_ARG
    assert lib.sb_unpack(MIT_COMMAND.id, fields, frames, 1, 7, values, 10) == lib.SB_E_ARG


def test_python_checks_output_capacity_first() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    with pytest.raises(ValueError, match="out holds 15 bytes, 2 frames need 16"):
        packer.pack_into(array("d", [0.0] * 10), bytearray(15))
    with pytest.raises(ValueError, match="out holds 9 values, 2 frames need 10"):
        packer.unpack_into(bytes(16), array("d", [0.0] * 9))


def test_pack_refuses_unknown_flags() -> None:
    fields, values, out = _fields(MIT_COMMAND), ffi.new("double[]", 5), ffi.new("uint8_t[]", 8)
    for flags in (2, -1, lib.SB_PACK_SATURATE | 4):
        assert lib.sb_pack(MIT_COMMAND.id, fields, values, 1, 8, flags, out, 8, ffi.NULL) == lib.SB_E_ARG


def test_range_error_without_an_error_record() -> None:
    """err may be NULL: the status alone comes back."""
    fields, out = _fields(MIT_COMMAND), ffi.new("uint8_t[]", 8)
    values = ffi.new("double[]", [99.0, 0, 0, 0, 0])
    assert lib.sb_pack(MIT_COMMAND.id, fields, values, 1, 8, 0, out, 8, ffi.NULL) == lib.SB_E_RANGE


# ---- 3. unknown layouts and kinds fail loudly ----


@pytest.mark.parametrize("layout", [0, -1, lib.SB_LAYOUT_COUNT + 1, 99, 1 << 30])
def test_unknown_layout_is_sb_e_layout(layout: int) -> None:
    fields, values = _fields(HOLLOW_FD_REPLY), ffi.new("double[]", 8)
    out = ffi.new("uint8_t[]", 16)
    assert lib.sb_pack(layout, fields, values, 1, 16, 0, out, 16, ffi.NULL) == lib.SB_E_LAYOUT
    assert lib.sb_unpack(layout, fields, out, 1, 16, values, 8) == lib.SB_E_LAYOUT
    assert (lib.sb_layout_size(layout), lib.sb_layout_fields(layout)) == (0, 0)
    assert lib.sb_layout_field_bits(layout, 0) == 0


def test_unknown_layout_through_python() -> None:
    fake = Layout("FAKE", 99, 8, MIT_COMMAND.fields, MIT_COMMAND.bits)
    with pytest.raises(ValueError, match=r"layout 'FAKE' \(id 99\) is not one of"):
        Packer(fake, MIT_V43)
    # Past the Python check (a layout swapped after construction), C still refuses it.
    packer = Packer(MIT_COMMAND, MIT_V43)
    packer.layout = fake
    with pytest.raises(ValueError, match=r"^FAKE: unknown layout"):
        packer.pack([0.0] * 5)
    with pytest.raises(ValueError, match=r"^FAKE: unknown layout"):
        packer.unpack(bytes(8))


@pytest.mark.parametrize("kind", [0, -1, 4, 99])
def test_unknown_deframer_kind_is_sb_e_layout(kind: int) -> None:
    state = ffi.new("sb_deframer *")
    assert lib.sb_deframer_init(state, kind, 0) == lib.SB_E_LAYOUT
    # A failed init leaves a state every function refuses.
    out, lens, consumed = ffi.new("uint8_t[]", 512), ffi.new("uint16_t[]", 4), ffi.new("size_t *")
    assert lib.sb_deframer_feed(state, b"\x3e\x01", 2, consumed, out, 512, lens, 4) == lib.SB_E_LAYOUT
    assert consumed[0] == 0 and state.len == 0
    assert lib.sb_deframer_idle(state, out, 512, lens, 4) == lib.SB_E_LAYOUT
    assert lib.sb_deframer_reset(state) == lib.SB_E_LAYOUT
    assert lib.sb_deframer_max_frame(state) == 0


def test_deframer_state_written_from_outside_is_refused() -> None:
    """The state is caller memory: a bad kind, option or length is answered with a status."""
    deframer = MyActuatorRs485Deframer()
    state = deframer._state
    for field, value, status in (
        ("kind", 99, lib.SB_E_LAYOUT),
        ("option", 0, lib.SB_E_ARG),
        ("len", lib.SB_DEFRAME_CAPACITY + 1, lib.SB_E_ARG),
    ):
        saved = getattr(state, field)
        setattr(state, field, value)
        assert lib.sb_deframer_reset(state) == status
        assert lib.sb_deframer_max_frame(state) == 0
        with pytest.raises(ValueError, match=r"^MyActuatorRs485Deframer: "):
            deframer.feed(b"\x3e\x01\x08")
        with pytest.raises(ValueError, match=r"^MyActuatorRs485Deframer: "):
            deframer.idle()
        with pytest.raises(ValueError, match=r"^MyActuatorRs485Deframer: "):
            deframer.feed_into(b"\x3e", bytearray(64), array("H", [0]))
        with pytest.raises(ValueError, match=r"^MyActuatorRs485Deframer: "):
            deframer.clear()
        setattr(state, field, saved)
    assert deframer.feed(b"") == [] and deframer.pending == 0


def test_deframer_init_options_are_checked_in_c() -> None:
    state = ffi.new("sb_deframer *")
    for kind, option in (
        (lib.SB_DEFRAME_MYACTUATOR_RS485, 0),
        (lib.SB_DEFRAME_MYACTUATOR_RS485, 256),
        (lib.SB_DEFRAME_HOLLOW_TRANSPARENT, 1),
        (lib.SB_DEFRAME_MODBUS_RTU, 0),
        (lib.SB_DEFRAME_MODBUS_RTU, 4),
    ):
        assert lib.sb_deframer_init(state, kind, option) == lib.SB_E_ARG


def test_deframer_output_that_cannot_progress_is_refused_in_c() -> None:
    state = ffi.new("sb_deframer *")
    assert lib.sb_deframer_init(state, lib.SB_DEFRAME_MYACTUATOR_RS485, 8) == lib.SB_OK
    out, lens, consumed = ffi.new("uint8_t[]", 13), ffi.new("uint16_t[]", 1), ffi.new("size_t *")
    assert lib.sb_deframer_feed(state, b"\x3e", 1, consumed, out, 12, lens, 1) == lib.SB_E_ARG
    assert lib.sb_deframer_feed(state, b"\x3e", 1, consumed, out, 13, lens, 0) == lib.SB_E_ARG
    assert lib.sb_deframer_idle(state, out, 12, lens, 1) == lib.SB_E_ARG
    assert state.len == 0
    assert lib.sb_deframer_feed(state, b"\x3e", 1, consumed, out, 13, lens, 1) == 0 and consumed[0] == 1


def test_no_catch_all_default_in_csrc() -> None:
    """Every switch lists its cases and returns the error after it (a received Modbus function byte
    is tested against the four that can start a frame before its switch)."""
    defaults = [
        (path.name, number)
        for path in sorted(CSRC.glob("*.c"))
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if re.search(r"\bdefault\s*:", line)
    ]
    assert defaults == []


# ---- 4. ABI ----


def test_core_abi_is_checked_at_import() -> None:
    assert lib.sb_core_abi() == lib.SB_CORE_ABI == _lib.CORE_ABI
    _lib.check_abi(_lib.CORE_ABI)
    for other in (_lib.CORE_ABI - 1, _lib.CORE_ABI + 1):
        with pytest.raises(ImportError, match=r"needs ABI .*reinstall servobus"):
            _lib.check_abi(other)


# ---- 5. clear goes through C ----


def test_clear_resets_through_c() -> None:
    deframer = MyActuatorRs485Deframer()
    assert deframer.feed(b"\x00\x3e\x01\x08\x9c") == []
    assert (deframer.discarded_bytes, deframer.pending) == (1, 4)
    deframer.clear()
    assert (deframer.discarded_bytes, deframer.pending) == (5, 0)
    assert lib.sb_deframer_reset(deframer._state) == lib.SB_OK
    assert deframer.discarded_bytes == 5


# ---- 6. wrong argument types: TypeError or ValueError, nothing else ----

STRIDED = memoryview(bytes(32))[::2]


@pytest.mark.parametrize("crc", [crc16_modbus, crc32_ieee])
def test_crc_argument_types(crc: Any) -> None:
    for data in ("str", 123, None, [1, 2], STRIDED):
        assert isinstance(_raises_clean(crc, data), TypeError)
    for start in (-1, 1 << 40, 1 << 64):
        assert isinstance(_raises_clean(crc, b"x", start), ValueError)
    for wrong in (1.5, "1", None):
        assert isinstance(_raises_clean(crc, b"x", wrong), TypeError)
    assert isinstance(_raises_clean(crc16_modbus, b"x", 0x10000), ValueError)
    assert isinstance(_raises_clean(crc32_ieee, b"x", 1 << 32), ValueError)
    assert crc(memoryview(b"abc")) == crc(b"abc")


def test_field_scale_argument_types() -> None:
    assert isinstance(_raises_clean(FieldScale, name=1, lo=0, hi=1), TypeError)
    assert isinstance(_raises_clean(FieldScale, name="f", lo="0", hi=1), TypeError)
    assert isinstance(_raises_clean(FieldScale, name="f", lo=None, hi=1), TypeError)
    assert isinstance(_raises_clean(FieldScale, name="f", lo=0, hi=10**400), ValueError)
    assert isinstance(_raises_clean(FieldScale.linear, "f", 0, 1, 2000), ValueError)
    assert isinstance(_raises_clean(FieldScale.linear, "f", 0, 1, -1), ValueError)
    assert isinstance(_raises_clean(FieldScale.linear, "f", 0, 1, "16"), TypeError)
    assert isinstance(_raises_clean(FieldScale.twos_complement, "f", 0), ValueError)


def test_packer_construction_argument_types() -> None:
    assert isinstance(_raises_clean(Packer, "MIT_COMMAND", MIT_V43), TypeError)
    assert isinstance(_raises_clean(Packer, MIT_COMMAND, [1.0] * 5), TypeError)
    assert isinstance(_raises_clean(Packer, MIT_COMMAND, 5), TypeError)
    for stride in ("8", 8.0):
        assert isinstance(_raises_clean(Packer, MIT_COMMAND, MIT_V43, stride=stride), TypeError)
    assert isinstance(_raises_clean(Packer, MIT_COMMAND, MIT_V43, stride=1 << 40), ValueError)


def test_packer_call_argument_types() -> None:
    packer = Packer(MIT_COMMAND, MIT_V43)
    doubles = array("d", [0.0] * 10)
    cases: list[tuple[Any, tuple[Any, ...], type[Exception]]] = [
        (packer.pack, (5,), TypeError),
        (packer.pack, (["a"] * 5,), TypeError),
        (packer.pack, ([None] * 5,), TypeError),
        (packer.pack, ([10**400, 0, 0, 0, 0],), ValueError),
        (packer.pack_many, (123,), TypeError),
        (packer.pack_many, ([["a"] * 5],), TypeError),
        (packer.pack_many, ([[10**400, 0, 0, 0, 0]],), ValueError),
        (packer.pack_many, (memoryview(doubles)[::2],), TypeError),
        (packer.pack_many, (array("f", [0.0] * 5),), TypeError),
        (packer.pack_into, ("values", bytearray(16)), TypeError),
        (packer.pack_into, (doubles, "out"), TypeError),
        (packer.pack_into, (doubles, memoryview(bytearray(32))[::2]), TypeError),
        (packer.unpack, ("12345678",), TypeError),
        (packer.unpack, (12345678,), TypeError),
        (packer.unpack, (STRIDED,), TypeError),
        (packer.unpack_many, ("1234567812345678",), TypeError),
        (packer.unpack_many, (None,), TypeError),
        (packer.unpack_many, (STRIDED,), TypeError),
        (packer.unpack_into, (bytes(8), "out"), TypeError),
        (packer.unpack_into, (bytes(8), memoryview(doubles)[::2]), TypeError),
        (packer.unpack_into, (STRIDED, doubles), TypeError),
    ]
    for call, args, expected in cases:
        assert isinstance(_raises_clean(call, *args), expected), (call.__name__, args)


@pytest.mark.parametrize("make", [MyActuatorRs485Deframer, HollowTransparentDeframer, ModbusRtuDeframer])
def test_deframer_argument_types(make: Any) -> None:
    deframer = make()
    out, lens = bytearray(512), array("H", [0] * 4)
    strided_lens = memoryview(array("H", [0] * 8))[::2]
    cases: list[tuple[Any, tuple[Any, ...]]] = [
        (deframer.feed, (123,)),
        (deframer.feed, ("str",)),
        (deframer.feed, (None,)),
        (deframer.feed, (STRIDED,)),
        (deframer.feed_into, (123, out, lens)),
        (deframer.feed_into, (STRIDED, out, lens)),
        (deframer.feed_into, (b"", "out", lens)),
        (deframer.feed_into, (b"", bytes(512), lens)),
        (deframer.feed_into, (b"", memoryview(out)[::2], lens)),
        (deframer.feed_into, (b"", out, 5)),
        (deframer.feed_into, (b"", out, strided_lens)),
        (deframer.feed_into, (b"", out, array("h", [0] * 4))),
    ]
    for call, args in cases:
        assert isinstance(_raises_clean(call, *args), TypeError), (call.__name__, args)
    assert deframer.idle() == [] and deframer.feed(b"") == []


def test_deframer_construction_argument_types() -> None:
    assert isinstance(_raises_clean(MyActuatorRs485Deframer, 8.5), TypeError)
    assert isinstance(_raises_clean(MyActuatorRs485Deframer, "8"), TypeError)
    assert isinstance(_raises_clean(MyActuatorRs485Deframer, 1 << 40), ValueError)
    assert isinstance(_raises_clean(ModbusRtuDeframer, []), TypeError)
    assert isinstance(_raises_clean(Deframer, 1), TypeError)


# ---- 7. feed() after a feed_into() that filled its output ----


def _rs485(motor: int, data: bytes) -> bytes:
    body = bytes([0x3E, motor & 0xFF, len(data)]) + data
    return body + crc16_modbus(body).to_bytes(2, "little")


def test_feed_after_a_full_feed_into_returns_the_pending_frames() -> None:
    frames = [_rs485(i, bytes([i & 0xFF])) for i in range(200)]
    stream = b"".join(frames)
    deframer = MyActuatorRs485Deframer()
    n, consumed = deframer.feed_into(stream, bytearray(13), array("H", [0]))
    assert n == 1 and consumed == lib.SB_DEFRAME_CAPACITY and deframer.pending > 6
    # Everything feed_into left buffered, then what the new bytes complete, in order.
    assert frames[:1] + deframer.feed(stream[consumed:]) == frames
    assert deframer.pending == 0 and deframer.frames == 200


def test_feed_after_a_full_feed_into_with_a_slice_that_fills_feeds_scratch() -> None:
    """The buffered frames plus a nearly full slice of small frames, on a de-framer whose maximum
    frame is large: feed must still return every complete frame in one call (it used to stop one
    maximum frame short and keep the rest buffered until the next feed)."""
    frames = [_rs485(i, bytes([i & 0xFF])) for i in range(12000)]
    stream = b"".join(frames)
    deframer = MyActuatorRs485Deframer(max_data_len=255)
    n, consumed = deframer.feed_into(stream, bytearray(260), array("H", [0]))
    assert (n, consumed) == (1, lib.SB_DEFRAME_CAPACITY)
    end = 6 * 11093  # whole 6-byte frames; the slice after the first 1024 bytes is 65534 bytes
    assert end - consumed <= 1 << 16 < end - 6
    got = frames[:1] + deframer.feed(stream[consumed:end])
    assert got == frames[: end // 6] and deframer.pending == 0
    assert deframer.feed(b"") == []


def test_feed_of_nothing_after_a_full_feed_into_drains_everything() -> None:
    frames = [_rs485(i, bytes(8)) for i in range(100)]
    deframer = MyActuatorRs485Deframer()
    n, consumed = deframer.feed_into(b"".join(frames), bytearray(13), array("H", [0]))
    assert n == 1
    whole, partial = divmod(consumed, 13)
    assert frames[:1] + deframer.feed(b"") == frames[:whole] and deframer.pending == partial


# ---- 8. one thread per de-framer ----


def test_deframer_says_it_belongs_to_one_thread() -> None:
    doc = " ".join((Deframer.__doc__ or "").split()).lower()
    assert "not thread-safe" in doc and "one thread" in doc


def test_every_layout_round_trips_through_the_checked_entry_points() -> None:
    """The capacity-taking signatures still pack and unpack every layout."""
    for layout in LAYOUTS:
        fields = ffi.new("sb_field[]", [(0.0, 1.0, 0.0, 1.0, 1.0)] * len(layout.fields))
        values = ffi.new("double[]", [1.0] * len(layout.fields))
        out = ffi.new("uint8_t[]", layout.size)
        assert lib.sb_pack(layout.id, fields, values, 1, layout.size, 0, out, layout.size, ffi.NULL) == 0
        back = ffi.new("double[]", len(layout.fields))
        assert lib.sb_unpack(layout.id, fields, out, 1, layout.size, back, len(layout.fields)) == 0
        assert list(back) == [1.0] * len(layout.fields), layout.name

"""servobus.dbc: the generated DBC loads in cantools and decodes every frame it describes to the values
servobus decodes, for MyActuator (standard and motion frames), LK (V2.36, V2.35, every motor type) and
hollow (normal, extended and CAN FD frames, the extended-id frames), and every layout of a family is in
the DBC or named as left out.

Frames come three ways:

* **encoder-built**: every message class's hypothesis strategy (``tests/protocols/<family>/_strategies.py``,
  ranges written from the specs) draws valid values, the family encoder packs them; a bounded number of
  examples per class, as each example decodes through cantools and servobus;
* **raw**: for every layout the DBC holds (each path of multiplexer values), random payload bytes with
  the multiplexer values, constants and a random in-range raw code of every signal written in; servobus
  decodes them where it accepts them, and its encoder packs them again, so bytes the DBC does not
  describe are random in the one frame and canonical in the other;
* the spec vectors (``/work/shared/spec/vectors``).

Each frame is decoded by cantools from the DBC text and by servobus, and ``_dbc_check.check_frame``
compares every field: raw codes exactly, scaled values within 1e-9 relative (its docstring says why that
tolerance and why the raw comparison is the one that pins every bit).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import random
import re
import struct
from collections.abc import Callable, Iterator
from typing import Any

import cantools
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _dbc_check import check_frame
from _spec import SPEC_DIR
from protocols.hollow import _strategies as hs
from protocols.lk import _strategies as ls
from protocols.myactuator import _strategies as ms
from servobus.errors import ProtocolError
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols.dbc import MUX, Layout, MessageSpec, SignalSpec, dbc_name
from servobus.protocols.hollow import CanMode
from servobus.protocols.lk.codec import REPLY_CLASSES, REQUESTS
from servobus.protocols.myactuator import codec as ma_codec
from servobus.tools.dbc import Placed, Plan, build_database, database, dbc_text, plan, signal_table

#: Encoder-built examples per class (each decodes through cantools and servobus, per revision).
EXAMPLES = 40
#: Raw frames per layout and background (random bytes, zeros).
RAW_FRAMES = 10

# ---- DBCs, built once ---------------------------------------------------------------------------


@functools.cache
def dbc(family: str, revision: str | None = None, **options: Any) -> tuple[Plan, Any]:
    """The plan for motors 1 and 7 and its DBC as cantools loads it back from the text."""
    p = plan(family, (1, 7), revision, **options)
    return p, cantools.database.load_string(dbc_text(database(p)), "dbc")


def message_at(p: Plan, frame_id: int, *, extended: bool = False) -> MessageSpec:
    return next(m for m in p.messages if m.frame_id == frame_id and m.extended == extended)


def is_left_out(p: Plan, kind: str, code: int) -> bool:
    return any(reason.startswith(f"{kind} 0x{code:02X} ") for reason in p.left_out)


# ---- servobus' side -----------------------------------------------------------------------------

Decoder = Callable[[MessageSpec, bytes], Any]


def ma_decoder(revision: str, max_torque_nm: float | None = None) -> Decoder:
    rev = ma.Revision[revision]
    scales = ma.MotionScales.for_revision(rev, max_torque_nm=max_torque_nm)

    def decode(spec: MessageSpec, data: bytes) -> Any:
        if spec.kind == "request":
            return ma.decode_request(spec.frame_id, data, revision=rev, motion_scales=scales)
        return ma.decode_reply(spec.frame_id, data, revision=rev, motion_scales=scales)

    return decode


def lk_decoder(model: lk.LkModel) -> Decoder:
    def decode(spec: MessageSpec, data: bytes) -> Any:
        if spec.kind == "request":
            return lk.decode_request(spec.frame_id, data, model=model)
        return lk.decode_reply(spec.frame_id, data, model=model)

    return decode


def ho_decoder(model: ho.HollowModel, can_mode: str) -> Decoder:
    def decode(spec: MessageSpec, data: bytes) -> Any:
        if spec.kind == "request":
            mode = CanMode.EXTENDED if can_mode == "extended" else CanMode.NORMAL
            return ho.decode_request(
                spec.frame_id, data, is_extended_id=spec.extended, is_fd=spec.fd, model=model, can_mode=mode
            )
        return ho.decode_reply(spec.frame_id, data, is_fd=spec.fd, model=model)

    return decode


# ---- raw frames for every layout ----------------------------------------------------------------


def leaf_paths(
    layout: Layout, mux: SignalSpec | None = None
) -> Iterator[list[tuple[SignalSpec | None, Layout]]]:
    """Each path of multiplexer values down a layout tree: ``(multiplexer signal, layout)`` pairs, the
    root's signal None."""
    if layout.mux is None:
        yield [(mux, layout)]
        return
    for sub in layout.mux.layouts:
        for rest in leaf_paths(sub, layout.mux.signal):
            yield [(mux, layout), *rest]


def put(data: bytearray, spec: SignalSpec, raw: int) -> None:
    """Write ``raw`` into ``data`` where ``spec`` says (written here from the DBC bit numbering, not by
    cantools or servobus): little-endian from the start bit up; big-endian from the start bit (the MSB)
    down through the byte and on to bit 7 of the next byte."""
    value = raw & ((1 << spec.length) - 1)
    position = spec.start
    order = range(spec.length) if spec.byte_order == "little_endian" else reversed(range(spec.length))
    for k in order:
        byte, bit = divmod(position, 8)
        data[byte] = (data[byte] & ~(1 << bit)) | ((value >> k & 1) << bit)
        if spec.byte_order == "little_endian":
            position += 1
        else:
            position = position + 15 if bit == 0 else position - 1


def random_raw(spec: SignalSpec, rng: random.Random) -> int:
    """A random raw code within the signal's range and choices (edges included)."""
    if spec.choices:
        return rng.choice(spec.choices)[0]
    if spec.is_float:
        value = rng.choice([0.0, 1.5, 1e-3, rng.uniform(0, 1e6), rng.uniform(-1e6, 1e6)])
        return int(struct.unpack("<I", struct.pack("<f", value))[0])
    lo, hi = (
        (-(1 << (spec.length - 1)), (1 << (spec.length - 1)) - 1)
        if spec.signed
        else (0, (1 << spec.length) - 1)
    )
    if spec.minimum is not None and spec.maximum is not None and spec.part is None:
        lo = max(lo, math.ceil((spec.minimum - spec.offset) / spec.scale - 1e-9))
        hi = min(hi, math.floor((spec.maximum - spec.offset) / spec.scale + 1e-9))
    return rng.choice([lo, hi, min(max(0, lo), hi), rng.randint(lo, hi), rng.randint(lo, hi)])


def random_frame(
    spec: MessageSpec, path: list[tuple[SignalSpec | None, Layout]], rng: random.Random, background: bool
) -> bytes:
    data = bytearray(rng.randbytes(spec.length) if background else bytes(spec.length))
    for mux, layout in path:
        if mux is not None:
            assert layout.code is not None
            put(data, mux, layout.code)
        for signal in layout.signals:
            put(data, signal, random_raw(signal, rng))
        for offset, byte in layout.constants:
            data[offset] = byte
    return bytes(data)


RAW_CONFIGS: list[tuple[str, str | None, dict[str, Any]]] = [
    ("myactuator", "V4_4", {}),
    ("myactuator", "V4_3", {}),
    ("myactuator", "V4_4", {"max_torque_nm": 60.0}),
    *[
        ("lk", revision, {"model": motor_type, "encoder_bits": bits})
        for revision in ("V2_36", "V2_35")
        for motor_type in ("MG", "MF", "MH", "MS")
        for bits in (14, 18)
    ],
    ("lk", "V2_35", {"model": "MG", "direction": "request"}),
    *[
        ("hollow", None, {"can_mode": mode, "model": name})
        for mode in ("normal", "extended", "fd")
        for name in ho.MODELS
    ],
    ("hollow", None, {"can_mode": "fd", "host_id": 5}),
]


def decoder_for(family: str, revision: str | None, options: dict[str, Any]) -> Decoder:
    if family == "myactuator":
        return ma_decoder(revision or "V4_4", options.get("max_torque_nm"))
    if family == "lk":
        motor_type = lk.MotorType[options.get("model", "MG")]
        rev = lk.Revision[revision or "V2_36"]
        return lk_decoder(
            lk.LkModel(revision=rev, motor_type=motor_type, encoder_bits=options.get("encoder_bits", 14))
        )
    return ho_decoder(ho.MODELS[options.get("model", "default")], options.get("can_mode", "normal"))


@pytest.mark.parametrize(
    ("family", "revision", "options"),
    RAW_CONFIGS,
    ids=[f"{f}-{r}-{'-'.join(str(v) for v in o.values())}" for f, r, o in RAW_CONFIGS],
)
def test_every_layout_of_the_dbc_decodes_as_servobus_decodes_it(
    family: str, revision: str | None, options: dict[str, Any]
) -> None:
    p, db = dbc(family, revision, **options)
    decode = decoder_for(family, revision, options)
    rng = random.Random(f"{family}{revision}{options}")
    for spec in p.messages:
        for path in leaf_paths(spec.root):
            accepted = 0
            for background in (True, False):
                for _ in range(RAW_FRAMES):
                    data = random_frame(spec, path, rng, background)
                    try:
                        ours = decode(spec, data)
                    except ProtocolError:
                        continue  # a combination servobus refuses (a limit of 0, a motor id of 0): not data
                    check_frame(spec, db, data, ours)
                    canonical = ours.encode()
                    check_frame(spec, db, canonical, decode(spec, canonical))
                    accepted += 1
            names = [layout.name for _, layout in path]
            assert accepted >= 3, (spec.name, names)


# ---- encoder-built frames -----------------------------------------------------------------------

LK_CASES: dict[type, Any] = {**ls.COMMANDS, **ls.REPLIES}


@pytest.mark.parametrize("cls", list(LK_CASES), ids=lambda c: c.__name__)
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_lk_frames_built_by_the_codec_decode_the_same_in_cantools(cls: type, data: st.DataObject) -> None:
    message = data.draw(LK_CASES[cls].strategy)
    home = ls.model_for(message)
    decoded_in = []
    for revision in lk.Revision:
        if revision not in cls.REVISIONS:
            continue
        model = dataclasses.replace(home, revision=revision)
        is_request = isinstance(message, lk.LkCommand)
        direction = "request" if is_request and revision is lk.Revision.V2_35 else None
        p, db = dbc("lk", None, model=model, direction=direction)
        if isinstance(message, lk.MultiMotorTorque):
            frame = lk.codec.request_frame(message, motor_id=None, model=model)
        elif is_request:
            frame = lk.codec.request_frame(message, motor_id=7, model=model)
        else:
            frame = lk.codec.reply_frame(message, motor_id=7, model=model)
        spec = message_at(p, frame.arbitration_id)
        decode = lk_decoder(model)
        try:
            ours = decode(spec, frame.data)
        except ProtocolError:
            continue  # not a frame of this revision (V2.35's iq ±2048, 0x91 in V2.36)
        code = frame.data[0]
        if spec.root.mux is not None and code not in {layout.code for layout in spec.root.mux.layouts}:
            assert is_left_out(p, spec.kind, code), (cls.__name__, hex(code))
            continue
        check_frame(spec, db, frame.data, ours)
        decoded_in.append(revision)
    assert decoded_in, "no revision decodes the frame"


HOLLOW_CASES: list[tuple[str, Any, tuple[str, ...]]] = [
    ("Setpoint", hs.setpoints(), ("normal",)),
    ("IncrementalSetpoint", hs.incremental_setpoints(), ("extended",)),
    ("FdCommand", hs.fd_commands(), ("fd",)),
    ("CanModeSwitch", hs.mode_switches, ("normal", "extended", "fd")),
    ("PiMultiplier", hs.pi_multipliers, ("normal", "extended", "fd")),
    ("NormalReply", hs.normal_replies(), ("normal",)),
    ("ExtendedReply", hs.extended_replies(), ("extended",)),
    ("FdReply", hs.fd_replies(), ("fd",)),
]


@pytest.mark.parametrize(("name", "strategy", "modes"), HOLLOW_CASES, ids=[c[0] for c in HOLLOW_CASES])
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_hollow_frames_built_by_the_codec_decode_the_same_in_cantools(
    name: str, strategy: Any, modes: tuple[str, ...], data: st.DataObject
) -> None:
    message = data.draw(strategy)
    model = getattr(message, "model", ho.DEFAULT_MODEL)
    for mode in modes:
        p, db = dbc("hollow", None, model=model, can_mode=mode)
        if isinstance(message, ho.HollowReply):
            frame = ho.codec.reply_frame(ho.DEFAULT_HOST_ID, message)
        else:
            frame = ho.codec.request_frame(7, message)
        spec = message_at(p, frame.arbitration_id, extended=frame.is_extended_id)
        assert (spec.fd, spec.length) == (frame.is_fd, len(frame.data))
        ours = ho_decoder(model, mode)(spec, frame.data)
        assert type(ours).__name__ == name
        check_frame(spec, db, frame.data, ours)


def test_hollow_special_commands_are_left_out() -> None:
    p, _ = dbc("hollow", None)
    assert any(reason.startswith("special commands FF x7 + F9..FE") for reason in p.left_out)
    assert not any(m.name.startswith("hollow_special") for m in p.messages)


def _myactuator_can_classes() -> list[type]:
    tables = (*ma_codec.REQUESTS.values(), *ma_codec.REPLIES.values())
    classes = {c.message for candidates in tables for c in candidates}
    return [
        c for c in ms.message_classes() if c in classes or c in (ma.Echo, ma.MotionCommand, ma.MotionReply)
    ]


@pytest.mark.parametrize("cls", _myactuator_can_classes(), ids=lambda c: c.__name__)
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_myactuator_frames_built_by_the_codec_decode_the_same_in_cantools(
    cls: type, data: st.DataObject
) -> None:
    message = data.draw(ms.message_strategy(cls))
    scales = getattr(message, "scales", None)
    for revision in ma.Revision:
        options: dict[str, Any] = {}
        if scales is not None:  # motion frames: the DBC of the ranges they were built with
            if scales == ma.MOTION_SCALES[ma.Revision.V4_3]:
                if revision is not ma.Revision.V4_3:
                    continue
            elif revision is ma.Revision.V4_4:
                options["max_torque_nm"] = scales.t_max_nm
            else:
                continue
        elif hasattr(message, "unavailable_reason") and message.unavailable_reason(revision) is not None:
            continue
        p, db = dbc("myactuator", revision.name, **options)
        if isinstance(message, ma.MotionReply):
            message = dataclasses.replace(message, motor_id=7)  # the DBC's motors are 1 and 7
            ident = 0x507
        elif isinstance(message, ma.MyActuatorReply | ma.Echo):
            ident = 0x247
        else:
            ident = ma_codec.arbitration_id(message, 7)
        if ident not in {m.frame_id for m in p.messages}:  # 0x300: 0x79, left out
            assert is_left_out(p, "request", message.code), cls.__name__
            continue
        spec = message_at(p, ident)
        payload = message.encode()
        try:
            ours = ma_decoder(revision.name, options.get("max_torque_nm"))(spec, payload)
        except ProtocolError:
            continue  # a reply layout of the other revision reading the same byte
        code = payload[0]
        if spec.root.mux is not None and code not in {layout.code for layout in spec.root.mux.layouts}:
            assert is_left_out(p, spec.kind, code), (cls.__name__, hex(code))
            continue
        check_frame(spec, db, payload, ours)


# ---- spec vectors -------------------------------------------------------------------------------


def _vectors(name: str) -> list[dict[str, Any]]:
    path = SPEC_DIR / "vectors" / f"{name}.json"
    if not path.exists():
        pytest.skip(f"spec vectors not found at {path}")
    vectors: list[dict[str, Any]] = json.loads(path.read_text())
    return vectors


def test_lk_spec_vectors_decode_the_same_in_cantools() -> None:
    checked = 0
    for vector in _vectors("lk-v2"):
        revision = lk.Revision.V2_35 if vector["dialect"] == "v2.35" else lk.Revision.V2_36
        model = lk.LkModel(revision=revision)
        kind = vector["direction"]
        direction = "request" if kind == "request" and revision is lk.Revision.V2_35 else None
        p, db = dbc("lk", None, model=model, direction=direction)
        data = bytes.fromhex(vector["data"])
        ident = 0x141 if kind == "request" else lk.ids.reply_id(1, revision)
        spec = next(m for m in p.messages if m.kind == kind and m.frame_id in (ident, 0x280))
        if spec.frame_id == 0x280:
            continue
        try:
            ours = lk_decoder(model)(spec, data)
        except ProtocolError:
            continue
        check_frame(spec, db, data, ours)
        checked += 1
    assert checked >= 30


def test_hollow_spec_vectors_decode_the_same_in_cantools() -> None:
    checked = 0
    for vector in _vectors("hollow"):
        if vector["transport"] not in ("can", "canfd"):
            continue
        data = bytes.fromhex(vector["data"])
        fd = vector["transport"] == "canfd"
        extended = "EXTENDED" in str(vector.get("can_id"))
        p, db = dbc("hollow", None, can_mode="fd" if fd else "normal")
        if vector["direction"] == "reply":
            spec = next(m for m in p.messages if m.kind == "reply")
        else:
            spec = message_at(p, 1, extended=extended)
        try:
            ours = ho_decoder(ho.DEFAULT_MODEL, "fd" if fd else "normal")(spec, data)
        except ProtocolError:
            continue
        if isinstance(ours, ho.SpecialCommand):
            continue  # left out: a 7-byte pattern, not a multiplexer value
        check_frame(spec, db, data, ours)
        checked += 1
    assert checked >= 6


def test_myactuator_spec_vectors_decode_the_same_in_cantools() -> None:
    checked = 0
    for vector in _vectors("myactuator-v4"):
        if vector["transport"] != "can" or not str(vector.get("can_id", "")).startswith("0x"):
            continue
        ident = int(vector["can_id"], 16)
        data = bytes.fromhex(vector.get("probable_data") or vector["data"])
        for revision in ("V4_4", "V4_3"):
            p, db = dbc("myactuator", revision)
            spec = next((m for m in p.messages if m.frame_id == ident), None)
            if spec is None or len(data) != 8:
                continue
            try:
                ours = ma_decoder(revision)(spec, data)
            except (ProtocolError, ValueError):
                continue
            if spec.root.mux is not None and data[0] not in {x.code for x in spec.root.mux.layouts}:
                assert is_left_out(p, spec.kind, data[0])
                continue
            check_frame(spec, db, data, ours)
            checked += 1
    assert checked >= 150


# ---- what is in the DBC, what is left out -------------------------------------------------------


def _top_codes(p: Plan, kind: str) -> set[int]:
    return {
        layout.code
        for m in p.messages
        if m.kind == kind and m.root.mux is not None and m.root.mux.signal.field == MUX
        for layout in m.root.mux.layouts
        if layout.code is not None
    }


@pytest.mark.parametrize("revision", ["V4_4", "V4_3"])
def test_every_myactuator_layout_is_in_the_dbc_or_left_out_with_why(revision: str) -> None:
    p, _ = dbc("myactuator", revision)
    rev = ma.Revision[revision]
    for kind, table in (("request", ma_codec.REQUESTS), ("reply", ma_codec.REPLIES)):
        codes = {code for code, candidates in table.items() if any(rev in c.revisions for c in candidates)}
        missing = codes - _top_codes(p, kind)
        assert missing == {code for code in missing if is_left_out(p, kind, code)}
    # In V4.4: 0x20 (its value is signed by index) both ways, 0xB5's text, the 0xF1 event (any bytes
    # after DATA[0]) and the RS485 MIT frames; V4.3 has no RS485 MIT frames and adds 0x79 both ways.
    assert len(p.left_out) == (5 if revision == "V4_4" else 6)
    names = {m.name for m in p.messages}
    assert {"myactuator_motion_command_7", "myactuator_motion_reply_7"} <= names


@pytest.mark.parametrize("revision", list(lk.Revision), ids=lambda r: r.name)
@pytest.mark.parametrize("motor_type", list(lk.MotorType), ids=lambda t: t.name)
def test_every_lk_layout_is_in_the_dbc_or_left_out_with_why(
    revision: lk.Revision, motor_type: lk.MotorType
) -> None:
    model = lk.LkModel(revision=revision, motor_type=motor_type)
    requests, _ = dbc("lk", None, model=model, direction="request")
    replies, _ = dbc("lk", None, model=model, direction="reply")
    for p, kind, table in ((requests, "request", REQUESTS), (replies, "reply", REPLY_CLASSES)):
        missing = set(table[revision]) - _top_codes(p, kind)
        assert missing == {code for code in missing if is_left_out(p, kind, code)}, kind
        for code in _top_codes(p, kind):
            layout = next(
                x
                for m in p.messages
                if m.kind == kind and m.root.mux
                for x in m.root.mux.layouts
                if x.code == code
            )
            assert layout.message == table[revision][code].__name__
    left = [r for r in requests.left_out]
    if motor_type is lk.MotorType.MS:  # no torque loop: 0xA1 and (V2.35) the 0x280 frame
        assert any(r.startswith("request 0xA1 (TorqueControl)") for r in left)
        assert any(r.startswith("request id 0x280") for r in left) == (revision is lk.Revision.V2_35)
    else:
        assert left == []
    multi = [m for m in requests.messages if m.frame_id == 0x280]
    assert len(multi) == (revision is lk.Revision.V2_35 and motor_type is not lk.MotorType.MS)


def test_lk_v235_replies_share_the_request_identifier() -> None:
    p, db = dbc("lk", "V2_35")
    assert {m.kind for m in p.messages if m.frame_id != 0x280} == {"reply"}
    assert any(r.startswith("requests on 0x140+ID") for r in p.left_out)
    assert [m.name for m in db.messages] == ["lk_reply_1", "lk_reply_7", "lk_multi_motor"]
    p, _ = dbc("lk", "V2_36")
    assert {(m.kind, m.frame_id) for m in p.messages} == {
        ("request", 0x141),
        ("reply", 0x181),
        ("request", 0x147),
        ("reply", 0x187),
    }


@pytest.mark.parametrize("mode", ["normal", "extended", "fd"])
def test_hollow_dbc_holds_one_can_mode_and_the_extended_id_frames(mode: str) -> None:
    p, db = dbc("hollow", None, can_mode=mode)
    config = db.get_message_by_name("hollow_config_7")
    assert (config.frame_id, config.is_extended_frame, config.is_fd) == (7, True, False)
    reply = db.get_message_by_frame_id(100)
    request = db.get_message_by_frame_id(7)
    assert (reply.is_fd, request.is_fd) == (mode == "fd", mode == "fd")
    assert (request.length, reply.length) == {"normal": (8, 6), "extended": (8, 8), "fd": (16, 16)}[mode]
    assert any(
        reason.startswith(f"the {' and '.join(m for m in ('normal', 'extended', 'fd') if m != mode)} frames")
        for reason in p.left_out
    )
    assert any("RS-485" in reason for reason in p.left_out)
    with pytest.raises(ValueError, match="host id"):
        plan("hollow", [1, 100])


# ---- what the signals say -----------------------------------------------------------------------


def test_myactuator_signals_carry_scale_range_and_unit_from_the_field_tables() -> None:
    _, db = dbc("myactuator", "V4_4")
    reply = db.get_message_by_name("myactuator_reply_1")
    speed = reply.get_signal_by_name("speed_dps")  # R2: int16 1 dps/LSB
    assert (speed.start, speed.length, speed.is_signed, speed.scale, speed.unit) == (32, 16, True, 1, "deg/s")
    current = reply.get_signal_by_name("current_a")
    assert (current.scale, current.unit, current.minimum, current.maximum) == (0.01, "A", -327.68, 327.67)
    angle = reply.get_signal_by_name("angle_deg_94")  # 0x94 V4.4: int32 0.01°, ±180°
    assert (angle.length, angle.scale, angle.minimum, angle.maximum) == (32, 0.01, -180, 180)
    assert reply.get_signal_by_name("value").is_float  # 0x30 PID float32
    assert db.get_message_by_frame_id(0x141).senders == ["host"]
    assert db.get_message_by_frame_id(0x280).name == "myactuator_broadcast"


@pytest.mark.parametrize(
    ("revision", "torque", "p_max", "kd_max", "t_max"),
    [("V4_4", None, 12.566, 50.0, 24.0), ("V4_3", None, 12.5, 5.0, 24.0), ("V4_4", 60.0, 12.566, 50.0, 60.0)],
)
def test_motion_signals_are_the_mit_mapping_of_the_revision_scales(
    revision: str, torque: float | None, p_max: float, kd_max: float, t_max: float
) -> None:
    """MIT packing of x in [lo, hi] into n bits is factor (hi - lo) / (2**n - 1), offset lo, big-endian."""
    options = {} if torque is None else {"max_torque_nm": torque}
    _, db = dbc("myactuator", revision, **options)
    command = db.get_message_by_name("myactuator_motion_command_7")
    assert command.frame_id == 0x407
    shape = {
        s.name: (s.start, s.length, s.byte_order, s.is_signed, s.scale, s.offset) for s in command.signals
    }
    assert shape == {
        "position_rad": (7, 16, "big_endian", False, 2 * p_max / 65535, -p_max),
        "velocity_rad_s": (23, 12, "big_endian", False, 90 / 4095, -45),
        "kp": (27, 12, "big_endian", False, 500 / 4095, 0),
        "kd": (47, 12, "big_endian", False, kd_max / 4095, 0),
        "torque_ff_nm": (51, 12, "big_endian", False, 2 * t_max / 4095, -t_max),
    }
    reply = db.get_message_by_name("myactuator_motion_reply_7")
    assert reply.frame_id == 0x507
    assert {s.name: (s.start, s.length) for s in reply.signals} == {
        "motor_id": (7, 8),
        "position_rad": (15, 16),
        "velocity_rad_s": (31, 12),
        "torque_nm": (35, 12),
    }
    # The manual's example (myactuator-v4.md §5.4): p 0xE666 = 9.9998 rad with ±12.5 rad.
    if revision == "V4_3":
        decoded = db.decode_message(0x501, bytes.fromhex("01E66682EB550000"))
        assert math.isclose(decoded["position_rad"], 0xE666 * 25 / 65535 - 12.5)


def test_hollow_extended_reply_position_is_two_runs_that_add_up() -> None:
    _, db = dbc("hollow", None, can_mode="extended")
    reply = db.get_message_by_name("hollow_ext_reply")
    low = reply.get_signal_by_name("position_deg_b0")
    high = reply.get_signal_by_name("position_deg_b16")
    step = 360 / (1 << 20)
    assert (low.start, low.length, low.is_signed, low.scale) == (15, 16, False, step)
    assert (high.start, high.length, high.is_signed, high.scale) == (55, 16, True, step * 65536)
    message = ho.ExtendedReply(motor_id=3, position_deg=-1234.5678, speed_rad_s=1.0, current_a=0.5)
    decoded = db.decode_message(100, message.encode())
    assert math.isclose(
        decoded["position_deg_b0"] + decoded["position_deg_b16"], message.position_deg, abs_tol=step
    )


def test_hollow_fd_frames_are_can_fd_in_the_dbc_text() -> None:
    p, db = dbc("hollow", None, can_mode="fd")
    text = dbc_text(database(p))
    assert 'BA_ "BusType" "CAN FD";' in text
    command = db.get_message_by_name("hollow_fd_command_7")
    assert (command.is_fd, command.length) == (True, 16)
    position = command.get_signal_by_name("position_deg")
    assert (position.start, position.length, position.is_signed, position.byte_order) == (
        7,
        40,
        True,
        "big_endian",
    )
    assert command.get_signal_by_name("mode").choices[2] == "POSITION"


def test_lk_parameter_frames_are_multiplexed_again_on_the_parameter() -> None:
    _, db = dbc("lk", "V2_36")
    write = bytes.fromhex("C11E0000E8030000")  # WriteControlParam TORQUE_LIMIT = 1000
    assert db.decode_message(0x147, write) == {
        "code": "WriteControlParam",
        "param_C1": "TORQUE_LIMIT",  # "param" alone is 0xC0's, a plain signal (ReadControlParam)
        "value_C1_1E": 1000,
    }
    # 0xC0 and 0xC1 replies share one nested multiplexer (the same layouts): the only "param" there.
    assert db.decode_message(0x187, bytes.fromhex("C11E0000E8030000")) == {
        "code": "ControlParamReply_C1",
        "param": "TORQUE_LIMIT",
        "value_C0_1E": 1000,  # "value" is another parameter's (0x20, 0x26: an int32 0..600000)
    }
    setting = bytes.fromhex("4205B20000400D03")  # WriteSetting MAX_SPEED = 0x030D4000
    assert db.decode_message(0x147, setting) == {
        "code": "WriteSetting",
        "param_group_42": "SINGLE_VALUE",  # 05: a single value, addressed by DATA[2]
        "param_42_05": "MAX_SPEED",
        "value_42_05_B2": 0x030D4000,
    }
    pid_reply = bytes.fromhex("40A0640032000A00")  # SettingReply POSITION_PID kp=100 ki=50 kd=10
    assert db.decode_message(0x187, pid_reply) == {
        "code": "SettingReply_40",
        "param_group": "POSITION_PID",
        "value_kp": 100,  # one multiplexer level up from 0xC0's PID values: the field's own name
        "value_ki": 50,
        "value_kd": 10,
    }


def test_every_signal_name_is_a_short_dbc_identifier() -> None:
    for family, revision, options in RAW_CONFIGS:
        _, db = dbc(family, revision, **options)
        for message in db.messages:
            assert len(message.name) <= 32
            for signal in message.signals:
                assert len(signal.name) <= 32 and signal.name.isidentifier(), signal.name


def depth(table: dict[str, Placed], placed: Placed) -> int:
    """How many multiplexers are above a signal."""
    return 0 if placed.mux_signal is None else 1 + depth(table, table[placed.mux_signal])


def test_every_signal_has_its_field_name_unless_another_signal_of_the_message_has_it() -> None:
    """The naming rule of the module docstring: a signal is named after its servobus field
    (``dbc_name``); only where another signal of the message already has that name (the field laid out
    otherwise, or under another multiplexer) does it get its multiplexer values as a suffix, and the
    signal keeping the name has no more multiplexer levels above it and no fewer values."""
    renamed = 0
    for family, revision, options in RAW_CONFIGS:
        p, _ = dbc(family, revision, **options)
        for spec in p.messages:
            table = signal_table(spec)
            for name, placed in table.items():
                base = placed.spec.base_name
                assert base == dbc_name(placed.spec.field) + (
                    "" if placed.spec.part is None else f"_b{placed.spec.part}"
                )
                if name == base:
                    continue
                renamed += 1
                assert re.fullmatch(re.escape(base) + r"(_[0-9A-F]{2})+", name), (spec.name, name)
                keeper = table[base]
                assert keeper.spec.base_name == base, (spec.name, name)
                shape = (placed.spec, placed.layouts, placed.mux_signal)
                assert (keeper.spec, keeper.layouts, keeper.mux_signal) != shape, (spec.name, name)
                rank = (-depth(table, keeper), len(keeper.mux_ids))
                assert rank >= (-depth(table, placed), len(placed.mux_ids)), (spec.name, name)
    assert renamed > 0
    _, db = dbc("myactuator", "V4_4")
    reply = db.get_message_by_name("myactuator_reply_1")
    assert db.decode_message(0x241, bytes.fromhex("9C326400F4012D00")) == {
        "code": "StatusReply_9C",
        "temperature_c": 50,
        "current_a": 1.0,
        "speed_dps": 500,
        "angle_deg": 45,  # int16 1° in status 2 and the control replies; was angle_deg_72
    }
    shared = [0x72, 0x73, 0x9C, 0xA1, 0xA2, 0xA4, 0xA8, 0xA9]  # status 2 and the control replies
    assert sorted(reply.get_signal_by_name("angle_deg").multiplexer_ids) == shared
    assert reply.get_signal_by_name("angle_deg_92").scale == 0.01  # int32 0.01° under 0x92


def test_build_database_and_bad_options() -> None:
    db, left_out = build_database("lk", [1], "V2_35", model="MH")
    assert [m.name for m in db.messages] == ["lk_reply_1", "lk_multi_motor"]
    assert db.get_message_by_name("lk_multi_motor").get_signal_by_name("iq_counts_0").unit == "counts"
    assert left_out
    with pytest.raises(ValueError, match="can_mode is an option of hollow, not of lk"):
        plan("lk", [1], can_mode="fd")
    with pytest.raises(ValueError, match="no family"):
        plan("bogus", [1])
    with pytest.raises(ValueError, match="motor type"):
        plan("lk", [1], model="XX")
    with pytest.raises(ValueError, match="no model"):
        plan("hollow", [1], model="nope")
    with pytest.raises(ValueError, match=r"V4\.3 fixes"):
        plan("myactuator", [1], "V4_3", max_torque_nm=10.0)
    with pytest.raises(ValueError, match="motor_id"):
        plan("myactuator", [0])

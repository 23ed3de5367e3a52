"""LK codec entry points (codec.py): the spec's command table, revisions, motor types, fuzzing."""

from __future__ import annotations

import contextlib
import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from _spec import SPEC_DIR
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import get_family, lk
from servobus.protocols.lk import LkModel, MotorType, Revision, ids
from servobus.protocols.lk.codec import (
    COMMAND_CLASSES,
    INFERRED_LAYOUTS,
    REPLY_CLASSES,
    REQUESTS,
    check_available,
    encode_request,
    reply_class,
    request_classes,
    request_frame,
    resolve_model,
)

from .._contract import can_payloads, decodes_or_protocol_error, standard_ids
from ._strategies import COMMANDS, model_for

V236 = Revision.V2_36
V235 = Revision.V2_35


def spec_command_table() -> list[tuple[int, dict[Revision, bool], str]]:
    """Rows of lk-v2.md §3: (command byte or 0x280, present per revision, the row's text)."""
    path = SPEC_DIR / "lk-v2.md"
    if not path.exists():
        pytest.skip(f"spec not found at {path}")
    section = path.read_text().split("## 3. Command summary", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        match = re.fullmatch(r"(?:\(ID )?(0x[0-9A-F]+)\)?", cells[0]) if len(cells) >= 6 else None
        if not match:
            continue

        def present(cell: str) -> bool:
            # "§n" = documented; "listed only" = named without layout (0x33); a dash or prose = absent.
            return cell.startswith("§") or "listed only" in cell

        rows.append((int(match[1], 16), {V236: present(cells[2]), V235: present(cells[3])}, line))
    return rows


ROWS = spec_command_table()


def test_the_spec_table_was_parsed() -> None:
    codes = [code for code, _, _ in ROWS]
    assert len(codes) == 32  # "31 distinct command bytes ... + the 0x280 multi-motor frame"
    assert len(set(codes)) == 32
    assert ids.MULTI_MOTOR_ID in codes


@pytest.mark.parametrize(("code", "present", "row"), ROWS, ids=[f"0x{c:02X}" for c, _, _ in ROWS])
def test_every_spec_command_has_encoder_and_decoders(
    code: int, present: dict[Revision, bool], row: str
) -> None:
    for revision, exists in present.items():
        if code == ids.MULTI_MOTOR_ID:
            has_request = lk.MultiMotorTorque in request_classes(revision)
            reply_code = ids.MULTI_MOTOR_REPLY_CODE
        else:
            has_request = code in REQUESTS[revision]
            reply_code = code
        assert has_request is exists, f"{revision.name}: request for {row}"
        if not exists:
            continue
        # An encoder (a command class with a round-trip strategy) and both decoders exist.
        cls = lk.MultiMotorTorque if code == ids.MULTI_MOTOR_ID else REQUESTS[revision][code]
        assert cls in COMMANDS
        assert reply_code in REPLY_CLASSES[revision], f"{revision.name}: reply decoder for {row}"
        # Layouts the manuals do not print are implemented from the spec's inference: documented.
        if "listed only" in row or "inferred" in row:
            assert code in INFERRED_LAYOUTS, row


def test_no_command_outside_the_spec_table() -> None:
    spec = {(code, r) for code, present, _ in ROWS for r, exists in present.items() if exists}
    ours = {(code, r) for r in Revision for code in REQUESTS[r]}
    ours |= {(ids.MULTI_MOTOR_ID, r) for r in Revision if lk.MultiMotorTorque in request_classes(r)}
    assert ours == spec


REVISION_ONLY = [
    (lk.BrakeControl(action=lk.BrakeAction.READ), V236),
    (lk.CalibrateEncoder(), V236),
    (lk.ReadControlParam(param=lk.ControlParam.SPEED_PID), V236),
    (lk.WriteControlParam(param=lk.ControlParam.SPEED_LIMIT, value=1), V236),
    (lk.ReadSetting(param=lk.SettingParam.MAX_SPEED), V236),
    (lk.SaveSettings(), V236),
    (lk.SpeedControl(speed_dps=1, motor_type=MotorType.MF, current_limit_a=1), V236),
    (lk.WriteEncoderOffset(offset_counts=1, encoder_bits=14), V235),
    (lk.ReadAcceleration(), V235),
    (lk.WriteAcceleration(acceleration_dps2=100), V235),
    (lk.ReadParam(param=lk.ParamId.ANGLE_PID), V235),
    (lk.SpeedControlV235(speed_dps=1), V235),
    (lk.SingleTurnPositionV235(angle_deg=1, direction=lk.SpinDirection.CLOCKWISE), V235),
    (lk.MultiMotorTorque(motor_type=MotorType.MG, currents_a=(0.0, 0.0, 0.0, 0.0)), V235),
]


@pytest.mark.parametrize(("command", "only"), REVISION_ONLY, ids=lambda v: type(v).__name__)
def test_commands_of_one_revision_only(command: Any, only: Revision) -> None:
    other = V235 if only is V236 else V236
    model = LkModel(revision=only, motor_type=getattr(command, "motor_type", MotorType.MG))
    data = encode_request(command, model=model)
    assert data == command.encode()
    with pytest.raises(ValueError, match=rf"{type(command).__name__} \(.*\) does not exist in {other.name}"):
        encode_request(command, revision=other)
    can_id = ids.MULTI_MOTOR_ID if isinstance(command, lk.MultiMotorTorque) else 0x141
    decoded = lk.decode_request(can_id, data, model=model)
    assert type(decoded) is type(command)
    assert decoded.encode() == data
    same_byte_exists = can_id != ids.MULTI_MOTOR_ID and data[0] in REQUESTS[other]
    if same_byte_exists:
        # 0x40/0x42/0x44, 0xA2, 0xA5: the byte exists in the other revision with another layout.
        # The other scheme's address/value bytes may not fit at all (ProtocolError), or decode to
        # the other revision's class, never to this one.
        with contextlib.suppress(ProtocolError):
            assert type(lk.decode_request(can_id, data, revision=other)) is not type(command)
    else:
        with pytest.raises(ProtocolError, match=f"{other.name}"):
            lk.decode_request(can_id, data, revision=other)


@pytest.mark.parametrize(
    ("can_id", "data", "revision"),
    [
        (0x181, "8C 01 00 00 00 00 00 00", V236),
        (0x141, "91 00 00 00 00 00 10 00", V235),
        (0x141, "34 00 00 00 10 00 00 00", V235),
    ],
)
def test_replies_of_one_revision_only(can_id: int, data: str, revision: Revision) -> None:
    raw = bytes.fromhex(data)
    lk.decode_reply(can_id, raw, revision=revision)
    other = V235 if revision is V236 else V236
    with pytest.raises(ProtocolError, match=f"no {other.name} reply has command byte 0x{raw[0]:02X}"):
        lk.decode_reply(ids.reply_id(1, other), raw, revision=other)


def test_revision_specific_layouts_decode_per_revision() -> None:
    status1 = bytes.fromhex("9A 19 E3 01 00 00 00 09")
    assert type(lk.decode_reply(0x181, status1, revision=V236)) is lk.Status1Reply
    assert type(lk.decode_reply(0x141, status1, revision=V235)) is lk.Status1ReplyV235
    angle = bytes.fromhex("94 00 00 00 10 27 00 00")
    assert lk.decode_reply(0x181, angle, revision=V236) == lk.SingleTurnAngleReply(angle_deg=100.0)
    assert lk.decode_reply(0x141, angle, revision=V235) == lk.SingleTurnAngleReplyV235(angle_deg=0.0)


def test_reply_ids_are_checked_per_revision() -> None:
    data = bytes.fromhex("80 00 00 00 00 00 00 00")
    with pytest.raises(ProtocolError, match=r"0x141 is not a V2_36 reply identifier \(0x181..0x1A0\)"):
        lk.decode_reply(0x141, data, revision=V236)
    with pytest.raises(ProtocolError, match=r"0x181 is not a V2_35 reply identifier \(0x141..0x160\)"):
        lk.decode_reply(0x181, data, revision=V235)
    with pytest.raises(ProtocolError, match="not an LK request identifier"):
        lk.decode_request(0x181, data)
    with pytest.raises(ProtocolError, match=r"0x280 .* does not exist in V2_36"):
        lk.decode_request(0x280, bytes(8), revision=V236)


def test_decode_errors_name_the_motor() -> None:
    with pytest.raises(ProtocolError) as info:
        lk.decode_reply(0x185, bytes.fromhex("9A 00 00 00 00 00 02 00"))
    assert info.value.motor_id == 5
    assert info.value.command == 0x9A
    with pytest.raises(ProtocolError, match="empty reply") as empty:
        lk.decode_reply(0x185, b"")
    assert empty.value.motor_id == 5


def test_motor_type_restrictions_of_the_v236_manual() -> None:
    # [001]: 0xA0 only on MS; 0xA1 only on MF/MH/MG. [003] names no such restriction for 0xA0.
    open_loop = lk.OpenLoopControl(power_counts=100)
    check_available(open_loop, model=LkModel(motor_type=MotorType.MS))
    with pytest.raises(
        ValueError, match=r"OpenLoopControl \(0xA0\) is not implemented on MG motors in V2_36"
    ):
        encode_request(open_loop, model=LkModel(motor_type=MotorType.MG))
    check_available(open_loop, model=LkModel(revision=V235, motor_type=MotorType.MG))
    check_available(open_loop, revision=V236)  # no motor type known: nothing to refuse
    torque = lk.TorqueControl(motor_type=MotorType.MF, current_a=1)
    check_available(torque, revision=V235)
    with pytest.raises(ValueError, match=r"motor_type=MF contradicts model\.motor_type=MG"):
        check_available(torque, model=LkModel(motor_type=MotorType.MG))


def test_revision_and_model_must_agree() -> None:
    assert resolve_model() == LkModel()
    assert resolve_model(V235) == LkModel(revision=V235)
    model = LkModel(revision=V235, motor_type=MotorType.MF, encoder_bits=16)
    assert resolve_model(V235, model) is model
    with pytest.raises(ValueError, match=r"revision=V2_36 contradicts model\.revision=V2_35"):
        lk.decode_reply(0x141, bytes(8), revision=V236, model=model)
    with pytest.raises(ValueError, match=r"revision='v2\.35' is not one of"):
        lk.decode_reply(0x141, bytes(8), revision="v2.35")  # type: ignore[arg-type]


def test_reply_class_names_what_answers_a_request() -> None:
    assert reply_class(0xA4, V236) is lk.Status2Reply
    assert reply_class(0x9A, V235) is lk.Status1ReplyV235
    assert reply_class(0x44, V236) is lk.SaveSettingsReply
    assert reply_class(0x44, V235) is lk.ParamWriteReply
    with pytest.raises(ValueError, match="0x8C does not exist in V2_35"):
        reply_class(0x8C, V235)


def test_family_is_registered() -> None:
    family = get_family("lk")
    assert family is lk.FAMILY
    assert family.revisions == (V236, V235)
    assert family.default_revision is V236
    assert family.revision("v2.35") is V235
    reply = family.decode_reply(0x141, bytes.fromhex("88 00 00 00 00 00 00 00"), revision=V235)
    assert reply == lk.EchoReply(command=0x88)


models = st.builds(
    LkModel,
    revision=st.sampled_from(list(Revision)),
    motor_type=st.sampled_from(list(MotorType)),
    encoder_bits=st.sampled_from([14, 15, 16, 18]),
)
lk_ids = st.one_of(
    standard_ids,
    st.integers(min_value=0x140, max_value=0x1A1),
    st.just(0x280),
    st.just(0x141),
    st.just(0x181),
)
lk_payloads = st.one_of(
    can_payloads,
    st.tuples(
        st.sampled_from(sorted({c for r in Revision for c in REPLY_CLASSES[r]})),
        st.binary(min_size=7, max_size=7),
    ).map(lambda t: bytes([t[0]]) + t[1]),
)


@given(lk_ids, lk_payloads, models)
def test_random_bytes_decode_or_raise_protocol_error(can_id: int, data: bytes, model: LkModel) -> None:
    request = decodes_or_protocol_error(lk.decode_request, can_id, data, model=model)
    reply = decodes_or_protocol_error(lk.decode_reply, can_id, data, model=model)
    if request is not None and can_id != ids.MULTI_MOTOR_ID:
        assert request.encode()[0] == data[0]
    if reply is not None:
        assert len(data) == 8
        assert reply.encode()[0] == data[0]


@pytest.mark.parametrize("cls", sorted(COMMANDS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@given(data=st.data())
def test_host_and_simulated_motor_agree(cls: type, data: st.DataObject) -> None:
    # Host encodes a request; the device side decodes it, answers with the reply class the table
    # names; the host keys the answer like the scheduler will (our own loop-back is not a reply).
    command = data.draw(COMMANDS[cls].strategy)
    model = model_for(command)
    frame = request_frame(command, motor_id=None if cls is lk.MultiMotorTorque else 7, model=model)
    assert lk.decode_request(frame.arbitration_id, frame.data, model=model) is not None
    looped_back = Frame(arbitration_id=frame.arbitration_id, data=frame.data, is_rx=False)
    assert ids.reply_key(looped_back, revision=model.revision) is None
    if cls is lk.MultiMotorTorque:
        expected = set(ids.multi_motor_reply_keys(model.revision))
        assert all(key[1] == 0xA1 for key in expected)
        return
    reply_cls = reply_class(frame.data[0], model.revision)
    assert command.CODE is not None
    keys = ids.request_keys(7, command.CODE, model.revision)
    # Whatever the reply class, a received frame on the reply id that starts with the request's command
    # byte is keyed to this request (the key reads only the id and DATA[0]).
    echo = Frame(arbitration_id=ids.reply_id(7, model.revision), data=frame.data, is_rx=True)
    assert ids.reply_key(echo, revision=model.revision) in keys
    if reply_cls is lk.EchoReply:
        assert lk.decode_reply(echo.arbitration_id, echo.data, model=model) == lk.EchoReply(
            command=command.CODE
        )


CLASS_CODES: dict[Any, frozenset[int]] = {
    **{cls: frozenset({cls.CODE}) for cls in COMMAND_CLASSES if cls.CODE is not None},
    lk.MultiMotorTorque: frozenset(),
    **dict(lk.codec.REPLY_LAYOUTS),
}


@pytest.mark.parametrize("cls", sorted(CLASS_CODES, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@given(data=st.data(), payload=can_payloads, model=models)
def test_every_class_decoder_decodes_or_raises_protocol_error(
    cls: Any, data: st.DataObject, payload: bytes, model: LkModel
) -> None:
    # Each class's own decode() (the simulator calls these directly). Most payloads get one of the
    # class's command bytes, so the value checks are reached, not only the command-byte check.
    codes = CLASS_CODES[cls]
    if codes and payload and data.draw(st.booleans()):
        payload = bytes([data.draw(st.sampled_from(sorted(codes)))]) + payload[1:]
    message = decodes_or_protocol_error(cls.decode, payload, model=model)
    if message is not None:
        assert type(message) is cls
        if codes:
            assert message.encode()[0] in codes

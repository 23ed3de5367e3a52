"""Decoder tables, revision availability and the CAN entry points (codec.py).

The command table test reads myactuator-v4.md §2 itself, so it follows the spec, not a list typed here.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from _spec import SPEC_DIR
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.codec import (
    ECHO_COMMANDS,
    NO_REPLY,
    REPLIES,
    REQUESTS,
    arbitration_id,
    check_available,
    encode_request,
    expects_reply,
    request_frame,
)

from .._contract import can_payloads, decodes_or_protocol_error, standard_ids
from ._strategies import message_classes

V43, V44 = ma.Revision.V4_3, ma.Revision.V4_4
ALL = frozenset(ma.Revision)


# ---- the spec's command table ----


@dataclass(frozen=True)
class Row:
    command: str
    name: str
    in_000: str
    in_002: str
    reply: str

    @property
    def revisions(self) -> frozenset[ma.Revision]:
        found = set()
        if self.in_000.startswith("yes"):
            found.add(V44)
        if self.in_002.startswith("yes"):
            found.add(V43)
        return frozenset(found)


def _spec_section() -> str:
    path = SPEC_DIR / "myactuator-v4.md"
    if not path.exists():
        if os.environ.get("CI"):
            raise FileNotFoundError(path)
        pytest.skip(f"spec not found at {path}")
    text = path.read_text()
    return text[text.index("## 2. Command summary") : text.index("## 3. ")]


def command_table() -> list[Row]:
    rows = []
    for line in _spec_section().splitlines():
        if line.startswith(("| 0x", "| FE EE")):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            rows.append(Row(*cells[:5]))
    return rows


ROWS = command_table()
STANDARD_ROWS = [r for r in ROWS if re.fullmatch(r"0x[0-9A-F]{2}", r.command)]


def test_the_table_was_read() -> None:
    # Every body row of §2's table was parsed (the header and the |---| rule are its only other lines).
    table = [line for line in _spec_section().splitlines() if line.startswith("|")]
    assert table[:2] == [
        "| Cmd | Name | [000] | [002] | Reply | Persistence / notes |",
        "|---|---|---|---|---|---|",
    ]
    assert len(ROWS) == len(table) - 2
    assert {r.command for r in ROWS} - {r.command for r in STANDARD_ROWS} == {
        "0x400+ID (CAN id)",
        "FE EE frame",
    }


@pytest.mark.parametrize("row", STANDARD_ROWS, ids=lambda r: r.command)
def test_every_command_of_the_table_has_an_encoder_and_decoders(row: Row) -> None:
    code = int(row.command, 16)
    layouts = REQUESTS.get(code)
    assert layouts, f"{row.command} {row.name}: no request class"
    assert frozenset().union(*(layout.revisions for layout in layouts)) == row.revisions
    for layout in layouts:
        assert callable(layout.message.encode) and code == layout.message.CODE
    reply = row.reply.lower()
    if "none" in reply or "random" in reply:
        assert NO_REPLY[code], f"{row.command}: no reply, and a reason is documented"
        assert code not in REPLIES
        return
    replies = REPLIES[code]
    echoes = [layout for layout in replies if layout.message in ECHO_COMMANDS]
    others = [layout for layout in replies if layout.message not in ECHO_COMMANDS]
    if reply.startswith("echo"):
        assert echoes, f"{row.command}: the reply is an echo"
    if not reply.startswith("echo") or "/" in reply:  # "echo / ID" (0x79) has both
        assert others, f"{row.command}: the reply has its own layout ({row.reply})"
    assert frozenset().union(*(layout.revisions for layout in replies)) == row.revisions


def test_motion_rows() -> None:
    can = next(r for r in ROWS if r.command.startswith("0x400"))
    assert can.revisions == ALL
    for revision in can.revisions:
        assert isinstance(ma.decode_request(0x401, bytes(8), revision=revision), ma.MotionCommand)
        assert isinstance(ma.decode_reply(0x501, b"\x01" + bytes(7), revision=revision), ma.MotionReply)
    rs485 = next(r for r in ROWS if r.command == "FE EE frame")
    assert ma.Rs485MotionCommand.REVISIONS == rs485.revisions == ma.Rs485MotionReply.REVISIONS


def test_no_command_outside_the_table_and_none_the_spec_calls_undefined() -> None:
    table = {int(r.command, 16) for r in STANDARD_ROWS}
    assert set(REQUESTS) == table
    section = _spec_section()
    start = section.index("not defined in either manual")
    sentence = re.sub(r"\([^)]*\)", "", re.split(r"\.\s", section[start:], maxsplit=1)[0])  # drop remarks
    undefined = {int(code, 16) for code in re.findall(r"0x[0-9A-F]{2}", sentence)}
    assert undefined == {0x9B, 0x9E, 0x9F, 0x8C, 0x88, 0x19}
    assert not undefined & set(REQUESTS) and not undefined & set(REPLIES)
    assert 0xA3 not in REQUESTS and 0xA5 not in REQUESTS  # removed in V3.7 (merged into 0xA4)


# ---- revisions ----


@pytest.mark.parametrize(
    ("command", "revision", "message"),
    [
        (ma.SetCanId(motor_id=1), V44, r"0x79 CAN-ID setting exists only in V4\.3 \(revision V4_4 given\)"),
        (ma.ReadCanId(), V44, r"0x79 CAN-ID setting exists only in V4\.3 \(revision V4_4 given\)"),
        (ma.ReadSingleTurnEncoder(), V44, "0x90 read single-turn encoder exists only in V4.3"),
        (
            ma.PositionSpeedFeedforward(angle_deg=0, max_speed_dps=None, feedforward_speed_pct=0),
            V43,
            r"0x72 position control with speed feed-forward exists only in V4\.4 \(revision V4_3 given\)",
        ),
        (
            ma.PositionTorqueFeedforward(angle_deg=0, max_speed_dps=None, feedforward_torque_pct=0),
            V43,
            "0x73 position control with torque feed-forward exists only in V4.4",
        ),
        (ma.FunctionControl.error_auto_recovery(True), V43, "0x20 function control index 8 .* only in V4.4"),
        (ma.ReadModel(), V44, "0xB5 read motor model \\(single frame\\) exists only in V4.3"),
        (ma.ReadModelPart(part=1), V43, "0xB5 read motor model \\(indexed\\) exists only in V4.4"),
        (
            ma.Rs485MotionCommand(motor_id=1, position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0),
            V43,
            "RS485 motion mode command exists only in V4.4",
        ),
    ],
)
def test_a_command_the_revision_lacks_is_refused(
    command: ma.MyActuatorCommand, revision: ma.Revision, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        check_available(command, revision)
    with pytest.raises(ValueError, match=message):
        encode_request(command, revision=revision)
    other = V43 if revision is V44 else V44
    assert encode_request(command, revision=other) == command.encode()  # encode() itself is revision-free


def test_encode_request_needs_a_revision_enum() -> None:
    with pytest.raises(ValueError, match="is not a Revision"):
        encode_request(ma.MotorStop(), revision="V4_4")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("decode", "can_id", "data", "revision", "message"),
    [
        (ma.decode_request, 0x141, "90 00 00 00 00 00 00 00", V44, "0x90 .* exists only in V4.3"),
        (ma.decode_request, 0x141, "72 3C F4 01 A0 8C 00 00", V43, "0x72 .* exists only in V4.4"),
        (ma.decode_request, 0x141, "20 08 00 00 01 00 00 00", V43, "index 8 .* exists only in V4.4"),
        (ma.decode_request, 0x300, "79 00 01 00 00 00 00 00", V44, "0x79 CAN-ID setting exists only in V4.3"),
        (ma.decode_reply, 0x241, "90 00 33 08 BE 2C 8B 24", V44, "0x90 .* exists only in V4.3"),
        (
            ma.decode_reply,
            0x241,
            "72 32 64 00 F4 01 2D 00",
            V43,
            r"0x72 status reply \(R2\) exists only in V4\.4",
        ),
        (ma.decode_reply, 0x241, "20 08 00 00 01 00 00 00", V43, "index 8 .* exists only in V4.4"),
        (ma.decode_reply, 0x300, "79 00 01 00 00 00 42 02", V44, "0x79 CAN-ID setting exists only in V4.3"),
        (ma.decode_reply, 0x241, "B5 01 01 58 38 53 32 56", V43, "not printable ASCII"),
    ],
)
def test_decoding_with_the_wrong_revision_is_a_protocol_error(
    decode: object, can_id: int, data: str, revision: ma.Revision, message: str
) -> None:
    with pytest.raises(ProtocolError, match=message):
        decode(can_id, bytes.fromhex(data), revision=revision)  # type: ignore[operator]


def test_layouts_that_differ_decode_by_revision() -> None:
    data = bytes.fromhex("94 00 00 00 4C 1D 00 00")
    assert ma.decode_reply(0x241, data, revision=V44) == ma.SingleTurnAngleReply(angle_deg=75.0)
    # The same bytes under V4.3 read DATA[6..7]: 0°. The revision is a parameter, not a guess.
    assert ma.decode_reply(0x241, data, revision=V43) == ma.CircleAngleReply(angle_deg=0.0)
    request = bytes.fromhex("B5 00 00 00 00 00 00 00")
    assert ma.decode_request(0x141, request, revision=V43) == ma.ReadModel()
    with pytest.raises(ProtocolError, match=r"DATA\[1\] is not 0x01"):
        ma.decode_request(0x141, request, revision=V44)


def test_default_revision_is_v44() -> None:
    assert ma.decode_reply(0x241, bytes.fromhex("94 00 00 00 4C 1D 00 00")) == ma.SingleTurnAngleReply(
        angle_deg=75
    )


# ---- identifiers ----


def test_identifier_selects_the_table() -> None:
    shutdown = bytes.fromhex("80 00 00 00 00 00 00 00")
    assert ma.decode_request(0x280, shutdown) == ma.MotorShutdown()  # broadcast: same data
    assert ma.decode_reply(0x244, shutdown) == ma.Echo(command=ma.MotorShutdown())
    with pytest.raises(ProtocolError, match="0x241 is not a MyActuator request identifier"):
        ma.decode_request(0x241, shutdown)
    with pytest.raises(ProtocolError, match="0x141 is not a MyActuator reply identifier"):
        ma.decode_reply(0x141, shutdown)
    with pytest.raises(ProtocolError, match="only 0x79 is sent on 0x300"):
        ma.decode_request(0x300, shutdown, revision=V43)
    with pytest.raises(ProtocolError, match="only 0x79 replies arrive on 0x300"):
        ma.decode_reply(0x300, shutdown, revision=V43)
    with pytest.raises(ProtocolError, match="0x79 is sent on 0x300"):
        ma.decode_request(0x141, bytes.fromhex("79 00 00 00 00 00 00 02"), revision=V43)
    # 0x79 replies are accepted on 0x300 (as printed) and on 0x240 + ID (§9 item 15).
    read = bytes.fromhex("79 00 01 00 00 00 42 02")
    assert ma.decode_reply(0x300, read, revision=V43) == ma.decode_reply(0x242, read, revision=V43)


def test_errors_name_the_motor_and_the_layout_that_matched() -> None:
    with pytest.raises(ProtocolError) as caught:
        ma.decode_reply(0x243, bytes.fromhex("9A 32 00 02 E5 01 00 00"))
    assert caught.value.motor_id == 3 and caught.value.command == 0x9A
    # 0x79 has two reply layouts (echo of a write, read reply): a bad read reply reports the read layout.
    with pytest.raises(ProtocolError, match="fit none of"):
        ma.decode_reply(0x300, bytes.fromhex("79 00 01 00 00 00 00 00"), revision=V43)
    with pytest.raises(ProtocolError, match=r"motor_id=0 is outside \[1, 32\]"):
        ma.decode_reply(0x300, bytes.fromhex("79 00 00 00 00 00 00 00"), revision=V43)
    with pytest.raises(ValueError, match="is not a Revision"):
        ma.decode_reply(0x241, bytes(8), revision="V4_4")  # type: ignore[arg-type]


def test_motion_reply_must_name_its_identifiers_motor() -> None:
    with pytest.raises(ProtocolError, match="motion reply on 0x502 names motor 1"):
        ma.decode_reply(0x502, bytes.fromhex("01 E6 66 82 EB 55 00 00"))


def test_motion_scales_can_be_passed_explicitly() -> None:
    scales = ma.MotionScales.for_revision(V44, max_torque_nm=10.0)
    command = ma.decode_request(0x401, bytes.fromhex("E6 66 82 E0 52 33 3B 55"), motion_scales=scales)
    assert isinstance(command, ma.MotionCommand)
    assert command.scales is scales
    assert command.torque_ff_nm == pytest.approx(4.168, abs=1e-3)


def test_replies_that_do_not_exist_say_why() -> None:
    with pytest.raises(ProtocolError, match="0xB4 has no reply: the reply is random"):
        ma.decode_reply(0x241, bytes.fromhex("B4 00 00 00 00 00 00 01"))
    with pytest.raises(ProtocolError, match="unknown reply command byte"):
        ma.decode_reply(0x241, bytes.fromhex("9E 00 00 00 00 00 00 00"))
    with pytest.raises(ProtocolError, match="empty reply"):
        ma.decode_reply(0x241, b"")
    assert not expects_reply(ma.SystemReset())
    assert not expects_reply(ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=False))
    assert expects_reply(ma.MotorStop())


def test_where_commands_go() -> None:
    assert arbitration_id(ma.MotorStop(), 3) == 0x143
    assert arbitration_id(ma.MotorStop(), broadcast=True) == 0x280
    assert arbitration_id(ma.SetCanId(motor_id=2)) == 0x300
    motion = ma.MotionCommand(position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0)
    assert arbitration_id(motion, 32) == 0x420
    with pytest.raises(ValueError, match="motor_id is required"):
        arbitration_id(ma.MotorStop())
    with pytest.raises(ValueError, match="no broadcast form"):
        arbitration_id(motion, broadcast=True)
    with pytest.raises(ValueError, match="no 0x280 form"):
        arbitration_id(ma.ReadCanId(), broadcast=True)
    frame = request_frame(ma.ReadStatus2(), 1)
    assert frame == Frame(arbitration_id=0x141, data=bytes.fromhex("9C 00 00 00 00 00 00 00"))
    assert not frame.is_rx
    with pytest.raises(ValueError, match=r"only in V4\.3"):
        request_frame(ma.ReadCanId(), revision=V44)


def test_family_registration() -> None:
    family = get_family("myactuator")
    assert family is ma.FAMILY
    assert family.revisions == (V44, V43) and family.default_revision is V44
    assert family.revision("v4.3") is V43
    assert family.decode_reply(0x241, bytes.fromhex("9C 32 64 00 F4 01 2D 00")) == ma.StatusReply(
        temperature_c=50, current_a=1.0, speed_dps=500, angle_deg=45
    )


# ---- any bytes: a message or ProtocolError ----

OUR_IDS = st.sampled_from([0x141, 0x160, 0x280, 0x300, 0x401, 0x241, 0x260, 0x501, 0x520])
CODES = sorted(set(REQUESTS) | set(REPLIES) | set(NO_REPLY))
payloads = st.one_of(
    can_payloads,
    st.tuples(st.sampled_from(CODES), st.binary(min_size=7, max_size=7)).map(lambda t: bytes([t[0]]) + t[1]),
)
revisions = st.sampled_from(list(ma.Revision))


@given(st.one_of(standard_ids, OUR_IDS), payloads, revisions)
def test_decode_request_takes_any_bytes(can_id: int, data: bytes, revision: ma.Revision) -> None:
    message = decodes_or_protocol_error(ma.decode_request, can_id, data, revision=revision)
    if message is not None:
        assert ma.decode_request(can_id, message.encode(), revision=revision) == message


@given(st.one_of(standard_ids, OUR_IDS), payloads, revisions)
def test_decode_reply_takes_any_bytes(can_id: int, data: bytes, revision: ma.Revision) -> None:
    message = decodes_or_protocol_error(ma.decode_reply, can_id, data, revision=revision)
    if message is not None:
        assert ma.decode_reply(can_id, message.encode(), revision=revision) == message


FIXED_CLASSES = [c for c in message_classes() if issubclass(c, ma.MyActuatorCommand | ma.MyActuatorReply)]


@given(st.sampled_from(FIXED_CLASSES), can_payloads, st.booleans())
def test_every_class_decoder_takes_any_bytes(cls: Any, data: bytes, own_code: bool) -> None:
    if own_code and data and cls.CODE is not None:
        data = bytes([cls.CODE]) + data[1:]
    decodes_or_protocol_error(cls.decode, data)

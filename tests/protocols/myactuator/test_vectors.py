"""Every vector of spec/vectors/myactuator-v4.json (402, CAN and RS485; spec §10) is a test.

Requests: the typed command is built from the physical values the vector states (parsed from its
``decoded`` text, not typed here), encoded, and compared byte for byte with the vector (RS485: the whole
frame ``frame_with_computed_crc``, so the CRC is checked too); the vector's bytes decode back to it.
Replies: the bytes decode to the values the vector states. Echo replies decode to ``Echo`` of the same
example's request.

Uncertain vectors (18, spec §9 items 2-6, 8, 15) are tested with the spec's resolution: ``probable_data``
where given (13 vectors), the §9 rule otherwise. :data:`UNCERTAIN` lists them with the resolution; a test
checks the list is exactly the vectors flagged. Motion-mode vectors have their own tests (their values
depend on the revision's ranges).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from typing import Any

import pytest

from _spec import hexbytes, load_vectors
from servobus.errors import ProtocolError
from servobus.protocols import myactuator as ma
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator import codec as ma_codec
from servobus.protocols.myactuator.codec import arbitration_id, encode_request
from servobus.protocols.myactuator.ids import BROADCAST_ID, ID_SETTING_ID, motor_id_from_reply_id
from servobus.protocols.myactuator.rs485 import decode_rs485_reply, decode_rs485_request, encode_rs485

VECTORS = load_vectors("myactuator-v4")
MOTION = "0x400+ID (motion mode)"


def key(v: dict[str, Any]) -> str:
    """A unique, readable id: source, section, example, command, transport, direction, identifier."""
    ident = v.get("can_id") or v.get("rs485_id")
    where = f"{v['source'][:3]}-{v['section']}-ex{v['example']}"
    return f"{where}-{v['command'][:4]}-{v['transport']}-{v['direction']}-{ident}"


def revision(v: dict[str, Any]) -> ma.Revision:
    # [000] is the V4.4 manual, [002] the V4.3 one.
    return ma.Revision.V4_4 if v["source"].startswith("000") else ma.Revision.V4_3


def body(v: dict[str, Any]) -> bytes:
    """The bytes as the spec resolves them (``probable_data`` if present)."""
    return hexbytes(v.get("probable_data", v["data"]))


def payload(v: dict[str, Any]) -> bytes:
    data = body(v)
    return data[3:] if v["transport"] == "rs485" else data


REQUESTS = [v for v in VECTORS if v["direction"] == "request" and v["command"] != MOTION]
REPLIES = [v for v in VECTORS if v["direction"] == "reply" and v["command"] != MOTION]
MOTION_VECTORS = [v for v in VECTORS if v["command"] == MOTION]
REQUEST_OF = {
    (v["source"], v["section"], v["example"], v["transport"]): v
    for v in VECTORS
    if v["direction"] == "request"
}

ZERO_B3 = "§9.8: the all-zero reply is accepted: Echo(SetCommTimeout(timeout_ms=None))"
#: The vectors flagged uncertain, and the resolution these tests apply (spec §9).
UNCERTAIN: dict[str, str] = {
    "000-2.2.5-ex1-0x31-can-reply-0x241": "§9.2: Data[1] lost; probable_data 31 01 00 00 00 00 C0 3F (echo)",
    "000-2.24.4-ex1-0x72-can-request-0x141": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex1-0x72-rs485-request-0x01": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex1-0x72-can-reply-0x241": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex1-0x72-rs485-reply-0x01": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex2-0x72-can-request-0x141": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex2-0x72-rs485-request-0x01": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex2-0x72-can-reply-0x241": "§9.3: printed DATA[0] 0x73; probable_data 0x72",
    "000-2.24.4-ex2-0x72-rs485-reply-0x01": "§9.3/9.4: 0x73 and D1 lost; probable_data 0x72 with D1 = 0x32",
    "000-2.25.4-ex2-0x73-rs485-reply-0x01": "§9.4: D1 lost; probable_data inserts D1 = 0x32",
    "000-2.32.4-ex2-0xB3-can-reply-0x241": ZERO_B3,
    "000-2.32.4-ex2-0xB3-rs485-reply-0x01": ZERO_B3,
    "000-2.34.5-ex1-0xB5-rs485-reply-0x01": "§9.5: printed D7 0x30; probable_data 0x56 ('X8S2V')",
    "000-4.4-ex1-0x40-can-reply-0x501": "§9.6: printed DATA[2] 0x65; probable_data 0x66 (p = 0xE666)",
    "002-2.31.4-ex2-0xB3-can-reply-0x241": ZERO_B3,
    "002-2.31.4-ex2-0xB3-rs485-reply-0x01": ZERO_B3,
    "002-5.4-ex1-0x40-can-reply-0x501": "§9.6: printed DATA[2] 0x65; probable_data 0x66 (p = 0xE666)",
    "002-7.4-ex2-0x79-rs485-reply-0xCD": "§9.15: ordered rule, DATA[6] = 0 and DATA[7] = 2 -> ID 2",
}


def test_inventory() -> None:
    """The file is the one myactuator-v4.md §10 describes, and every vector reaches a test."""
    assert len(VECTORS) == 402  # §10: "contains **402** vectors"
    assert sum("probable_data" in v for v in VECTORS) == 13  # §10: "13 of them carry `probable_data`"
    # §10: each vector names its transport and that transport's identifier (RS485: with its CRC).
    for v in VECTORS:
        assert v["transport"] in ("can", "rs485"), key(v)
        can = v["transport"] == "can"
        assert ("can_id" in v, "computed_crc" in v) == (can, not can), key(v)
    assert len({key(v) for v in VECTORS}) == len(VECTORS)  # one test id per vector
    assert len(REQUESTS) + len(REPLIES) + len(MOTION_VECTORS) == len(VECTORS)  # nothing excluded


def test_uncertain_list_is_exactly_the_flagged_vectors() -> None:
    assert {key(v) for v in VECTORS if v["uncertain"]} == set(UNCERTAIN)


# ---- values from the vectors' text ----


def unit(name: str) -> Callable[[str], float]:
    pattern = re.compile(rf"(-?\d+(?:\.\d+)?)\s*{re.escape(name)}(?![A-Za-z/])")

    def parse(text: str) -> float:
        found = pattern.search(text)
        assert found, f"no value in {name} in {text!r}"
        return float(found.group(1))

    return parse


def hex_first(text: str) -> int:
    found = re.search(r"0x([0-9A-Fa-f]+)", text)
    assert found, f"no hex value in {text!r}"
    return int(found.group(1), 16)


def decimal_after_equals(text: str) -> int:
    found = re.search(r"(?:^|=\s*)(-?\d+)(?![\dxX.])", text)
    assert found, f"no decimal value in {text!r}"
    return int(found.group(1))


def float_value(text: str) -> float:
    found = re.findall(r"(?<![0-9A-Fa-fx.])-?\d+\.\d+", text)
    assert found, f"no float in {text!r}"
    return float(found[-1])


def quoted(text: str) -> str:
    found = re.search(r"'([^']*)'", text)
    assert found, f"no quoted text in {text!r}"
    return found.group(1)


def percent_or_hex(text: str) -> int:
    return int(unit("%")(text)) if "%" in text else hex_first(text)


def ms_or_leading(text: str) -> int:
    return int(unit("ms")(text)) if re.search(r"\d\s*ms\b", text) else decimal_after_equals(text)


def version_date(text: str) -> int:
    found = re.search(r"=\s*(\d{8})\b", text)
    assert found
    return int(found.group(1))


def reply_identifier_or_id(text: str) -> int:
    # 0x79 read reply: "0x0242 ... the reply identifier 0x240+ID" (CAN) or "ID 2 per the manual" (RS485).
    if "0x240+ID" in text:
        return hex_first(text) - 0x240
    found = re.search(r"\bID (\d+)\b", text) or re.search(r"DATA\[7\] = (\d+)", text)
    assert found
    return int(found.group(1))


#: decoded key -> (attribute, parser). The attribute names are the typed classes' fields.
FIELDS: dict[str, tuple[str, Callable[[str], Any]]] = {
    "index": ("index", hex_first),
    "value": ("value", float_value),
    "Accel": ("acceleration_dps_s", unit("dps/s")),
    "encoder": ("encoder_counts", lambda t: int(unit("pulses")(t))),
    "encoderRaw": ("raw_counts", lambda t: int(unit("pulses")(t))),
    "encoderOffset": ("offset_counts", lambda t: int(unit("pulses")(t))),
    "motorAngle": ("angle_deg", unit("deg")),
    "single_turn_angle": ("angle_deg", unit("deg")),
    "circleAngle": ("angle_deg", unit("deg")),
    "temperature": ("temperature_c", lambda t: int(unit("degC")(t))),
    "MOS_temperature": ("mos_temperature_c", hex_first),
    "brake": ("brake_released", lambda t: hex_first(t) == 1),
    "voltage": ("voltage_v", unit("V")),
    "errorState": ("errors", hex_first),
    "iq": ("current_a", unit("A")),
    "speed": ("speed_dps", unit("dps")),
    "degree": ("angle_deg", unit("deg")),
    "iA": ("phase_a_current_a", unit("A")),
    "iB": ("phase_b_current_a", unit("A")),
    "iC": ("phase_c_current_a", unit("A")),
    "iqControl": ("current_a", unit("A")),
    "maxTorque": ("max_torque_pct", percent_or_hex),
    "speedControl": ("speed_dps", unit("dps")),
    "maxSpeed": ("max_speed_dps", unit("dps")),
    "angleControl": ("angle_deg", unit("deg")),
    "spinDirection": ("direction", hex_first),
    "Feedforward Speed": ("feedforward_speed_pct", lambda t: int(unit("%")(t))),
    "Feedforward Torque": ("feedforward_torque_pct", lambda t: int(unit("%")(t))),
    "runmode": ("mode", hex_first),
    "SysRunTime": ("run_time_ms", lambda t: int(unit("ms")(t))),
    "VersionDate": ("version_date", version_date),
    "CanRecvTime_MS": ("timeout_ms", ms_or_leading),
    "baudrate": ("baud_index", decimal_after_equals),
    "chars": ("text", quoted),
    "chars_per_CAN_row_and_text": ("text", quoted),  # §9.5's resolution of the misprinted RS485 row
    "model": ("model", quoted),
    "command": ("command", hex_first),
    "enable": ("enabled", lambda t: hex_first(t) == 1),
    "interval": ("interval_ms", lambda t: int(unit("ms")(t))),
    "Value": ("value", decimal_after_equals),
    "CANID": ("motor_id", reply_identifier_or_id),
    "RS485ID": ("motor_id", reply_identifier_or_id),
}
#: Keys that do not state a field value, and where they are checked instead.
NOT_FIELDS = {
    "request": "prose: a read request has no fields",
    "broadcast": "prose; the identifier (0x280 / 0xCD) is checked",
    "motor": "checked against the reply identifier",
    "effect": "prose (RAM / ROM)",
    "echo": "checked: the reply equals Echo(request)",
    "printed_reply": "§9.8: checked as Echo(SetCommTimeout(0))",
    "manual_claim": "§9.8: prose",
    "command_byte_printed": "§9.3: the printed 0x73; probable_data is checked",
    "chars_as_printed": "§9.5: the misprint; probable_data is checked",
    "RS485ID_field": "§9.15: prose on the byte layout",
    "meaning_per_this_manual": "test_baud_rate_index_meanings",
    "flag": "a layout constant (DATA[1] = 0x01), checked by encode/decode",
    "wReadWriteFlag": "selects SetCanId / ReadCanId",
}
# Keys whose attribute differs for one class.
RENAMED = {(ma.ReadModelPart, "index"): "part", (ma.ModelPartReply, "index"): "part"}


def can_sibling(v: dict[str, Any]) -> dict[str, Any] | None:
    """The CAN vector of the same example with the same data (§0: DATA is identical on both links)."""
    same = ("source", "section", "example", "direction", "command")
    for other in VECTORS:
        if other["transport"] != "can" or not all(other[k] == v[k] for k in same):
            continue
        if payload(other) == payload(v):
            return other
    return None


def stated_values(v: dict[str, Any], cls: type) -> dict[str, Any]:
    """The field values the vector states. Some RS485 vectors state fewer (0x72/0x73 ex. 2 omit
    maxSpeed): the values of the CAN vector carrying the same data fill in."""
    sibling = can_sibling(v) if v["transport"] == "rs485" else None
    values = stated_values(sibling, cls) if sibling is not None else {}
    for name, text in v["decoded"].items():
        if name in NOT_FIELDS:
            continue
        assert name in FIELDS, f"{key(v)}: no parser for decoded key {name!r}"
        attribute, parse = FIELDS[name]
        values[RENAMED.get((cls, name), attribute)] = parse(text)
    return {name: explicit(cls, name, value) for name, value in values.items()}


def explicit(cls: type, name: str, value: Any) -> Any:
    """A stated raw special value (maxTorque 0, timeout 0) as the explicit None it decodes to."""
    spec = cls.field_specs().get(name) if hasattr(cls, "field_specs") else None
    if (
        isinstance(spec, SpecialZero)
        and spec.explicit
        and value is not None
        and spec.code_of(value) == spec.raw
    ):
        return None
    return value


def request_class(v: dict[str, Any]) -> type:
    code = int(v["command"], 16)
    layouts = [layout for layout in ma_codec.REQUESTS[code] if revision(v) in layout.revisions]
    if code == 0x79:  # two layouts share the byte; the vector says which
        flag = v["decoded"]["wReadWriteFlag"]
        return ma.ReadCanId if re.search(r"1 -> read", flag) else ma.SetCanId
    assert len(layouts) == 1, key(v)
    return layouts[0].message


def check_values(decoded: Any, stated: dict[str, Any], where: str) -> None:
    assert stated, f"{where}: the vector states no value"
    for attribute, value in stated.items():
        actual = getattr(decoded, attribute)
        if isinstance(value, float):
            assert actual == pytest.approx(value, abs=1e-6), f"{where}: {attribute}"
        else:
            assert actual == value, f"{where}: {attribute} is {actual!r}, the vector says {value!r}"


# ---- requests ----


@pytest.mark.parametrize("v", REQUESTS, ids=key)
def test_request_vector(v: dict[str, Any]) -> None:
    cls = request_class(v)
    command = cls(**stated_values(v, cls))
    rev = revision(v)
    assert encode_request(command, revision=rev) == payload(v)
    if v["transport"] == "can":
        can_id = int(v["can_id"], 16)
        assert ma.decode_request(can_id, payload(v), revision=rev) == command
        if can_id == BROADCAST_ID:
            assert arbitration_id(command, broadcast=True) == can_id
        elif can_id == ID_SETTING_ID:
            assert arbitration_id(command) == can_id
        else:
            assert arbitration_id(command, can_id - 0x140) == can_id
    else:
        frame = hexbytes(v["frame_with_computed_crc"])
        rs485_id = int(v["rs485_id"], 16)
        assert frame == body(v) + hexbytes(v["computed_crc"])
        assert encode_rs485(rs485_id, command, revision=rev) == frame
        assert decode_rs485_request(frame, revision=rev) == (rs485_id, command)


# ---- replies ----


def _is_echo(v: dict[str, Any]) -> bool:
    return (
        "echo" in v["decoded"]
        or "printed_reply" in v["decoded"]
        or ("motor" in v["decoded"] and "echoes" in v["decoded"]["motor"])
    )


@pytest.mark.parametrize("v", REPLIES, ids=key)
def test_reply_vector(v: dict[str, Any]) -> None:
    rev = revision(v)
    if v["transport"] == "can":
        can_id = int(v["can_id"], 16)
        reply = ma.decode_reply(can_id, payload(v), revision=rev)
        motor_id = motor_id_from_reply_id(can_id) if can_id != ID_SETTING_ID else None
    else:
        frame = hexbytes(v["frame_with_computed_crc"])
        assert frame == body(v) + hexbytes(v["computed_crc"])
        motor_id, reply = decode_rs485_reply(frame, revision=rev)
        assert motor_id == int(v["rs485_id"], 16)
        assert encode_rs485(motor_id, reply) == frame
    assert reply.encode() == payload(v)
    if "motor" in v["decoded"]:
        assert f"ID {motor_id} " in v["decoded"]["motor"]
    if _is_echo(v):
        request = REQUEST_OF[(v["source"], v["section"], v["example"], v["transport"])]
        expected = ma.Echo(command=request_class(request)(**stated_values(request, request_class(request))))
        if "printed_reply" in v["decoded"]:  # §9.8: the all-zero reply printed for a 1000 ms request
            expected = ma.Echo(command=ma.SetCommTimeout.protection_off())
            assert "all-zero" in v["decoded"]["printed_reply"]
        assert reply == expected
        return
    check_values(reply, stated_values(v, type(reply)), key(v))
    if "errorState" in v["decoded"]:
        for name in reply.errors.names():  # type: ignore[attr-defined]
            assert name.lower().replace("_", " ") in v["decoded"]["errorState"]


# ---- motion mode ----


def motion(v: dict[str, Any]) -> dict[str, str]:
    decoded: dict[str, str] = v["decoded"]
    return decoded


@pytest.mark.parametrize("v", [m for m in MOTION_VECTORS if m["direction"] == "request"], ids=key)
def test_motion_request_vector(v: dict[str, Any]) -> None:
    """E6 66 82 E0 52 33 3B 55 under the vector's revision: [002] with V4.3's ranges; [000] with V4.4's
    (its example still uses ±12.5 rad, so that range is passed explicitly, §5.6)."""
    text, data, rev = motion(v), payload(v), revision(v)
    scales = ma.MotionScales.for_revision(rev)
    command = ma.decode_request(int(v["can_id"], 16), data, revision=rev)
    assert isinstance(command, ma.MotionCommand) and command.scales == scales
    assert "1.021" in text["v_des"] and command.velocity_rad_s == pytest.approx(1.02198, abs=1e-5)
    assert "10.012" in text["kp"] and command.kp == pytest.approx(10.012, abs=1e-3)
    if rev is ma.Revision.V4_3:
        assert "10.0002" in text["p_des"] and command.position_rad == pytest.approx(10.0002, abs=1e-4)
        assert "= 1.0" in text["kd"] and command.kd == pytest.approx(1.0, abs=1e-3)
        assert "10.004" in text["t_ff"] and command.torque_ff_nm == pytest.approx(10.004, abs=1e-3)
        as_stated = ma.MotionCommand(
            position_rad=10.0, velocity_rad_s=1.02198, kp=10.0, kd=1.0, torque_ff_nm=10.0, scales=scales
        )
    else:
        assert "10.053" in text["p_des"] and command.position_rad == pytest.approx(10.053, abs=1e-3)
        assert "= 10" in text["kd"] and command.kd == pytest.approx(10.0, abs=1e-3)
        assert "0.416" in text["t_ff"] and command.torque_ff_nm / scales.t_max_nm == pytest.approx(
            0.416, abs=1e-3
        )
        example = dataclasses.replace(scales, p_max_rad=12.5)
        assert ma.MotionCommand.decode(data, example).position_rad == pytest.approx(10.0002, abs=1e-4)
        as_stated = ma.MotionCommand(
            # t_ff: "0.416 x MaxTorque" is truncated (0.41685); with the default 24 N·m, 10 N·m is 0xB55.
            position_rad=10.0,
            velocity_rad_s=1.02198,
            kp=10.0,
            kd=10.0,
            torque_ff_nm=10.0,
            scales=example,
        )
    assert as_stated.encode() == data
    assert arbitration_id(as_stated, 1) == int(v["can_id"], 16)


@pytest.mark.parametrize("v", [m for m in MOTION_VECTORS if m["direction"] == "reply"], ids=key)
def test_motion_reply_vector(v: dict[str, Any]) -> None:
    """§9.6: the printed DATA[2] 0x65 contradicts the table's own 0xE666; probable_data is used."""
    rev = revision(v)
    reply = ma.decode_reply(int(v["can_id"], 16), payload(v), revision=rev)
    assert isinstance(reply, ma.MotionReply) and reply.motor_id == 1
    assert reply.encode() == payload(v)
    scales = ma.MotionScales.for_revision(rev)
    assert reply.velocity_rad_s == pytest.approx(1.02198, abs=1e-5)
    assert reply.torque_nm == pytest.approx(2901 * 2 * scales.t_max_nm / 4095 - scales.t_max_nm)
    assert reply.position_rad == pytest.approx(0xE666 * 2 * scales.p_max_rad / 65535 - scales.p_max_rad)
    printed = ma.decode_reply(int(v["can_id"], 16), hexbytes(v["data"]), revision=rev)
    assert isinstance(printed, ma.MotionReply)
    assert round((printed.position_rad + scales.p_max_rad) * 65535 / (2 * scales.p_max_rad)) == 0xE665


# ---- what the printed bytes of the uncertain vectors do ----


def test_printed_bytes_of_uncertain_vectors() -> None:
    by_key = {key(v): v for v in VECTORS}
    # §9.2: the 0x31 reply as printed is 7 bytes.
    with pytest.raises(ProtocolError, match="expected 8 data bytes, got 7"):
        ma.decode_reply(0x241, hexbytes(by_key["000-2.2.5-ex1-0x31-can-reply-0x241"]["data"]))
    # §9.3: the 0x72 examples as printed are TF (0x73) frames.
    printed = hexbytes(by_key["000-2.24.4-ex1-0x72-can-request-0x141"]["data"])
    assert isinstance(ma.decode_request(0x141, printed), ma.PositionTorqueFeedforward)
    # §9.4: the RS485 rows without D1 are not 13-byte frames.
    short = hexbytes(by_key["000-2.25.4-ex2-0x73-rs485-reply-0x01"]["data"])
    assert len(short) == 10
    # §9.5: printed as-is, the model reads "X8S20".
    misprint = hexbytes(by_key["000-2.34.5-ex1-0xB5-rs485-reply-0x01"]["data"])[3:]
    assert ma.decode_reply(0x241, misprint) == ma.ModelPartReply(part=1, text="X8S20")


def rate(text: str, link: str) -> int | None:
    found = re.search(rf"{link} (\d+) ?(K|M)?bps", text)
    if found is None:
        assert f"{link} invalid" in text, text
        return None
    return int(found.group(1)) * {"K": 1000, "M": 1_000_000, None: 1}[found.group(2)]


def test_baud_rate_index_meanings() -> None:
    """§4.34 / §8 item 7: the codec's meanings are [002]'s; [000]'s examples swap the CAN rates of 0 and 1."""
    checked = 0
    for v in (v for v in REQUESTS if v["command"] == "0xB4" and v["transport"] == "can"):
        setting = ma.BAUD_RATE_INDEXES[payload(v)[7]]
        text = v["decoded"]["meaning_per_this_manual"]
        if revision(v) is ma.Revision.V4_3:
            assert (rate(text, "RS485"), rate(text, "CAN")) == (setting.rs485_bps, setting.can_bps), text
            checked += 1
        elif payload(v)[7] in (0, 1):
            assert rate(text, "CAN") != setting.can_bps, text
    assert checked == 3

"""Every vector of spec/vectors/lk-v2.json as a test: typed message <-> exact bytes, on the right id.

Requests: the typed command built from the vector's decoded (physical) values encodes to exactly
the vector's bytes, and the bytes decode back to it. Replies: the bytes decode to the stated values
and re-encode to themselves. The identifier is the vector's ``can_id`` or, where the manual gives
none, the one its ``can_id_rule`` names — checked against ``ids``.

Uncertain vectors and the resolution applied (spec §10):

* 0x44 V2.36 replies ``44 05 01 ..`` / ``44 05 00 ..`` — DATA[7] is lost in the OCR text (A14);
  resolution: NULL (0x00), and like every NULL byte ignored on decode.

Vectors with ``decode_conflict`` (W5, W6: 0xA8 maxSpeed, A2): the bytes are certain; the codec reads
maxSpeed at 1 dps/LSB (both manuals' text), so 3600 counts are 3600 dps; the example's annotation
reads the same 3600 counts as 36.00 dps. Both readings are asserted on the raw count.

No vector is excluded: all 43 are LK CAN frames of this codec (``EXCLUDED`` stays empty, checked).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import pytest

from _spec import hexbytes, load_vectors, vector_id
from servobus.errors import ProtocolError
from servobus.protocols import Message, lk
from servobus.protocols.lk import ParamResult, Revision, ids
from servobus.protocols.lk.codec import REQUESTS, encode_request, reply_frame, request_frame

VECTORS = load_vectors("lk-v2")
DIALECTS = {"v2.36": Revision.V2_36, "v2.35": Revision.V2_35}
EXCLUDED: dict[str, str] = {}  # vector id -> reason; none: every vector is an LK frame of this codec


def _ids(vectors: list[dict[str, Any]]) -> list[str]:
    # vector_id() needs "id" or transport/section fields; fixed frames repeat across dialects/directions.
    return [f"{vector_id(v)}-{v['dialect']}-{v['command']}-{v['direction']}-{v['data'][:5]}" for v in vectors]


Builder = Callable[[dict[str, Any], Revision], Message]


def _fixed_request(code: int) -> Builder:
    return lambda decoded, revision: REQUESTS[revision][code]()


REQUEST_BUILDERS: dict[int, Builder] = {
    **{
        code: _fixed_request(code)
        for code in (0x9A, 0x9B, 0x9C, 0x9D, 0x80, 0x81, 0x88, 0x90, 0x18, 0x19, 0x92, 0x94, 0x95)
    },
    0x8C: lambda d, r: lk.BrakeControl(action=lk.BrakeAction(int(d["brake_byte"]["raw"], 16))),
    0xA2: lambda d, r: lk.SpeedControlV235(speed_dps=d["speedControl"]["value"]),
    0x40: lambda d, r: lk.ReadParam(param=lk.ParamId(int(d["ParamID"]["raw"], 16))),
    # maxSpeed at 1 dps/LSB (spec A2): the raw count is the value in dps.
    0xA8: lambda d, r: lk.IncrementalPositionSpeed(
        increment_deg=d["angleIncrement"]["value"], max_speed_dps=float(d["maxSpeed"]["raw"])
    ),
    0x44: lambda d, r: lk.SaveSettings(),
}
REPLY_BUILDERS: dict[int, Builder] = {
    **{code: (lambda c: lambda d, r: lk.EchoReply(command=c))(code) for code in (0x80, 0x81, 0x88, 0x95)},
    0x44: lambda d, r: lk.SaveSettingsReply(
        result=ParamResult.SUCCESS if d["save_flag"]["raw"] == 1 else ParamResult.FAILURE
    ),
}


def can_id_of(vector: dict[str, Any], revision: Revision) -> int:
    """The vector's identifier, or motor 1's under its can_id_rule (checked against ids.py)."""
    if vector["direction"] == "request":
        expected_base = ids.request_id(1) - 1
    else:
        expected_base = ids.reply_id(1, revision) - 1
    if vector["can_id"] is not None:
        can_id = int(vector["can_id"], 16)
        assert can_id - expected_base in range(1, 33)
        return can_id
    base = int(re.match(r"(0x[0-9A-F]+)\+ID", vector["can_id_rule"])[1], 16)  # type: ignore[index]
    assert base == expected_base, vector["can_id_rule"]
    return base + 1


def test_the_vector_file_is_handled_in_full() -> None:
    # spec lk-v2.md §12: two kinds of vector; the worked examples are its W1-W6.
    assert {v["kind"] for v in VECTORS} == {"worked-example", "fixed-frame-from-table"}
    assert sorted(v["id"] for v in VECTORS if v["kind"] == "worked-example") == [f"W{i}" for i in range(1, 7)]
    assert EXCLUDED == {}
    for vector in VECTORS:
        builders = REQUEST_BUILDERS if vector["direction"] == "request" else REPLY_BUILDERS
        assert int(vector["command"], 16) in builders, vector
        assert vector["dialect"] in DIALECTS
        assert vector["transport"] == "can"


@pytest.mark.parametrize("vector", VECTORS, ids=_ids(VECTORS))
def test_vector(vector: dict[str, Any]) -> None:
    revision = DIALECTS[vector["dialect"]]
    data = hexbytes(vector["data"])
    code = int(vector["command"], 16)
    can_id = can_id_of(vector, revision)
    if vector["direction"] == "request":
        command = REQUEST_BUILDERS[code](vector["decoded"], revision)
        assert encode_request(command, revision=revision) == data
        assert lk.decode_request(can_id, data, revision=revision) == command
        frame = request_frame(command, motor_id=ids.motor_id_from_request_id(can_id), revision=revision)
        assert frame.arbitration_id == can_id
        assert frame.data == data
    else:
        reply = REPLY_BUILDERS[code](vector["decoded"], revision)
        assert lk.decode_reply(can_id, data, revision=revision) == reply
        assert reply.encode() == data
        assert reply_frame(reply, motor_id=1, revision=revision).arbitration_id == can_id


CONFLICTS = [v for v in VECTORS if v.get("decode_conflict")]


@pytest.mark.parametrize("vector", CONFLICTS, ids=_ids(CONFLICTS))
def test_decode_conflict_both_readings_of_the_same_count(vector: dict[str, Any]) -> None:
    # Spec §10 A2: text 1 dps/LSB (chosen) vs example annotation 0.01 dps/LSB; the count is certain.
    command = lk.decode_request(0x141, hexbytes(vector["data"]), revision=Revision.V2_35)
    assert isinstance(command, lk.IncrementalPositionSpeed)
    raw = vector["decoded"]["maxSpeed"]["raw"]
    assert command.max_speed_dps == raw == 3600
    assert vector["decoded"]["maxSpeed"]["per_manual_text_1dps_per_LSB"] == f"{command.max_speed_dps:.0f} dps"
    annotation = vector["decoded"]["maxSpeed"]["per_example_annotation_0.01dps_per_LSB"]
    assert annotation == f"{command.max_speed_dps * 0.01:.2f} dps"
    assert command.increment_deg == vector["decoded"]["angleIncrement"]["value"]


def test_w3_read_as_v236_is_an_undefined_zero_torque_limit() -> None:
    # W3's note: under the V2.36 layout DATA[2..3] is iqControl, which this V2.35 frame sets to 0. Neither
    # manual defines a limit of 0 (spec §4.11), so the V2.36 layout refuses it (issue 19).
    (w3,) = [v for v in VECTORS if v.get("id") == "W3"]
    expected = w3["decoded"]["if_decoded_as_v2.36_(001)"]
    assert expected["iqControl_torque_limit_raw"] == 0
    with pytest.raises(ProtocolError, match=r"iqControl 0, which is not defined by the manuals"):
        lk.decode_request(0x141, hexbytes(w3["data"]), revision=Revision.V2_36)


UNCERTAIN = [v for v in VECTORS if v["uncertain"]]


def test_uncertain_vectors_are_the_ones_the_note_lists() -> None:
    assert [(v["command"], v["direction"], v["dialect"]) for v in UNCERTAIN] == [
        ("0x44", "reply", "v2.36"),
        ("0x44", "reply", "v2.36"),
    ]


@pytest.mark.parametrize("vector", UNCERTAIN, ids=_ids(UNCERTAIN))
def test_uncertain_data7_is_a_null_byte_ignored_on_decode(vector: dict[str, Any]) -> None:
    # Spec A14: DATA[7] lost in the OCR text; resolution NULL. Whatever it holds, the flag decides.
    data = hexbytes(vector["data"])
    assert data[7] == 0x00
    for last in (0x00, 0x5A, 0xFF):
        reply = lk.decode_reply(0x181, data[:7] + bytes([last]), revision=Revision.V2_36)
        assert isinstance(reply, lk.SaveSettingsReply)
        assert reply.ok is (vector["decoded"]["save_flag"]["raw"] == 1)

"""The simulated MyActuator motor against myactuator-v4.md and the manuals.

Requests are built and replies read with the family codec (the host's side), so every test is also a
round trip through the protocol's second implementation. Manual [000] is V4.4, [002] is V4.3.
This file: every request vector from the device side, manual reply bytes, addressing and revisions.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from _spec import hexbytes, load_vectors, vector_id
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.codec import NO_REPLY
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_ID,
    RS485_BROADCAST_ID,
    motion_reply_id,
    reply_id,
)
from servobus.protocols.myactuator.rs485 import decode_rs485_reply, encode_rs485
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.sim.plant import PlantParams
from test_layering import violations

from ._myactuator import TURNAROUND, ask, frame_for

VECTORS = [v for v in load_vectors("myactuator-v4") if v["direction"] == "request"]
BROADCAST_MOTORS = (1, 2, 3, 4)  # the manuals' multi-motor examples use ids 1..4 (§1.3)


def _revision(vector: dict[str, Any]) -> ma.Revision:
    return ma.Revision.V4_4 if vector["source"].startswith("000") else ma.Revision.V4_3


def _request_bytes(vector: dict[str, Any]) -> bytes:
    return hexbytes(vector.get("probable_data", vector["data"]))


def _code(vector: dict[str, Any]) -> int | None:
    return None if vector["command"].startswith("0x400") else int(vector["command"], 16)


# The reply class each command byte gets (§2's table), by revision where the layout differs.
_ECHO = {0x20, 0x31, 0x32, 0x43, 0x63, 0x77, 0x78, 0x80, 0x81, 0xB3}
_R2 = {0x9C, 0xA1, 0xA2, 0xA4, 0xA8, 0xA9, 0x72, 0x73}
_REPLY_CLASS: dict[int, type[Any]] = {
    0x30: ma.PidReply,
    0x42: ma.AccelerationReply,
    0x60: ma.EncoderPositionReply,
    0x61: ma.EncoderRawReply,
    0x62: ma.EncoderOffsetReply,
    0x64: ma.ZeroOffsetReply,
    0x70: ma.RunModeReply,
    0x90: ma.SingleTurnEncoderReply,
    0x92: ma.MultiTurnAngleReply,
    0x9A: ma.Status1Reply,
    0x9D: ma.Status3Reply,
    0xA6: ma.SingleTurnStatusReply,
    0xB1: ma.RunTimeReply,
    0xB2: ma.VersionDateReply,
}
_BY_REVISION: dict[tuple[int, ma.Revision], type[Any]] = {
    (0x94, ma.Revision.V4_4): ma.SingleTurnAngleReply,
    (0x94, ma.Revision.V4_3): ma.CircleAngleReply,
    (0xB5, ma.Revision.V4_4): ma.ModelPartReply,
    (0xB5, ma.Revision.V4_3): ma.ModelReply,
}


def _expected(code: int | None, data: bytes, revision: ma.Revision) -> type[Any] | None:
    """The reply class the manual documents for this request, None where it says there is none."""
    if code is None:
        return ma.MotionReply
    if code in NO_REPLY:
        return None
    if code in _ECHO or (code == 0x79 and data[2] == 0):
        return ma.Echo
    if code == 0x79:
        return ma.CanIdReply
    if code in _R2:
        return ma.StatusReply
    return _REPLY_CLASS.get(code) or _BY_REVISION[(code, revision)]


def test_the_vectors_cover_both_manuals_both_transports_and_every_no_reply_command() -> None:
    assert {(_revision(v), v["transport"]) for v in VECTORS} == {
        (r, t) for r in ma.Revision for t in ("can", "rs485")
    }
    assert {_code(v) for v in VECTORS} >= set(NO_REPLY)


@pytest.mark.parametrize("vector", [v for v in VECTORS if v["transport"] == "can"], ids=vector_id)
def test_can_request_vector_gets_the_documented_reply_on_the_right_id(vector: dict[str, Any]) -> None:
    revision, data, code = _revision(vector), _request_bytes(vector), _code(vector)
    can_id = int(vector["can_id"], 16)
    broadcast = can_id in (BROADCAST_ID, ID_SETTING_ID)
    motors = [MyActuatorMotor(i, revision=revision) for i in (BROADCAST_MOTORS if broadcast else (1,))]
    expected = _expected(code, data, revision)
    for motor in motors:
        emissions = motor.receive(Frame(arbitration_id=can_id, data=data), 0.25)
        assert motor.counters["accepted"] == 1
        if expected is None:  # §4.28 0x76, §4.34 0xB4, §4.36 0xB6
            assert emissions == []
            continue
        (emission,) = emissions
        assert emission.ready_s == pytest.approx(0.25 + TURNAROUND, abs=1e-12)
        if code is None:
            expected_id = motion_reply_id(motor.motor_id)
        elif can_id == ID_SETTING_ID:
            expected_id = ID_SETTING_ID  # the 0x79 examples print the reply on 0x300 (§4.38)
        else:
            expected_id = reply_id(motor.motor_id)  # 0x280 too: each motor on its own id (§1.3)
        frame = emission.frame
        assert frame.arbitration_id == expected_id and len(frame.data) == 8
        reply = ma.decode_reply(frame.arbitration_id, frame.data, revision=revision)
        assert isinstance(reply, expected)
        if code is not None:
            assert frame.data[0] == code
        if expected is ma.Echo:
            assert frame.data == data  # §0: the reply DATA equals the request DATA
        if isinstance(reply, ma.MotionReply):
            assert reply.motor_id == motor.motor_id


@pytest.mark.parametrize("vector", [v for v in VECTORS if v["transport"] == "rs485"], ids=vector_id)
def test_rs485_request_vector_gets_the_documented_reply_frame(vector: dict[str, Any]) -> None:
    revision, code = _revision(vector), _code(vector)
    frame = hexbytes(vector["frame_with_computed_crc"])
    id_byte = int(vector["rs485_id"], 16)
    ids = BROADCAST_MOTORS if id_byte == RS485_BROADCAST_ID else (1,)
    fronts = [MyActuatorRs485Motor(MyActuatorMotor(i, revision=revision)) for i in ids]
    expected = _expected(code, frame[3:11], revision)
    for front in fronts:
        out = front.receive_bytes(frame, 0.5)
        assert front.counters["frames"] == 1 and front.motor.counters["accepted"] == 1
        if expected is None:
            assert out == []
            continue
        (emission,) = out
        assert emission.ready_s == pytest.approx(0.5 + TURNAROUND, abs=1e-12)
        motor_id, reply = decode_rs485_reply(emission.data, revision=revision)
        # §1.3: every motor answers a 0xCD frame with its own id; 0x79 keeps 0xCD (§4.38).
        assert motor_id == (RS485_BROADCAST_ID if code == 0x79 else front.motor.motor_id)
        assert isinstance(reply, expected)
        assert emission.data[3] == code
        if expected is ma.Echo:
            assert emission.data[3:11] == frame[3:11]


# ---- manual reply bytes the simulator reproduces exactly ----


def _manual_reply(source: str, command: str, transport: str, example: int = 1) -> bytes:
    for v in load_vectors("myactuator-v4"):
        if (v["source"][:3], v["command"], v["transport"], v["direction"], v["example"]) == (
            source,
            command,
            transport,
            "reply",
            example,
        ):
            return hexbytes(v.get("probable_data", v["data"]))
    raise LookupError((source, command, transport, example))


def test_default_parameters_read_back_as_in_the_manual_examples() -> None:
    motor = MyActuatorMotor(1)
    # §4.1 example: current KP = 1.0; §4.4 example: 10000 dps/s.
    (pid,) = motor.receive(frame_for(motor, ma.ReadPid(index=ma.PidIndex.CURRENT_KP)), 0.0)
    assert pid.frame.data == _manual_reply("000", "0x30", "can")
    accel = ma.ReadAcceleration(index=ma.AccelIndex.POSITION_ACCELERATION)
    (acc,) = motor.receive(frame_for(motor, accel), 0.0)
    assert acc.frame.data == _manual_reply("000", "0x42", "can")


@pytest.mark.parametrize("revision", list(ma.Revision), ids=str)
def test_model_reply_matches_the_manual_for_each_revision(revision: ma.Revision) -> None:
    motor = MyActuatorMotor(1, revision=revision)  # default model "X8S2V10", the manuals' example
    if revision is ma.Revision.V4_3:
        (e,) = motor.receive(frame_for(motor, ma.ReadModel()), 0.0)
        assert e.frame.data == _manual_reply("002", "0xB5", "can")
        return
    parts = [ask(motor, ma.ReadModelPart(part=p), 0.0, ma.ModelPartReply) for p in (1, 2, 3)]
    (e,) = motor.receive(frame_for(motor, ma.ReadModelPart(part=1)), 0.0)
    assert e.frame.data == _manual_reply("000", "0xB5", "can")
    assert ma.join_model(parts) == "X8S2V10"


def test_version_date_reply_and_the_revision_rule() -> None:
    motor = MyActuatorMotor(1, revision=ma.Revision.V4_3, version_date=20220206)
    (e,) = motor.receive(frame_for(motor, ma.ReadVersionDate()), 0.0)
    assert e.frame.data == _manual_reply("002", "0xB2", "can")  # B2 00 00 00 2E 89 34 01
    for revision in ma.Revision:
        reply = ask(MyActuatorMotor(1, revision=revision), ma.ReadVersionDate(), 0.0, ma.VersionDateReply)
        assert reply.revision() is revision
    with pytest.raises(ValueError, match="another revision"):
        MyActuatorMotor(1, revision=ma.Revision.V4_4, version_date=20220206)


def test_can_id_read_reply_matches_both_manual_examples() -> None:
    """[002] §4/§7: motor 2 answers the 0x79 read with 0x0242 on CAN and DATA[7] = 2 on RS485."""
    motor = MyActuatorMotor(2, revision=ma.Revision.V4_3)
    read = ma.ReadCanId()
    (e,) = motor.receive(Frame(arbitration_id=ID_SETTING_ID, data=read.encode()), 0.0)
    assert (e.frame.arbitration_id, e.frame.data) == (0x300, _manual_reply("002", "0x79", "can", 2))
    front = MyActuatorRs485Motor(MyActuatorMotor(2, revision=ma.Revision.V4_3))
    (out,) = front.receive_bytes(encode_rs485(RS485_BROADCAST_ID, read), 0.0)
    assert out.data[:11] == _manual_reply("002", "0x79", "rs485", 2)


# ---- addressing, revisions, ignored frames ----


def test_a_motor_ignores_frames_that_are_not_its_own_and_counts_why() -> None:
    v44 = MyActuatorMotor(5)
    v43 = MyActuatorMotor(5, revision=ma.Revision.V4_3)
    status = ma.ReadStatus2().encode()
    cases = [
        (v44, Frame(arbitration_id=0x146, data=status), "ignored_id"),
        (v44, Frame(arbitration_id=0x245, data=status), "ignored_id"),  # a reply, even its own id
        (v44, Frame(arbitration_id=0x145, data=status, is_extended_id=True), "ignored_kind"),
        (v44, Frame(arbitration_id=0x145, data=status[:7]), "undecodable"),  # DLC is always 8 (§1.1)
        (v44, Frame(arbitration_id=0x145, data=bytes([0x9B]) + bytes(7)), "undecodable"),  # undefined code
        (v44, Frame(arbitration_id=0x145, data=bytes([0x20, 9]) + bytes(6)), "undecodable"),  # no index 9
        # Commands only the other revision has (§8 items 1-3, 6, 13): a V4.4 motor does not know them.
        (v44, Frame(arbitration_id=0x145, data=ma.ReadSingleTurnEncoder().encode()), "other_revision"),
        (v44, Frame(arbitration_id=0x300, data=ma.ReadCanId().encode()), "other_revision"),
        (v44, Frame(arbitration_id=0x145, data=ma.ReadModel().encode()), "other_revision"),
        (v43, Frame(arbitration_id=0x145, data=bytes.fromhex("72 3C F4 01 A0 8C 00 00")), "other_revision"),
        (
            v43,
            Frame(arbitration_id=0x145, data=ma.FunctionControl.error_auto_recovery(True).encode()),
            "other_revision",
        ),
    ]
    for motor, frame, counter in cases:
        before = motor.counters[counter]
        assert motor.receive(frame, 0.0) == []
        assert motor.counters[counter] == before + 1, (frame, counter)
    assert v44.counters["accepted"] == v43.counters["accepted"] == 0
    assert v43.feedforward_pct is None and not v43.enabled
    # A V4.3 firmware reads only DATA[0] of 0xB5 (its request is all NULL): V4.4's indexed request
    # gets the single-frame model, which a V4.4 host then fails to decode as a ModelPartReply.
    (e,) = v43.receive(Frame(arbitration_id=0x145, data=ma.ReadModelPart(part=1).encode()), 0.0)
    assert isinstance(ma.decode_reply(0x245, e.frame.data, revision=ma.Revision.V4_3), ma.ModelReply)


def test_id_change_takes_effect_after_a_restart() -> None:
    """0x20 index 5 (both) and 0x79 (V4.3): saved to ROM, used after reboot (§1.4, §4.37)."""
    motor = MyActuatorMotor(3)
    ask(motor, ma.FunctionControl.set_can_id(9), 0.0, ma.Echo)
    assert ask(motor, ma.ReadStatus2(), 0.01, ma.StatusReply)  # still id 3
    motor.reboot(0.02)
    assert motor.motor_id == 9
    assert motor.receive(Frame(arbitration_id=0x143, data=ma.ReadStatus2().encode()), 0.03) == []
    (e,) = motor.receive(Frame(arbitration_id=0x149, data=ma.ReadStatus2().encode()), 0.04)
    assert e.frame.arbitration_id == 0x249

    v43 = MyActuatorMotor(1, revision=ma.Revision.V4_3)
    (echo,) = v43.receive(Frame(arbitration_id=0x300, data=ma.SetCanId(motor_id=2).encode()), 0.0)
    assert echo.frame.arbitration_id == 0x300 and echo.frame.data == ma.SetCanId(motor_id=2).encode()
    v43.reboot(0.1)
    (read,) = v43.receive(Frame(arbitration_id=0x300, data=ma.ReadCanId().encode()), 0.2)
    reply = ma.decode_reply(0x300, read.frame.data, revision=ma.Revision.V4_3)
    assert isinstance(reply, ma.CanIdReply) and reply.motor_id == 2


def test_invalid_construction_is_refused() -> None:
    for kwargs in (
        {"motor_id": 0},
        {"motor_id": 33},
        {"motor_id": 1, "turnaround_s": -1e-6},
        {"motor_id": 1, "revision": ma.Revision.V4_3, "model": "X8S2V10-LONG"},  # 7 characters on V4.3
        {"motor_id": 1, "model": "X" * 16},  # 15 on V4.4
        {"motor_id": 1, "rated_current_a": 0.0},
    ):
        with pytest.raises(ValueError):
            MyActuatorMotor(**kwargs)


def test_the_device_model_is_sans_io() -> None:
    src = Path(__file__).resolve().parents[3] / "src" / "servobus" / "sim" / "devices"
    for path in sorted(src.glob("myactuator*.py")):
        assert violations(path.read_text()) == [], path.name


def test_plant_defaults_can_be_replaced() -> None:
    motor = MyActuatorMotor(1, plant_params=PlantParams(ambient_c=50.0, supply_v=48.5))
    reply = ask(motor, ma.ReadStatus1(), 0.0, ma.Status1Reply)
    # §4.14's worked example values: 50 °C, 48.5 V, brake command not in effect at power-up.
    assert (reply.temperature_c, reply.voltage_v, reply.brake_released) == (50, 48.5, False)

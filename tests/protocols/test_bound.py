"""One contract over every family, through ``Family.bind()`` only (protocols/_bound.py).

For every command class of every family, on every link the family has: encode it with the bound codec,
hand the frame (through the link's framing on serial links) to the simulator's device for that family,
and check what comes back: each reply is classified REPLY with exactly the key ``reply_key`` promised
(or nothing comes back when it promised None), and decodes through the bound codec to the same reply
the family's own decoder gives. The simulator is written from the device side of the same manuals, so
this is the host<->device pair of style.md, run through the one interface the Bus uses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servobus import Frame
from servobus.errors import ProtocolError
from servobus.protocols import FrameKind, check_bus, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.rs485 import decode_modbus_reply
from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.rs485 import decode_rs485_reply, encode_rs485
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor

from .hollow import _strategies as hs
from .lk import _strategies as ls
from .myactuator import _strategies as ms

MOTOR = 3


@dataclass(frozen=True)
class Case:
    family: str
    link: str
    options: dict[str, Any]
    device: Callable[[], Any]  # a fresh simulated device (CAN Device or SerialDevice)
    commands: dict[str, st.SearchStrategy[Any]]  # class name -> commands of that class


def _ma_commands(revision: ma.Revision, link: str) -> dict[str, st.SearchStrategy[Any]]:
    out = {}
    for cls in ms.message_classes():
        if not issubclass(cls, ma.MyActuatorCommand | ma.MotionCommand) or cls.REVISIONS.isdisjoint(
            {revision}
        ):
            continue
        if link == "rs485" and cls in (ma.ActiveReply, ma.MotionCommand):
            continue
        strategy = (
            ms._motion_command(ma.MOTION_SCALES[revision])
            if cls is ma.MotionCommand
            else ms.message_strategy(cls)
        )
        out[cls.__name__] = strategy.filter(lambda m: m.unavailable_reason(revision) is None)
    return out


def _lk_commands(model: lk.LkModel) -> dict[str, st.SearchStrategy[Any]]:
    out = {}
    for cls, case in ls.COMMANDS.items():
        if (
            cls is lk.MultiMotorTorque
            or not issubclass(cls, lk.LkCommand)
            or model.revision not in cls.REVISIONS
        ):
            continue
        allowed = getattr(cls, "MOTOR_TYPES", {}).get(model.revision)
        if allowed is not None and model.motor_type not in allowed:
            continue
        strategy = case.strategy
        if "encoder_bits" in getattr(cls, "__dataclass_fields__", {}):
            strategy = strategy.filter(lambda m: m.encoder_bits == model.encoder_bits)
        if "motor_type" in getattr(cls, "__dataclass_fields__", {}):
            strategy = strategy.filter(lambda m: m.motor_type is model.motor_type)
        out[cls.__name__] = strategy
    return out


def _hollow_commands(link: str) -> dict[str, st.SearchStrategy[Any]]:
    default = ho.DEFAULT_MODEL if hasattr(ho, "DEFAULT_MODEL") else None
    fd = {"FdCommand": hs.fd_commands().filter(lambda m: m.model == default)}
    pi = {"PiMultiplier": hs.pi_multipliers}
    if link == "rs485":
        return fd
    if link == "modbus":
        return {**fd, "ModbusRead": st.just(ho.ModbusRead(slave_id=MOTOR))}
    if link == "canfd":
        return {**fd, **pi}
    setpoints = hs.setpoints().filter(lambda m: m.model == default)
    increments = hs.incremental_setpoints().filter(lambda m: m.model == default)
    return {
        "Setpoint": setpoints,
        "IncrementalSetpoint": increments,
        "SpecialCommand": hs.special_commands,
        "CanModeSwitch": hs.mode_switches,
        **pi,
    }


CASES = [
    *(
        Case(
            "myactuator",
            "can",
            {"revision": rev},
            lambda rev=rev: MyActuatorMotor(MOTOR, revision=rev),
            _ma_commands(rev, "can"),
        )
        for rev in ma.Revision
    ),
    *(
        Case(
            "myactuator",
            "rs485",
            {"revision": rev},
            lambda rev=rev: MyActuatorRs485Motor(MyActuatorMotor(MOTOR, revision=rev)),
            _ma_commands(rev, "rs485"),
        )
        for rev in ma.Revision
    ),
    *(
        Case(
            "lk",
            "can",
            {"model": model},
            lambda model=model: LkMotor(MOTOR, model=model),
            _lk_commands(model),
        )
        for model in (
            lk.LkModel(),
            lk.LkModel(revision=lk.Revision.V2_35),
            lk.LkModel(motor_type=lk.MotorType.MS),
            lk.LkModel(motor_type=lk.MotorType.MH, encoder_bits=18),
        )
    ),
    Case("hollow", "can", {}, lambda: HollowMotor(MOTOR), _hollow_commands("can")),
    Case("hollow", "canfd", {}, lambda: HollowMotor(MOTOR, fd_enabled=True), _hollow_commands("canfd")),
    Case(
        "hollow",
        "rs485",
        {},
        lambda: HollowConverter([HollowMotor(MOTOR, fd_enabled=True)]),
        _hollow_commands("rs485"),
    ),
    Case(
        "hollow",
        "modbus",
        {},
        lambda: HollowConverter([HollowMotor(MOTOR, fd_enabled=True)], mode=ConverterMode.MODBUS),
        _hollow_commands("modbus"),
    ),
]

PAIRS = [
    pytest.param(
        case, name, id=f"{case.family}-{case.link}-{'-'.join(map(str, case.options.values()))}-{name}"
    )
    for case in CASES
    for name in case.commands
]


def _exchange(codec: Any, device: Any, frame: Frame) -> list[Frame]:
    """What the device sends back for ``frame``, as Frames the codec classifies."""
    if codec.framing is None:
        return [emission.frame for emission in device.receive(frame, 0.0)]
    deframer = codec.framing.deframer()
    out: list[Frame] = []
    for emission in device.receive_bytes(codec.framing.encode(frame), 0.0):
        out += deframer.feed(emission.data)
    return out + deframer.idle()


@pytest.mark.parametrize(("case", "name"), PAIRS)
@settings(
    max_examples=10, deadline=None, suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow]
)
@given(data=st.data())
def test_every_command_round_trips_through_the_device(case: Case, name: str, data: st.DataObject) -> None:
    family = get_family(case.family)
    codec = family.bind(MOTOR, link=case.link, **case.options)
    command = data.draw(case.commands[name])
    frame = codec.encode(command)
    assert isinstance(frame, Frame) and not frame.is_rx
    assert frame.data == _expected_body(case, command)  # the fast encoders are byte-exact
    key = codec.reply_key(command)
    replies = _exchange(codec, case.device(), frame)
    if key is None:
        assert replies == [], f"{command!r} promised no reply"
        return
    assert len(replies) == 1, f"{command!r}: {replies}"
    reply = replies[0]
    assert codec.classify(reply) == (FrameKind.REPLY, key)
    decoded = codec.decode(reply)
    assert decoded == _family_decode(case, reply)
    # Our own frame looped back by an adapter is never a reply.
    echo = Frame(
        arbitration_id=reply.arbitration_id,
        data=reply.data,
        is_fd=reply.is_fd,
        is_serial=reply.is_serial,
        is_rx=False,
    )
    assert codec.classify(echo)[0] is FrameKind.NOT_OURS


def _expected_body(case: Case, command: Any) -> bytes:
    """What the family's own encoders put in the frame (on Modbus: the PDU of the write or read)."""
    if case.link != "modbus":
        return bytes(command.encode())
    if not isinstance(command, ho.ModbusRead):
        command = ho.ModbusWrite(slave_id=MOTOR, command=command)
    return bytes(command.encode()[1:-2])


def _family_decode(case: Case, frame: Frame) -> Any:
    """The family's own (non-bound) decoder for a reply frame."""
    if case.family == "myactuator":
        if case.link == "rs485":
            return decode_rs485_reply(encode_rs485(frame.arbitration_id, frame.data), **case.options)[1]
        return ma.decode_reply(frame.arbitration_id, frame.data, **case.options)
    if case.family == "lk":
        return lk.decode_reply(frame.arbitration_id, frame.data, **case.options)
    if case.link == "modbus":
        assert frame.is_serial
        return decode_modbus_reply(bytes([frame.arbitration_id]) + frame.data + _crc16(frame))
    return ho.decode_reply(frame.arbitration_id, frame.data, is_fd=frame.is_fd or frame.is_serial)


def _crc16(frame: Frame) -> bytes:
    from servobus.core import crc16_modbus

    return crc16_modbus(bytes([frame.arbitration_id]) + frame.data).to_bytes(2, "little")


def test_every_link_of_every_family_is_covered() -> None:
    for name in ("myactuator", "lk", "hollow"):
        family = get_family(name)
        assert {c.link for c in CASES if c.family == name} == set(family.links)
        for link in family.links:
            assert any(c.commands for c in CASES if c.family == name and c.link == link)


# ---- the three decodes issue 13 found missing ----


def test_hollow_fd_reply_decodes_through_family() -> None:
    codec = get_family("hollow").bind(7, link="canfd")
    reply = ho.FdReply(slave_id=7, position_deg=90.0, temperature_c=40, running=True)
    frame = Frame(arbitration_id=100, data=reply.encode(), is_fd=True)
    assert codec.classify(frame) == (FrameKind.REPLY, codec.reply_key(ho.FdCommand(position_deg=0.0)))
    assert codec.decode(frame) == reply


def test_myactuator_rs485_reply_decodes_through_family() -> None:
    codec = get_family("myactuator").bind(2, link="rs485")
    wire = encode_rs485(2, bytes.fromhex("9C 32 64 00 F4 01 2D 00"))
    assert codec.framing is not None
    (frame,) = codec.framing.deframer().feed(wire)
    assert codec.classify(frame) == (FrameKind.REPLY, codec.reply_key(ma.ReadStatus2()))
    assert codec.decode(frame) == ma.StatusReply(
        temperature_c=50, current_a=1.0, speed_dps=500.0, angle_deg=45.0
    )


def test_lk_v235_reply_decodes_and_our_echo_is_not_a_reply() -> None:
    codec = get_family("lk").bind(4, revision="V2_35")
    request = codec.encode(lk.ReadStatus2())
    assert request.arbitration_id == 0x144
    assert codec.classify(request)[0] is FrameKind.NOT_OURS  # our own frame, looped back
    reply = Frame(arbitration_id=0x144, data=bytes.fromhex("9C 32 64 00 F4 01 2D 00"))
    assert codec.classify(reply) == (FrameKind.REPLY, codec.reply_key(lk.ReadStatus2()))
    decoded = codec.decode(reply)
    assert decoded == lk.decode_reply(0x144, reply.data, revision=lk.Revision.V2_35)
    assert decoded.temperature_c == 50 and decoded.speed_dps == 500


def test_lk_v235_clear_errors_waits_for_either_reply_byte() -> None:
    codec = get_family("lk").bind(4, revision="V2_35")
    key = codec.reply_key(lk.ClearErrors())
    for code in (0x9A, 0x9B):
        frame = Frame(arbitration_id=0x144, data=bytes([code]) + bytes(7))
        assert codec.classify(frame) == (FrameKind.REPLY, key)


# ---- streams and error reports (myactuator) ----


def test_stream_and_report_frames_are_classified_as_such_while_a_request_waits() -> None:
    codec = get_family("myactuator").bind(1)
    status = Frame(arbitration_id=0x241, data=bytes.fromhex("9C 32 64 00 F4 01 2D 00"))
    report = Frame(arbitration_id=0x241, data=bytes.fromhex("9A 32 00 01 E5 01 04 00"))
    status_key, report_key = codec.reply_key(ma.ReadStatus2()), codec.reply_key(ma.ReadStatus1())
    pending = {status_key, report_key}
    assert codec.classify(status) == (FrameKind.REPLY, codec.reply_key(ma.ReadStatus2()))
    assert codec.classify(report)[0] is FrameKind.REPLY

    codec.note_sent(ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10))
    codec.note_sent(ma.FunctionControl(index=ma.FunctionIndex.ERROR_REPORTING, value=1))
    kind, key = codec.classify(status)
    assert (kind, key) == (FrameKind.STREAM, status_key) and key in pending
    kind, key = codec.classify(report)
    assert (kind, key) == (FrameKind.REPORT, report_key) and key in pending
    # While it streams, the motor answers only reads of the streamed command (by the stream).
    assert codec.reply_key(ma.ReadStatus2()) == status_key and codec.reply_key(ma.ReadStatus1()) is None
    assert codec.decode(report) == ma.decode_reply(0x241, report.data)

    codec.note_sent(ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=False, interval_ms=10))
    codec.note_sent(ma.FunctionControl(index=ma.FunctionIndex.ERROR_REPORTING, value=0))
    assert codec.classify(status)[0] is FrameKind.REPLY
    assert codec.classify(report)[0] is FrameKind.REPLY


def test_stream_frames_from_the_simulator_are_streams() -> None:
    codec = get_family("myactuator").bind(1)
    motor = MyActuatorMotor(1)
    command = ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10)
    assert codec.reply_key(command) is None
    assert motor.receive(codec.encode(command), 0.0) == []
    codec.note_sent(command)
    frames = [e.frame for t in range(1, 6) for e in motor.poll(t * 0.01)]
    assert len(frames) == 5
    for frame in frames:
        assert codec.classify(frame) == (FrameKind.STREAM, codec.reply_key(ma.ReadStatus2()))
        assert isinstance(codec.decode(frame), ma.StatusReply)


# ---- several families on one bus ----


def test_myactuator_and_lk_v235_motor_1_collide_and_the_error_names_both() -> None:
    a = get_family("myactuator").bind(1)
    b = get_family("lk").bind(1, revision="V2_35")
    with pytest.raises(ValueError, match=r"myactuator motor 1 .* lk motor 1 .*0x141"):
        check_bus([a, b])


def test_myactuator_broadcast_id_is_lk_v235_multi_motor_frame() -> None:
    with pytest.raises(ValueError, match=r"0x280"):
        check_bus([get_family("myactuator").bind(1), get_family("lk").bind(5, revision="V2_35")])


def test_hollow_motor_on_the_host_id_collides() -> None:
    with pytest.raises(ValueError, match=r"hollow motor 100 .*0x064"):
        check_bus([get_family("hollow").bind(1), get_family("hollow").bind(100)])


def test_same_motor_twice_collides() -> None:
    with pytest.raises(ValueError, match="cannot share a bus"):
        check_bus([get_family("lk").bind(2), get_family("lk").bind(2)])


def test_families_that_do_not_collide_share_a_bus() -> None:
    check_bus(
        [
            *(get_family("myactuator").bind(m) for m in range(1, 9)),
            *(get_family("lk").bind(m) for m in range(9, 17)),  # V2.36 replies on 0x180+ID
            *(get_family("hollow").bind(m) for m in range(17, 25)),
        ]
    )


# ---- broadcasts ----


def test_myactuator_broadcast_collects_one_key_per_motor() -> None:
    family = get_family("myactuator")
    motors = [family.bind(m) for m in (1, 2, 5)]
    out = family.broadcast(ma.ReadStatus2(), motors)
    assert out.frame == Frame(arbitration_id=0x280, data=ma.ReadStatus2().encode())
    assert out.replies == {m.motor_id: m.reply_key(ma.ReadStatus2()) for m in motors}
    rs485 = family.broadcast(ma.MotorStop(), [family.bind(m, link="rs485") for m in (1, 2)])
    assert rs485.frame.arbitration_id == 0xCD
    with pytest.raises(ValueError, match="no broadcast form"):
        family.broadcast(ma.SetCanId(motor_id=3), motors)


def test_lk_multi_motor_torque_broadcast() -> None:
    family = get_family("lk")
    motors = [family.bind(m, revision="V2_35") for m in (1, 2, 3, 4)]
    command = lk.MultiMotorTorque(motor_type=lk.MotorType.MG, currents_a=(1.0, 0.0, -1.0, 2.0))
    out = family.broadcast(command, motors)
    assert out.frame.arbitration_id == 0x280 and out.frame.data == command.encode()
    assert out.replies == {
        m.motor_id: m.reply_key(lk.TorqueControl(motor_type=lk.MotorType.MG, current_a=0.0)) for m in motors
    }
    with pytest.raises(ValueError, match=r"V2\.35"):
        family.broadcast(command, [family.bind(1)])


def test_hollow_has_no_broadcast() -> None:
    with pytest.raises(ValueError, match="no broadcast"):
        get_family("hollow").broadcast(ho.Stop(), [get_family("hollow").bind(1)])


# ---- what bind refuses ----


@pytest.mark.parametrize(
    ("family", "kwargs", "match"),
    [
        ("myactuator", {"motor_id": 33}, r"motor_id=33"),
        ("myactuator", {"motor_id": 1, "revision": "V9"}, r"no revision 'V9'"),
        ("myactuator", {"motor_id": 1, "link": "canfd"}, r"no link 'canfd'"),
        ("lk", {"motor_id": 0}, r"motor_id"),
        ("lk", {"motor_id": 1, "link": "rs485"}, r"no link"),
        ("hollow", {"motor_id": 101}, r"motor_id=101"),
    ],
)
def test_bind_refuses_bad_arguments(family: str, kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        get_family(family).bind(**kwargs)


def test_encode_refuses_what_the_link_or_revision_lacks() -> None:
    with pytest.raises(ValueError, match="CAN only"):
        get_family("myactuator").bind(1, link="rs485").encode(
            ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10)
        )
    with pytest.raises(ValueError, match=r"only in V4\.3"):
        get_family("myactuator").bind(1, revision="V4_4").encode(ma.ReadSingleTurnEncoder())
    with pytest.raises(ValueError, match="not a MyActuator command"):
        get_family("myactuator").bind(1).encode(lk.ReadStatus2())
    with pytest.raises(ValueError, match="CAN FD"):
        get_family("hollow").bind(1).encode(ho.FdCommand(position_deg=0.0))
    with pytest.raises(ValueError, match="broadcast"):
        get_family("lk").bind(1, revision="V2_35").encode(
            lk.MultiMotorTorque(motor_type=lk.MotorType.MG, currents_a=(0.0, 0.0, 0.0, 0.0))
        )


def test_decode_of_another_motors_frame_is_a_protocol_error() -> None:
    codec = get_family("myactuator").bind(1)
    other = Frame(arbitration_id=0x242, data=bytes.fromhex("9C 32 64 00 F4 01 2D 00"))
    assert codec.classify(other)[0] is FrameKind.NOT_OURS
    with pytest.raises(ProtocolError, match="motor 1"):
        codec.decode(other)


@pytest.mark.parametrize(
    ("family", "options", "kinds"),
    [
        ("myactuator", {}, {"stop": 0x81, "shutdown": 0x80, "brake": 0x78}),
        ("lk", {}, {"stop": 0x81, "shutdown": 0x80, "brake": 0x8C}),
        ("lk", {"revision": "V2_35"}, {"stop": 0x81, "shutdown": 0x80}),
        ("hollow", {}, {"stop": 0xFD, "shutdown": 0xFD}),
        ("hollow", {"link": "canfd"}, {"stop": None, "shutdown": None}),
    ],
)
def test_safe_commands_encode_for_the_motor_or_are_refused(
    family: str, options: dict[str, Any], kinds: dict[str, int | None]
) -> None:
    codec = get_family(family).bind(3, **options)
    for kind in ("stop", "shutdown", "brake"):
        if kind not in kinds:
            with pytest.raises(ValueError):
                codec.safe_command(kind)
            continue
        frame = codec.encode(codec.safe_command(kind))
        code = kinds[kind]
        if code is None:  # an FD control frame with Run Cmd off
            assert frame.is_fd and frame.data[12] == 0
        else:
            assert frame.data[-1 if family == "hollow" else 0] == code


# ---- what a review found (issue 13 follow-up) ----


def test_motors_on_different_media_cannot_share_a_bus() -> None:
    with pytest.raises(ValueError, match=r"one is on CAN, the other on the hollow-modbus-rtu serial line"):
        check_bus([get_family("myactuator").bind(1), get_family("hollow").bind(2, link="modbus")])
    with pytest.raises(ValueError, match=r"myactuator-rs485 serial line, the other on CAN"):
        check_bus([get_family("myactuator").bind(5, link="rs485"), get_family("lk").bind(5)])


def test_an_lk_command_for_another_encoder_width_is_refused() -> None:
    codec = get_family("lk").bind(1, revision="V2_35")  # 14-bit encoder
    with pytest.raises(ValueError, match="encoder_bits=16 contradicts the motor's 14-bit encoder"):
        codec.encode(lk.WriteEncoderOffset(encoder_bits=16, offset_counts=40000))


def test_a_can_id_change_is_never_broadcast() -> None:
    family = get_family("myactuator")
    with pytest.raises(ValueError, match="every motor would take the same id"):
        family.broadcast(
            ma.FunctionControl(index=ma.FunctionIndex.SET_CAN_ID, value=7), [family.bind(1), family.bind(2)]
        )


def test_only_a_revision_with_0x79_claims_its_reply() -> None:
    frame = Frame(arbitration_id=0x300, data=bytes.fromhex("79 00 01 00 00 00 00 02"))
    assert get_family("myactuator").bind(1, revision="V4_3").classify(frame)[0] is FrameKind.REPLY
    assert get_family("myactuator").bind(1, revision="V4_4").classify(frame)[0] is FrameKind.NOT_OURS


def test_frame_flags_are_stored_as_bools() -> None:
    frame = Frame(arbitration_id=2, data=b"\x9c" + bytes(7), is_serial=1)  # type: ignore[arg-type]
    assert frame.is_serial is True
    assert get_family("myactuator").bind(2, link="rs485").classify(frame)[0] is FrameKind.REPLY

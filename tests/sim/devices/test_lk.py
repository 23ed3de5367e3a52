"""The simulated LK motor (servobus.protocols.lk.sim.device) against the LK spec, from the device side.

Replies are decoded with the codec's host-side ``decode_reply`` of the motor's revision, so every
assertion is also a check that the simulator and the codec agree on the bytes (spec lk-v2.md).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import Any

import pytest

from _spec import hexbytes, load_vectors
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import (
    ErrorState,
    ErrorStateV235,
    LkCommand,
    LkModel,
    LkReply,
    MotorState,
    MotorType,
    ParamId,
    ParamResult,
    Revision,
    SettingParam,
    decode_reply,
)
from servobus.protocols.lk.codec import reply_class, request_frame
from servobus.protocols.lk.ids import reply_id
from servobus.protocols.lk.sim import device as lk_device
from servobus.protocols.lk.sim.device import DEFAULT_CALIBRATION_S, DEFAULT_TURNAROUND_S, LkMotor, RunState
from servobus.protocols.lk.sim.state import LK_PLANT_PARAMS
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import CurrentControl, Off, PlantParams

V236, V235 = Revision.V2_36, Revision.V2_35
DIALECTS = {"v2.36": V236, "v2.35": V235}
VECTORS = load_vectors("lk-v2")
REQUEST_VECTORS = [v for v in VECTORS if v["direction"] == "request"]
# Fixed reply frames of the manuals (echoes, the 0x44 "saved" flag): the motor must send exactly them.
REPLY_BYTES = {
    (DIALECTS[v["dialect"]], int(v["command"], 16)): hexbytes(v["data"])
    for v in VECTORS
    if v["direction"] == "reply" and v["data"] != "44 05 00 00 00 00 00 00"  # the "save failed" one
}


class Rig:
    """One LK motor (or several) on a virtual-clock network, with a host that asks and waits."""

    def __init__(self, revision: Revision, *, motor_id: int = 1, **kwargs: Any) -> None:
        self.model = LkModel(revision=revision, motor_type=kwargs.pop("motor_type", MotorType.MG))
        self.motor = LkMotor(motor_id, model=self.model, **kwargs)
        self.net = SimCanNetwork([self.motor])

    def ask(self, command: LkCommand, motor_id: int | None = None) -> LkReply:
        """Send ``command``; return the one reply, decoded as the host would."""
        replies = self.ask_all(command, self.motor.motor_id if motor_id is None else motor_id)
        assert len(replies) == 1, replies
        return replies[0][1]

    def ask_all(self, command: LkCommand, motor_id: int | None) -> list[tuple[int, LkReply]]:
        self.net.send(request_frame(command, motor_id=motor_id, model=self.model))
        frames = self.net.run_until_idle()
        return [
            (f.arbitration_id, decode_reply(f.arbitration_id, f.data, model=self.model)) for _, f in frames
        ]

    def wait(self, seconds: float) -> None:
        self.net.advance(self.net.now_s + seconds)

    def angle(self) -> float:
        reply = self.ask(lk.ReadMultiTurnAngle())
        assert isinstance(reply, lk.MultiTurnAngleReply)
        return reply.angle_deg

    def status2(self) -> lk.Status2Reply:
        reply = self.ask(lk.ReadStatus2())
        assert isinstance(reply, lk.Status2Reply)
        return reply

    def encoder(self) -> lk.EncoderReply:
        reply = self.ask(lk.ReadEncoder())
        assert isinstance(reply, lk.EncoderReply)
        return reply

    def speed(self, dps: float) -> LkReply:
        """A speed command in the revision's layout (V2.36 with a 20 A torque limit)."""
        if self.model.revision is V236:
            return self.ask(lk.SpeedControl(speed_dps=dps, motor_type=MotorType.MG, current_limit_a=20.0))
        return self.ask(lk.SpeedControlV235(speed_dps=dps))

    def reboot(self) -> None:
        self.motor.reboot(self.net.now_s)


# ---- every request vector, device side ----


def _vector_name(vector: dict[str, Any]) -> str:
    return f"{vector.get('id', vector['kind'])}-{vector['dialect']}-{vector['data'].replace(' ', '')}"


@pytest.mark.parametrize("vector", REQUEST_VECTORS, ids=[_vector_name(v) for v in REQUEST_VECTORS])
def test_every_request_vector_gets_one_reply_of_the_documented_layout(vector: dict[str, Any]) -> None:
    revision = DIALECTS[vector["dialect"]]
    model = LkModel(revision=revision)
    motor = LkMotor(1, model=model)
    can_id = int(vector["can_id"], 16) if vector["can_id"] else 0x141  # null can_id: motor 1
    code = int(vector["command"], 16)

    (emission,) = motor.receive(Frame(arbitration_id=can_id, data=hexbytes(vector["data"])), 0.5)

    # V2.36 answers on 0x180+ID, V2.35 on the request's own 0x140+ID (spec §1.1, D1).
    assert emission.frame.arbitration_id == {V236: 0x181, V235: 0x141}[revision]
    assert emission.frame.arbitration_id == reply_id(1, revision)
    delay = DEFAULT_CALIBRATION_S if code == 0x18 else DEFAULT_TURNAROUND_S  # 0x18: after calibrating
    assert emission.ready_s == pytest.approx(0.5 + delay)
    reply = decode_reply(emission.frame.arbitration_id, emission.frame.data, model=model)
    assert isinstance(reply, reply_class(code, revision))
    assert emission.frame.data[0] == code  # rule 2 (0x9B answered with 0x9B, A4)
    if (revision, code) in REPLY_BYTES:
        assert emission.frame.data == REPLY_BYTES[revision, code]


# ---- identifiers on a bus ----


@pytest.mark.parametrize("revision", [V236, V235])
def test_thirty_two_motors_answer_on_their_reply_ids(revision: Revision) -> None:
    model = LkModel(revision=revision)
    motors = [LkMotor(i, model=model) for i in range(1, 33)]
    net = SimCanNetwork(motors)
    for i in range(1, 33):
        net.send(request_frame(lk.ReadStatus2(), motor_id=i, model=model), 0.0)
    frames = [f for _, f in net.run_until_idle()]
    base = {V236: 0x180, V235: 0x140}[revision]
    assert sorted(f.arbitration_id for f in frames) == [base + i for i in range(1, 33)]
    assert all(
        isinstance(decode_reply(f.arbitration_id, f.data, model=model), lk.Status2Reply) for f in frames
    )
    # On V2.35 every reply is also on a request identifier: still exactly one reply per motor.
    assert [m.counters["replied"] for m in motors] == [1] * 32


def test_v235_reply_on_0x140_id_is_not_taken_for_a_request() -> None:
    model = LkModel(revision=V235)
    one, two = LkMotor(1, model=model), LkMotor(2, model=model)
    net = SimCanNetwork([one, two])
    net.send(request_frame(lk.MotorOff(), motor_id=1, model=model), 0.0)
    frames = [f for _, f in net.run_until_idle()]
    assert frames == [Frame(arbitration_id=0x141, data=bytes([0x80]) + bytes(7))]  # the echo, once
    assert one.counters["received"] == 1  # its own reply never comes back to it
    assert two.counters["ignored_id"] == 2  # the request and the reply, both for motor 1


def test_multi_motor_frame_gets_four_replies_in_ascending_order() -> None:
    model = LkModel(revision=V235)
    motors = [LkMotor(i, model=model) for i in (6, 3, 1, 4, 5, 2)]
    net = SimCanNetwork(motors)
    currents = (1.0, -2.0, 3.0, -4.0)
    net.send(
        request_frame(
            lk.MultiMotorTorque(motor_type=MotorType.MG, currents_a=currents), motor_id=None, model=model
        )
    )
    frames = [f for _, f in net.run_until_idle()]
    assert [f.arbitration_id for f in frames] == [0x141, 0x142, 0x143, 0x144]  # spec §5
    assert all(f.data[0] == 0xA1 for f in frames)
    by_id = {m.motor_id: m for m in motors}
    for motor_id, current in enumerate(currents, start=1):
        control = by_id[motor_id].plant.control
        assert isinstance(control, CurrentControl)
        assert control.current_a == pytest.approx(current, abs=66 / 4096)
    assert by_id[5].counters["ignored_id"] >= 1 and by_id[5].counters["replied"] == 0
    net.advance(net.now_s + 0.01)
    reply = decode_reply(0x142, _ask_raw(net, model, 2).data, model=model)
    assert isinstance(reply, lk.Status2Reply) and reply.current_a == pytest.approx(-2.0, abs=0.05)


def _ask_raw(net: SimCanNetwork, model: LkModel, motor_id: int) -> Frame:
    net.send(request_frame(lk.ReadStatus2(), motor_id=motor_id, model=model))
    (frame,) = [f for _, f in net.run_until_idle()]
    return frame


def test_multi_motor_frame_does_not_exist_on_v236() -> None:
    motor = LkMotor(1, model=LkModel(revision=V236))
    assert motor.receive(Frame(arbitration_id=0x280, data=bytes(8)), 0.0) == []
    assert motor.counters["other_revision"] == 1


# ---- motion ----


@pytest.mark.parametrize("revision", [V236, V235])
@pytest.mark.parametrize("gear_ratio", [1.0, 6.0])
def test_speed_command_moves_the_shaft_and_the_multi_turn_angle_integrates_it(
    revision: Revision, gear_ratio: float
) -> None:
    params = PlantParams(
        **{**{f: getattr(LK_PLANT_PARAMS, f) for f in LK_PLANT_PARAMS.__slots__}, "gear_ratio": gear_ratio}
    )
    rig = Rig(revision, plant_params=params)
    reply = rig.speed(720.0)
    assert isinstance(reply, lk.Status2Reply) and reply.command == 0xA2
    rig.wait(0.5)  # past the acceleration ramp
    first = rig.angle()
    assert rig.status2().speed_dps == pytest.approx(720.0, abs=2.0)  # motor-shaft dps (spec §4.3)
    rig.wait(0.5)
    second = rig.angle()
    elapsed = 0.5 + 0.00044  # the wait plus one request/reply exchange on the wire
    assert second - first == pytest.approx(720.0 * elapsed, abs=1.0)
    # The protocol counts the motor shaft; the plant's output shaft turned 1/ratio of it.
    assert second == pytest.approx(rig.motor.plant.motor_position_deg, abs=0.05)
    assert rig.motor.plant.speed_dps == pytest.approx(720.0 / gear_ratio, rel=0.01)


@pytest.mark.parametrize("revision", [V236, V235])
def test_motor_off_stops_output(revision: Revision) -> None:
    rig = Rig(revision)
    rig.speed(360.0)
    rig.wait(0.3)
    assert rig.ask(lk.MotorOff()).encode() == bytes([0x80]) + bytes(7)  # echo (spec §4.5)
    rig.wait(0.05)
    status = rig.status2()
    assert status.current_a == 0.0 and isinstance(rig.motor.plant.control, Off)
    rig.wait(2.0)
    assert rig.status2().speed_dps == pytest.approx(0.0, abs=2.0)  # coasted down
    if revision is V236:
        report = rig.ask(lk.ReadStatus1())
        assert isinstance(report, lk.Status1Reply) and report.motor_state is MotorState.OFF
        # [001] §5: replies to control commands but does not act, until 0x88.
        assert isinstance(rig.speed(360.0), lk.Status2Reply)
        rig.wait(0.3)
        assert rig.status2().current_a == 0.0 and isinstance(rig.motor.plant.control, Off)
        assert rig.motor.counters["not_executed_off"] == 1
        rig.ask(lk.MotorRun())
    rig.speed(360.0)  # V2.35: a control command runs the motor again at once
    rig.wait(0.3)
    assert rig.status2().speed_dps == pytest.approx(360.0, abs=2.0)


def test_v236_motor_off_clears_the_turn_count() -> None:
    rig = Rig(V236)
    rig.ask(lk.MultiTurnPositionSpeed(angle_deg=800.0, max_speed_dps=2000.0))
    rig.wait(1.5)
    assert rig.angle() == pytest.approx(800.0, abs=0.5)
    rig.ask(lk.MotorOff())
    assert rig.angle() == pytest.approx(80.0, abs=0.5)  # [001] §5: "clear the number of turns"


@pytest.mark.parametrize("revision", [V236, V235])
def test_stop_then_run(revision: Revision) -> None:
    rig = Rig(revision)
    rig.speed(360.0)
    rig.wait(0.3)
    rig.ask(lk.MotorStop())
    rig.wait(0.3)
    assert rig.status2().speed_dps == pytest.approx(0.0, abs=2.0)
    assert rig.motor.state is RunState.STOPPED
    rig.ask(lk.MotorRun())
    rig.wait(0.3)
    if revision is V235:  # [003] §4.18: resumes the control mode held before the stop
        assert rig.status2().speed_dps == pytest.approx(360.0, abs=2.0)
    else:  # [001]: 0x88 is OFF -> ON only; a new control command moves the motor
        assert rig.status2().speed_dps == pytest.approx(0.0, abs=2.0)
        rig.speed(-180.0)
        rig.wait(0.3)
        assert rig.status2().speed_dps == pytest.approx(-180.0, abs=2.0)


@pytest.mark.parametrize("revision", [V236, V235])
@pytest.mark.parametrize(
    ("direction", "expected"),
    [(lk.SpinDirection.CLOCKWISE, 350.0), (lk.SpinDirection.COUNTER_CLOCKWISE, -10.0)],
)
def test_single_turn_target_is_reached_in_the_commanded_direction(
    revision: Revision, direction: lk.SpinDirection, expected: float
) -> None:
    rig = Rig(revision)
    cls = lk.SingleTurnPositionSpeed if revision is V236 else lk.SingleTurnPositionSpeedV235
    rig.ask(cls(angle_deg=350.0, direction=direction, max_speed_dps=1000.0))
    rig.wait(0.05)
    assert math.copysign(1.0, rig.status2().speed_dps) == (1.0 if expected > 0 else -1.0)
    rig.wait(1.5)
    assert rig.angle() == pytest.approx(expected, abs=0.3)
    single = rig.ask(lk.ReadSingleTurnAngle())
    assert single.angle_deg == pytest.approx(350.0, abs=0.3)  # type: ignore[attr-defined]


def test_position_speed_limit_and_increment_from_worked_example() -> None:
    rig = Rig(V235)
    # W5: A8 00 10 0E B8 0B 00 00 = +30 deg, maxSpeed 3600 (1 dps/LSB, spec A2).
    rig.net.send(Frame(arbitration_id=0x141, data=hexbytes("A8 00 10 0E B8 0B 00 00")))
    rig.net.run_until_idle()
    rig.wait(1.0)
    assert rig.angle() == pytest.approx(30.0, abs=0.2)
    rig.ask(lk.MultiTurnPositionSpeed(angle_deg=120.0, max_speed_dps=45.0))
    rig.wait(0.5)
    assert rig.status2().speed_dps == pytest.approx(45.0, abs=2.0)  # limited by maxSpeed


def test_v236_control_parameter_limits_speed_until_reboot() -> None:
    rig = Rig(V236)
    written = rig.ask(lk.WriteControlParam(param=lk.ControlParam.SPEED_LIMIT, value=9000))  # 90 dps
    assert written == lk.ControlParamReply(command=0xC1, param=lk.ControlParam.SPEED_LIMIT, value=9000)
    rig.ask(lk.MultiTurnPosition(angle_deg=3600.0))
    rig.wait(0.5)
    assert rig.status2().speed_dps == pytest.approx(90.0, abs=2.0)
    rig.reboot()  # RAM only (spec §4.19): back to the ROM's Max Speed
    read = rig.ask(lk.ReadControlParam(param=lk.ControlParam.SPEED_LIMIT))
    assert isinstance(read, lk.ControlParamReply) and read.value == 200_000  # 2000 dps, the plant's


def test_v235_acceleration_is_ram_and_limits_the_ramp() -> None:
    rig = Rig(V235)
    assert rig.ask(lk.WriteAcceleration(acceleration_dps2=1000.0)) == lk.AccelerationReply(
        command=0x34, acceleration_dps2=1000.0
    )
    assert rig.ask(lk.ReadAcceleration()) == lk.AccelerationReply(command=0x33, acceleration_dps2=1000.0)
    rig.speed(720.0)
    rig.wait(0.2)
    assert rig.status2().speed_dps == pytest.approx(200.0, abs=10.0)  # 1000 dps/s for 0.2 s
    rig.reboot()
    reply = rig.ask(lk.ReadAcceleration())
    assert (
        isinstance(reply, lk.AccelerationReply)
        and reply.acceleration_dps2 == LK_PLANT_PARAMS.max_acceleration_dps2
    )


def test_v236_brake_holds_the_shaft() -> None:
    rig = Rig(V236)
    assert rig.ask(lk.BrakeControl(action=lk.BrakeAction.ENGAGE)) == lk.BrakeReply(
        state=lk.BrakeState.ENGAGED
    )
    rig.speed(360.0)
    rig.wait(0.3)
    assert rig.angle() == 0.0
    assert rig.ask(lk.BrakeControl(action=lk.BrakeAction.READ)) == lk.BrakeReply(state=lk.BrakeState.ENGAGED)
    rig.ask(lk.BrakeControl(action=lk.BrakeAction.RELEASE))
    rig.wait(0.3)
    assert rig.status2().speed_dps == pytest.approx(360.0, abs=2.0)  # the held command runs


# ---- errors ----


@pytest.mark.parametrize(
    ("revision", "flag"), [(V236, ErrorState.HIGH_VOLTAGE), (V235, ErrorStateV235.OVER_TEMPERATURE)]
)
def test_injected_error_is_reported_and_cleared_only_once_the_condition_ends(
    revision: Revision, flag: ErrorState | ErrorStateV235
) -> None:
    rig = Rig(revision)
    rig.speed(360.0)
    rig.wait(0.3)
    rig.motor.inject_error(flag, rig.net.now_s)
    status = rig.ask(lk.ReadStatus1())
    assert isinstance(status, lk.Status1Reply | lk.Status1ReplyV235)
    assert status.error_state == flag
    rig.wait(2.0)
    assert rig.status2().speed_dps == pytest.approx(0.0, abs=2.0)  # protection: output off
    rig.speed(360.0)
    assert rig.motor.counters["not_executed_fault"] == 1
    # spec §4.2: the flag cannot be cleared while the condition persists.
    cleared = rig.ask(lk.ClearErrors())
    assert isinstance(cleared, lk.Status1Reply | lk.Status1ReplyV235)
    assert cleared.command == 0x9B and cleared.error_state == flag
    rig.motor.end_error(flag, rig.net.now_s)
    assert rig.ask(lk.ReadStatus1()).error_state == flag  # type: ignore[attr-defined] # latched
    cleared = rig.ask(lk.ClearErrors())
    assert cleared.error_state == 0  # type: ignore[attr-defined]
    rig.wait(0.3)
    assert rig.status2().current_a == 0.0  # the trip dropped the command: no restart by itself
    rig.speed(360.0)
    rig.wait(0.3)
    assert rig.status2().speed_dps == pytest.approx(360.0, abs=2.0)


def test_transient_error_stays_latched_until_0x9b_and_v235_has_only_two_flags() -> None:
    rig = Rig(V236)
    rig.motor.inject_error(ErrorState.MOTOR_STALL, 0.0, persistent=False)
    assert rig.ask(lk.ReadStatus1()).error_state == ErrorState.MOTOR_STALL  # type: ignore[attr-defined]
    assert rig.ask(lk.ClearErrors()).error_state == 0  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="does not define"):
        LkMotor(1, model=LkModel(revision=V235)).inject_error(ErrorState.HIGH_VOLTAGE, 0.0)


# ---- zero points: RAM (0x95) and ROM (0x19, V2.35 0x91) ----


def _move_to(rig: Rig, angle_deg: float) -> None:
    rig.ask(lk.MultiTurnPositionSpeed(angle_deg=angle_deg, max_speed_dps=1000.0))
    rig.wait(1.0)
    assert rig.angle() == pytest.approx(angle_deg, abs=0.2)


@pytest.mark.parametrize("revision", [V236, V235])
def test_zero_in_ram_is_lost_at_reboot(revision: Revision) -> None:
    rig = Rig(revision)
    _move_to(rig, 100.0)
    raw = rig.encoder().raw_counts
    assert rig.ask(lk.SetZeroRam()).encode() == bytes([0x95]) + bytes(7)
    assert rig.angle() == pytest.approx(0.0, abs=0.05)
    assert rig.ask(lk.ReadSingleTurnAngle()).angle_deg == pytest.approx(0.0, abs=0.05)  # type: ignore[attr-defined]
    assert rig.encoder().offset_counts == raw
    # [001] §25 (A30): then the motor-stop state; [003] says nothing of the kind.
    assert rig.motor.state is (RunState.STOPPED if revision is V236 else RunState.ON)
    rig.reboot()
    assert rig.encoder().offset_counts == 0  # the ROM zero again
    assert rig.angle() == pytest.approx(100.0, abs=0.2)


@pytest.mark.parametrize("revision", [V236, V235])
def test_zero_in_rom_acts_after_reboot(revision: Revision) -> None:
    rig = Rig(revision)
    _move_to(rig, 100.0)
    raw = rig.encoder().raw_counts
    reply = rig.ask(lk.SetZeroRom())
    assert isinstance(reply, lk.EncoderOffsetReply) and reply.offset_counts == raw
    # spec §4.22: takes effect only after a power cycle.
    assert rig.angle() == pytest.approx(100.0, abs=0.2)
    assert rig.encoder().offset_counts == 0
    rig.reboot()
    assert rig.encoder().offset_counts == raw
    assert rig.angle() == pytest.approx(0.0, abs=0.05)


def test_v235_encoder_offset_acts_at_once() -> None:
    rig = Rig(V235)
    _move_to(rig, 90.0)  # 4096 counts of a 14-bit encoder
    reply = rig.ask(lk.WriteEncoderOffset(offset_counts=1000, encoder_bits=14))
    assert reply == lk.EncoderOffsetReply(command=0x91, encoder_bits=14, offset_counts=1000)
    encoder = rig.encoder()
    assert encoder.offset_counts == 1000
    assert encoder.encoder_counts == (encoder.raw_counts - 1000) % 16384
    assert rig.angle() == pytest.approx(90.0 - 1000 * 360 / 16384, abs=0.2)


# ---- settings: 0x40 / 0x42 / 0x44 ----


def test_v236_setting_reads_back_and_survives_reboot_only_after_0x44() -> None:
    rig = Rig(V236)
    default = rig.ask(lk.ReadSetting(param=SettingParam.MAX_SPEED))
    written = rig.ask(lk.WriteSetting(param=SettingParam.MAX_SPEED, value=12_345))
    assert written == lk.SettingReply(command=0x42, param=SettingParam.MAX_SPEED, value=12_345)
    assert rig.ask(lk.ReadSetting(param=SettingParam.MAX_SPEED)).value == 12_345  # type: ignore[attr-defined]
    rig.reboot()
    assert rig.ask(lk.ReadSetting(param=SettingParam.MAX_SPEED)) == default  # never saved
    rig.ask(lk.WriteSetting(param=SettingParam.MAX_SPEED, value=12_345))
    assert rig.ask(lk.SaveSettings()) == lk.SaveSettingsReply(result=ParamResult.SUCCESS)
    rig.reboot()
    assert rig.ask(lk.ReadSetting(param=SettingParam.MAX_SPEED)).value == 12_345  # type: ignore[attr-defined]
    # At power-up the saved Max Speed became the speed limit the loops use (0xC0 0x20).
    limit = rig.ask(lk.ReadControlParam(param=lk.ControlParam.SPEED_LIMIT))
    assert limit.value == 12_345  # type: ignore[attr-defined]


def test_v236_saved_driver_id_moves_the_motor_after_reboot() -> None:
    rig = Rig(V236, motor_id=3)
    rig.ask(lk.WriteSetting(param=SettingParam.DRIVER_ID, value=7))
    rig.ask(lk.SaveSettings())
    assert rig.ask_all(lk.ReadStatus2(), 3)[0][0] == 0x183  # not before the power cycle
    rig.reboot()
    assert rig.ask_all(lk.ReadStatus2(), 3) == []
    assert rig.ask_all(lk.ReadStatus2(), 7)[0][0] == 0x187


def test_v235_parameters_ram_and_rom() -> None:
    rig = Rig(V235)
    default = rig.ask(lk.ReadParam(param=ParamId.MAX_SPEED))
    ram = rig.ask(lk.WriteParamRam(param=ParamId.MAX_SPEED, value=5_000))
    assert ram == lk.ParamWriteReply(command=0x42, param=ParamId.MAX_SPEED, result=ParamResult.SUCCESS)
    assert rig.ask(lk.ReadParam(param=ParamId.MAX_SPEED)) == lk.ParamReply(
        param=ParamId.MAX_SPEED, value=5_000
    )
    rig.reboot()
    assert rig.ask(lk.ReadParam(param=ParamId.MAX_SPEED)) == default  # RAM: lost at power-off
    rom = rig.ask(lk.WriteParamRom(param=ParamId.MAX_SPEED, value=6_000))
    assert rom == lk.ParamWriteReply(command=0x44, param=ParamId.MAX_SPEED, result=ParamResult.SUCCESS)
    rig.reboot()
    assert rig.ask(lk.ReadParam(param=ParamId.MAX_SPEED)) == lk.ParamReply(
        param=ParamId.MAX_SPEED, value=6_000
    )
    # 60 dps from ROM now limits 0xA3 (Max Speed, spec §4.12; 0.01 dps/LSB inferred).
    rig.ask(lk.MultiTurnPosition(angle_deg=3600.0))
    rig.wait(0.5)
    assert rig.status2().speed_dps == pytest.approx(60.0, abs=2.0)
    refused = rig.ask(lk.WriteParamRam(param=ParamId.MAX_SPEED, value=-1))
    assert refused == lk.ParamWriteReply(command=0x42, param=ParamId.MAX_SPEED, result=ParamResult.FAILURE)


# ---- what the motor ignores, and faults of the simulator ----


def test_unresponsive_motor_acts_but_never_replies() -> None:
    rig = Rig(V236)
    rig.motor.unresponsive = True
    # (A V2.35 0xA2 frame would not do here: read as V2.36 its torque limit 0 is undefined and does
    # not decode, issue 19.)
    assert rig.ask_all(lk.ReadStatus1(), 1) == []
    assert (
        rig.ask_all(lk.SpeedControl(speed_dps=360.0, motor_type=MotorType.MG, current_limit_a=20.0), 1) == []
    )
    rig.wait(0.3)
    assert rig.ask_all(lk.ReadStatus2(), 1) == []
    assert rig.motor.plant.speed_dps == pytest.approx(360.0, rel=0.01)
    assert rig.motor.counters["unanswered"] == 3


@pytest.mark.parametrize(
    ("revision", "frame", "reason"),
    [
        (V236, Frame(arbitration_id=0x142, data=bytes([0x9C]) + bytes(7)), "ignored_id"),
        (V236, Frame(arbitration_id=0x181, data=bytes([0x9C]) + bytes(7)), "ignored_id"),
        (
            V236,
            Frame(arbitration_id=0x141, data=bytes([0x9C]) + bytes(7), is_extended_id=True),
            "ignored_kind",
        ),
        (V236, Frame(arbitration_id=0x141, data=bytes([0x9C, 0, 0])), "undecodable"),
        (V236, Frame(arbitration_id=0x141, data=bytes([0x77]) + bytes(7)), "undecodable"),
        (V236, Frame(arbitration_id=0x141, data=bytes([0x91]) + bytes(7)), "other_revision"),
        (V235, Frame(arbitration_id=0x141, data=bytes([0x8C, 0x01]) + bytes(6)), "other_revision"),
        (V235, Frame(arbitration_id=0x141, data=bytes([0xC0, 0x0A]) + bytes(6)), "other_revision"),
    ],
)
def test_frames_not_for_the_motor_are_ignored_and_counted(
    revision: Revision, frame: Frame, reason: str
) -> None:
    motor = LkMotor(1, model=LkModel(revision=revision))
    assert motor.receive(frame, 0.0) == []
    assert motor.counters[reason] == 1 and motor.counters["replied"] == 0


def test_commands_a_motor_type_lacks_are_answered_but_not_executed() -> None:
    mg = Rig(V236)
    # [001]: 0xA0 is MS only (the codec will not even encode it for MG; the bytes are sent raw).
    mg.net.send(Frame(arbitration_id=0x141, data=bytes([0xA0, 0, 0, 0, 0xF4, 0x01, 0, 0])))
    (reply,) = mg.net.run_until_idle()
    assert isinstance(decode_reply(0x181, reply[1].data, revision=V236), lk.Status2Reply)
    assert isinstance(mg.motor.plant.control, Off) and mg.motor.counters["not_implemented"] == 1
    ms = Rig(V236, motor_type=MotorType.MS)
    ms.net.send(Frame(arbitration_id=0x141, data=bytes([0xA1, 0, 0, 0, 0x10, 0, 0, 0])))  # [001]: not MS
    (reply,) = ms.net.run_until_idle()
    assert reply[1].data[0] == 0xA1 and ms.motor.counters["not_implemented"] == 1
    status = ms.ask(lk.OpenLoopControl(power_counts=500))
    ms.wait(0.05)
    assert isinstance(status, lk.Status2Reply) and ms.status2().power_counts == 500  # power, not iq


def test_calibration_replies_after_several_seconds_and_is_busy_meanwhile() -> None:
    motor = LkMotor(1, model=LkModel(revision=V236))
    (emission,) = motor.receive(Frame(arbitration_id=0x141, data=bytes([0x18]) + bytes(7)), 1.0)
    assert emission.ready_s == pytest.approx(1.0 + DEFAULT_CALIBRATION_S)
    reply = decode_reply(0x181, emission.frame.data, revision=V236)
    assert isinstance(reply, lk.CalibrationReply) and reply.succeeded
    assert motor.receive(Frame(arbitration_id=0x141, data=bytes([0x9C]) + bytes(7)), 2.0) == []
    assert motor.counters["busy"] == 1
    assert len(motor.receive(Frame(arbitration_id=0x141, data=bytes([0x9C]) + bytes(7)), 4.5)) == 1


def test_constructor_rejects_impossible_motors() -> None:
    for motor_id in (0, 33):
        with pytest.raises(ValueError, match="motor_id"):
            LkMotor(motor_id)
    with pytest.raises(ValueError, match="ParamId"):
        LkMotor(1, model=LkModel(revision=V235), settings={SettingParam.MAX_SPEED: 1})
    with pytest.raises(ValueError, match="max_speed"):
        LkMotor(1, settings={SettingParam.MAX_SPEED: 700_000})


def test_device_modules_are_sans_io() -> None:
    folder = Path(lk_device.__file__).parent
    for path in sorted(folder.glob("lk*.py")):
        tree = ast.parse(path.read_text())
        imported = {
            a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
        }
        imported |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        assert not imported & {"asyncio", "time", "threading", "socket"}, path.name

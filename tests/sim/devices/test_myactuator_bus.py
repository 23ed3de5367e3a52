"""The simulated MyActuator motor on a SimCanNetwork, in virtual time: 0xB3, 0xB6, 0x280, error reports.

The manuals' words each test follows are quoted in ``servobus.protocols.myactuator.sim.device``'s docstring.
"""

from __future__ import annotations

from typing import Any

import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.codec import request_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import Brake, Off, SpeedControl
from servobus.timing import frame_time_s

from .._standins import Sniffer
from ._myactuator import TURNAROUND, frame_for

ErrorFlags = ma.ErrorFlags


def _decoded(received: list[tuple[float, Frame]]) -> list[tuple[float, int, Any]]:
    return [(at, f.arbitration_id, ma.decode_reply(f.arbitration_id, f.data)) for at, f in received]


def _send(network: SimCanNetwork, motor: MyActuatorMotor, command: Any, at: float) -> None:
    network.send(frame_for(motor, command), at)


def _end_of(sniffer: Sniffer, data: bytes, can_id: int) -> float:
    """When the (last) frame with this identifier and data ended on the wire."""
    return [t for t, f in sniffer.seen if f.arbitration_id == can_id and f.data == data][-1]


# ---- 0xB3 communication-interruption protection ----


def test_comm_timeout_cuts_the_output_and_locks_the_brake_at_exactly_the_set_time() -> None:
    motor, other, sniffer = MyActuatorMotor(1), MyActuatorMotor(2), Sniffer()
    network = SimCanNetwork([motor, other, sniffer])
    _send(network, motor, ma.SetCommTimeout(timeout_ms=100), 0.0)
    speed = ma.SpeedControl(speed_dps=200.0)
    _send(network, motor, speed, 0.001)
    for k in range(1, 40):  # traffic for another motor does not keep motor 1 alive
        _send(network, other, ma.ReadStatus2(), 0.01 * k)
    network.advance(0.05)
    assert isinstance(motor.plant.control, SpeedControl) and motor.plant.speed_dps > 0
    last_heard = _end_of(sniffer, speed.encode(), 0x141)
    deadline = last_heard + 0.1
    network.advance(deadline - 1e-9)
    assert not motor.comm_tripped and isinstance(motor.plant.control, SpeedControl)
    network.advance(deadline)
    # "it will cut off the output [and] brake lock" ([000]/[002] 0xB3)
    assert motor.comm_tripped and motor.counters["comm_timeouts"] == 1
    assert isinstance(motor.plant.control, Brake) and isinstance(motor.control, Off)
    network.advance(0.5)
    assert motor.plant.speed_dps == 0.0 and other.counters["comm_timeouts"] == 0  # 0xB3 is per motor

    # A new frame restores communication; the motor reports what happened and runs again.
    _send(network, motor, ma.ReadStatus1(), 0.5)
    _send(network, motor, ma.ReadRunMode(), 0.5)
    replies = {type(r): r for _, _, r in _decoded(network.advance(0.51))}
    assert replies[ma.Status1Reply].brake_released is False
    assert replies[ma.Status1Reply].errors == ErrorFlags.NONE  # the manuals name no error flag for it
    assert replies[ma.RunModeReply].mode == ma.RunMode.SPEED_LOOP  # the tripped loop's mode stays
    assert motor.counters["comm_restored"] == 1 and not motor.comm_tripped
    _send(network, motor, speed, 0.52)
    network.advance(0.6)
    motor.advance(0.6)  # the plant is advanced lazily, when the motor is asked
    assert isinstance(motor.plant.control, SpeedControl) and motor.plant.speed_dps > 0
    assert motor.brake_released  # 0xA2 releases it again
    network.advance(0.52 + 0.1 + 0.01)  # and the protection is armed again
    assert motor.counters["comm_timeouts"] == 2


def test_comm_timeout_zero_keeps_executing_the_last_command() -> None:
    """ "Writing 0 means the protection is not enabled": the motor keeps the current command."""
    motor = MyActuatorMotor(1)
    network = SimCanNetwork([motor])
    _send(network, motor, ma.SetCommTimeout(timeout_ms=50), 0.0)
    _send(network, motor, ma.SetCommTimeout.protection_off(), 0.01)
    _send(network, motor, ma.SpeedControl(speed_dps=50.0), 0.02)
    network.advance(2.0)
    motor.advance(2.0)
    assert motor.next_deadline_s() is None and motor.counters["comm_timeouts"] == 0
    assert motor.plant.speed_dps == pytest.approx(50.0, abs=0.5)


def test_comm_timeout_is_kept_in_rom() -> None:
    """0xB3 example 2: "saved in ROM, kept after power-off"."""
    motor = MyActuatorMotor(1)
    network = SimCanNetwork([motor])
    _send(network, motor, ma.SetCommTimeout(timeout_ms=1000), 0.0)
    network.advance(0.1)
    motor.reboot(0.1)
    assert motor.protection_deadline_s() == pytest.approx(1.1)
    network.advance(1.2)
    assert motor.counters["comm_timeouts"] == 1


# ---- 0xB6 active reply ----


def test_active_reply_streams_at_its_interval_and_the_motor_stops_answering() -> None:
    motor, sniffer = MyActuatorMotor(1), Sniffer()
    network = SimCanNetwork([motor, sniffer])
    enable = ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=20)
    assert enable.encode() == bytes.fromhex("B6 9C 01 02 00 00 00 00")  # 2 x 10 ms
    _send(network, motor, enable, 0.0)
    received = network.advance(0.101)
    origin = _end_of(sniffer, enable.encode(), 0x141)
    frames = _decoded(received)
    assert [r.command for _, _, r in frames] == [ma.StatusCommand.READ_STATUS_2] * 5  # none for 0xB6
    assert {can_id for _, can_id, _ in frames} == {0x241}
    for k, (at, frame) in enumerate(received, start=1):
        assert at == pytest.approx(origin + 0.02 * k + frame_time_s(frame), abs=1e-12)

    # "the motor will not reply after receiving the command": executed, but unanswered.
    _send(network, motor, ma.ReadStatus1(), 0.105)
    _send(network, motor, ma.SpeedControl(speed_dps=150.0), 0.106)
    later = _decoded(network.advance(0.5))
    assert all(
        isinstance(r, ma.StatusReply) and r.command is ma.StatusCommand.READ_STATUS_2 for _, _, r in later
    )
    assert later[-1][2].speed_dps == 150  # the speed command ran; the stream shows it
    assert motor.counters["silenced_by_active_reply"] == 2

    disable = ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=False)
    _send(network, motor, disable, 0.5)
    tail = network.advance(0.6)
    assert all(at < _end_of(sniffer, disable.encode(), 0x141) + 0.02 for at, _ in tail)  # stream stopped
    _send(network, motor, ma.ReadStatus1(), 0.6)
    ((_, can_id, reply),) = _decoded(network.advance(0.7))
    assert can_id == 0x241 and isinstance(reply, ma.Status1Reply)  # answering again


def test_two_streams_run_on_their_own_intervals() -> None:
    """ "More than one command can be specified, and different commands will be cyclically and
    alternately replied according to the set time." Each command keeps its own interval."""
    motor = MyActuatorMotor(1)
    network = SimCanNetwork([motor])
    _send(
        network,
        motor,
        ma.ActiveReply(command=ma.StreamableCommand.ENCODER_POSITION, enabled=True, interval_ms=10),
        0.0,
    )
    _send(
        network,
        motor,
        ma.ActiveReply(command=ma.StreamableCommand.STATUS_1, enabled=True, interval_ms=50),
        0.0,
    )
    frames = _decoded(network.advance(0.2005))
    kinds = [type(r) for _, _, r in frames]
    assert kinds.count(ma.EncoderPositionReply) == 20 and kinds.count(ma.Status1Reply) == 4
    times = [at for at, _, r in frames if isinstance(r, ma.Status1Reply)]
    assert times[1] - times[0] == pytest.approx(0.05, abs=3e-4)  # may wait behind a 0x60 frame


def test_active_reply_stream_has_exact_period_over_many_frames() -> None:
    motor = MyActuatorMotor(1)
    motor.receive(
        frame_for(
            motor, ma.ActiveReply(command=ma.StreamableCommand.MULTI_TURN_ANGLE, enabled=True, interval_ms=30)
        ),
        0.0,
    )
    times: list[float] = []
    while (deadline := motor.next_deadline_s()) is not None and deadline < 3.0:
        times += [e.ready_s for e in motor.poll(deadline)]
    assert times == [pytest.approx(0.03 * k, abs=1e-12) for k in range(1, 100)]
    # A late poll sends one frame, not a burst, and keeps the grid.
    late = motor.poll(3.1)
    assert len(late) == 1 and motor.next_deadline_s() == pytest.approx(3.12, abs=1e-12)
    assert motor.counters["stream_skipped"] == 3


# ---- 0x280 broadcast and the CAN-ID filter ----


def test_broadcast_with_the_filter_off_every_motor_executes_and_replies_on_its_own_id() -> None:
    motors = [MyActuatorMotor(i) for i in (1, 2, 3, 4)]
    network = SimCanNetwork(motors)
    for motor in motors:
        _send(network, motor, ma.SpeedControl(speed_dps=30.0), 0.0)
    network.advance(0.1)
    network.send(request_frame(ma.MotorShutdown(), broadcast=True), 0.1)
    frames = _decoded(network.advance(0.2))
    assert sorted(can_id for _, can_id, _ in frames) == [0x241, 0x242, 0x243, 0x244]
    assert all(r == ma.Echo(command=ma.MotorShutdown()) for _, _, r in frames)
    assert all(isinstance(m.plant.control, Off) for m in motors)


def test_broadcast_with_the_filter_on_is_not_received() -> None:
    """0x20 index 2 value 1: "after enabling, 0x280 cannot be used" ([002] 0x20 example 2)."""
    motors = [MyActuatorMotor(i) for i in (1, 2, 3, 4)]
    network = SimCanNetwork(motors)
    for motor in motors:
        _send(network, motor, ma.FunctionControl.can_id_filter(True), 0.0)
    network.advance(0.01)
    network.send(request_frame(ma.SpeedControl(speed_dps=30.0), broadcast=True), 0.01)
    network.send(request_frame(ma.ReadEncoderPosition(), broadcast=True), 0.01)
    assert network.advance(0.2) == []
    assert all(m.counters["filtered"] == 2 and isinstance(m.plant.control, Brake) for m in motors)
    motors[0].reboot(0.2)  # FLASH: "the value is kept after power-off"
    assert motors[0].ram.can_id_filter
    _send(network, motors[0], ma.FunctionControl.can_id_filter(False), 0.2)
    network.send(request_frame(ma.ReadEncoderPosition(), broadcast=True), 0.21)
    frames = _decoded(network.advance(0.3))
    assert [(can_id, type(r)) for _, can_id, r in frames][-1] == (0x241, ma.EncoderPositionReply)


def test_thirty_two_motors_on_one_bus_each_answer() -> None:
    motors = [MyActuatorMotor(i) for i in range(1, 33)]
    sniffer = Sniffer()
    network = SimCanNetwork([*motors, sniffer])
    for motor in motors:
        _send(network, motor, ma.ReadStatus2(), 0.0)
    received = network.run_until_idle()
    assert sorted(f.arbitration_id for _, f in received) == [0x240 + i for i in range(1, 33)]
    request_end = {f.arbitration_id: t for t, f in sniffer.seen if f.arbitration_id < 0x200}
    for at, frame in received:
        started = at - network.bus.frame_time_s(frame)
        assert started >= request_end[frame.arbitration_id - 0x100] + TURNAROUND - 1e-12
    network.send(request_frame(ma.ReadMultiTurnAngle(), broadcast=True), network.now_s)
    replies = _decoded(network.run_until_idle())
    assert sorted(can_id for _, can_id, _ in replies) == [0x240 + i for i in range(1, 33)]
    assert all(isinstance(r, ma.MultiTurnAngleReply) for _, _, r in replies)
    assert all(m.counters["replied"] == 2 for m in motors)


# ---- 0x20 index 3: automatic 0x9A error reports ----


@pytest.mark.parametrize("reporting", [True, False], ids=["on", "off"])
def test_error_reports_every_100_ms_while_an_error_is_present(reporting: bool) -> None:
    motor, sniffer = MyActuatorMotor(1), Sniffer()
    network = SimCanNetwork([motor, sniffer])
    _send(network, motor, ma.FunctionControl.error_reporting(reporting), 0.0)
    assert len(network.advance(0.2)) == 1  # the echo
    motor.inject_error(ErrorFlags.MOTOR_OVER_TEMPERATURE, 0.2)
    reports = network.advance(0.55)
    motor.clear_error(ErrorFlags.MOTOR_OVER_TEMPERATURE, 0.55)
    after = network.advance(1.0)
    if not reporting:
        assert reports == after == []
        return
    assert after == [] and motor.counters["error_reports"] == 4
    for k, (at, frame) in enumerate(reports):
        assert frame.arbitration_id == 0x241
        assert at == pytest.approx(0.2 + 0.1 * k + frame_time_s(frame), abs=1e-12)
        reply = ma.decode_reply(0x241, frame.data)
        assert isinstance(reply, ma.Status1Reply) and reply.errors == ErrorFlags.MOTOR_OVER_TEMPERATURE


def test_switching_reports_on_while_an_error_is_present_starts_them() -> None:
    motor = MyActuatorMotor(1)
    network = SimCanNetwork([motor])
    motor.inject_error(ErrorFlags.STALL, 0.0)
    assert network.advance(0.3) == []
    _send(network, motor, ma.FunctionControl.error_reporting(True), 0.3)
    frames = _decoded(network.advance(0.65))
    # The first report leaves when reporting is switched on, before the echo's turnaround.
    assert [type(r) for _, _, r in frames] == [ma.Status1Reply, ma.Echo] + [ma.Status1Reply] * 3

"""The simulated MyActuator motor: commands moving the plant, brake, faults, ROM/RAM across restarts.

Spec sections: §4.19-§4.26 (control), §4.29-§4.30 (brake), §4.14 and §7 (errors), §4.1-§4.10, §4.37
(parameters and zero), §5 (motion mode). Manual [000] is V4.4, [002] is V4.3.
"""

from __future__ import annotations

import math

import pytest

from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import RUN_MODE_POWER_UP, MyActuatorMotor
from servobus.sim.plant import Brake, CurrentControl, Impedance, Off, PositionControl, SpeedControl

from ._myactuator import angle, ask, frame_for, status, status1, tell

ErrorFlags = ma.ErrorFlags


def _run_mode(motor: MyActuatorMotor, at: float) -> int:
    return int(ask(motor, ma.ReadRunMode(), at, ma.RunModeReply).mode)


# ---- control commands -> plant ----


def test_speed_command_moves_the_shaft_and_0x92_reads_back_the_integrated_angle() -> None:
    motor = MyActuatorMotor(1)
    reply = ask(motor, ma.SpeedControl(speed_dps=100.0), 0.0, ma.StatusReply)
    assert reply.command is ma.StatusCommand.SPEED_CONTROL and reply.speed_dps == 0  # values at receipt
    assert isinstance(motor.plant.control, SpeedControl)  # 0xA2 releases the brake by itself
    integral, dt = 0.0, 0.001
    for k in range(1, 1001):  # integrate the speeds the motor reports, 1 ms apart
        integral += status(motor, k * dt).speed_dps * dt
    assert status(motor, 1.0).speed_dps == 100
    reported = angle(motor, 1.0)
    # 0x92 is the integral of the speed (0.01° resolution; the 1 dps R2 resolution bounds the sum).
    assert reported == pytest.approx(integral, abs=0.6)
    assert 99.0 < reported < 100.0  # ramp at the 10000 dps/s speed acceleration: 0.5° lost
    assert _run_mode(motor, 1.0) == ma.RunMode.SPEED_LOOP


def test_speed_command_torque_limit_form_caps_the_current() -> None:
    """0xA2 maxTorque (§4.20): % of rated current; 0 or above the stall current: no extra limit."""
    motor = MyActuatorMotor(1, rated_current_a=10.0)
    ask(motor, ma.SpeedControl(speed_dps=1000.0, max_torque_pct=20), 0.0, ma.StatusReply)
    assert motor.plant.control == SpeedControl(speed_dps=1000.0, max_current_a=2.0)
    assert max(abs(status(motor, k * 0.002).current_a) for k in range(1, 50)) <= 2.0
    ask(motor, ma.SpeedControl(speed_dps=10.0, max_torque_pct=None), 0.2, ma.StatusReply)
    assert motor.plant.control == SpeedControl(speed_dps=10.0, max_current_a=None)
    ask(
        motor, ma.SpeedControl(speed_dps=10.0, max_torque_pct=255), 0.3, ma.StatusReply
    )  # 25.5 A < 30 A stall
    assert motor.plant.control == SpeedControl(speed_dps=10.0, max_current_a=25.5)


def test_absolute_and_incremental_position_commands_reach_their_targets() -> None:
    motor = MyActuatorMotor(1)
    ask(motor, ma.AbsolutePositionControl(angle_deg=360.0, max_speed_dps=500.0), 0.0, ma.StatusReply)
    assert max(status(motor, k * 0.05).speed_dps for k in range(1, 20)) <= 500
    assert angle(motor, 3.0) == pytest.approx(360.0, abs=0.05)
    assert _run_mode(motor, 3.0) == ma.RunMode.POSITION_LOOP
    ask(motor, ma.IncrementalPositionControl(angle_deg=-90.0, max_speed_dps=300.0), 3.0, ma.StatusReply)
    assert angle(motor, 5.0) == pytest.approx(270.0, abs=0.05)
    reply = ask(
        motor,
        ma.ForcePositionControl(angle_deg=0.0, max_speed_dps=200.0, max_torque_pct=60),
        5.0,
        ma.StatusReply,
    )
    assert reply.command is ma.StatusCommand.FORCE_POSITION
    assert motor.plant.control == PositionControl(position_deg=0.0, max_speed_dps=200.0, max_current_a=6.0)
    assert angle(motor, 8.0) == pytest.approx(0.0, abs=0.05)


def test_v44_feedforward_commands_position_like_0xa4_and_keep_the_feedforward() -> None:
    motor = MyActuatorMotor(1)
    sf = ma.PositionSpeedFeedforward(angle_deg=90.0, max_speed_dps=400.0, feedforward_speed_pct=10)
    assert ask(motor, sf, 0.0, ma.StatusReply).command is ma.StatusCommand.POSITION_SPEED_FEEDFORWARD
    assert motor.feedforward_pct == 10
    tf = ma.PositionTorqueFeedforward(angle_deg=-90.0, max_speed_dps=400.0, feedforward_torque_pct=-5)
    assert ask(motor, tf, 0.1, ma.StatusReply).command is ma.StatusCommand.POSITION_TORQUE_FEEDFORWARD
    assert motor.feedforward_pct == -5
    assert angle(motor, 2.0) == pytest.approx(-90.0, abs=0.05)


@pytest.mark.parametrize(
    ("direction", "expected"),
    [(ma.SpinDirection.CLOCKWISE, 30.0), (ma.SpinDirection.COUNTER_CLOCKWISE, -330.0)],
    ids=["cw", "ccw"],
)
def test_single_turn_position_goes_the_commanded_way_round(
    direction: ma.SpinDirection, expected: float
) -> None:
    motor = MyActuatorMotor(1)
    command = ma.SingleTurnPositionControl(angle_deg=30.0, max_speed_dps=500.0, direction=direction)
    ask(motor, command, 0.0, ma.SingleTurnStatusReply)
    assert angle(motor, 3.0) == pytest.approx(expected, abs=0.05)
    final = ask(motor, command, 3.0, ma.SingleTurnStatusReply)  # already there: no move
    counts = motor.encoder.counts_per_turn
    # R2-A6 (§3.2): the encoder from the zero within one rotor turn (rotor = 6 x output here).
    wanted = round(expected * 6 / 360 * counts) % counts
    assert abs(final.encoder_counts - wanted) <= 16  # 0.05° output = 0.3° rotor = 14 counts


def test_stop_holds_the_position_and_shutdown_lets_the_shaft_coast() -> None:
    motor = MyActuatorMotor(1)
    ask(motor, ma.SpeedControl(speed_dps=200.0), 0.0, ma.StatusReply)
    tell(motor, ma.MotorStop(), 0.5)
    held = motor.plant.position_deg
    assert isinstance(motor.plant.control, PositionControl)
    motor.plant.external_torque_nm = 5.0  # [002]: "will not move under external force"
    assert status(motor, 1.5).speed_dps == 0
    assert motor.plant.position_deg == pytest.approx(held, abs=1.0)
    tell(motor, ma.MotorShutdown(), 1.5)
    # 0x80 cuts the output; the brake stays released (only 0x78, 0xB3 and power-off lock it).
    assert isinstance(motor.plant.control, Off)
    assert status1(motor, 1.5).brake_released


def test_a1_cannot_release_the_brake_but_0x77_can() -> None:
    """§4.19: "For safety, this command cannot release the brake... Send 0x77 first" (both manuals)."""
    motor = MyActuatorMotor(1)
    ask(motor, ma.TorqueControl(current_a=2.0), 0.0, ma.StatusReply)
    assert isinstance(motor.plant.control, Brake) and motor.counters["brake_locked"] == 1
    assert status(motor, 0.5).speed_dps == 0 and not status1(motor, 0.5).brake_released
    tell(motor, ma.BrakeRelease(), 0.5)
    assert motor.plant.control == CurrentControl(current_a=2.0)
    assert status(motor, 0.6).speed_dps > 0 and status1(motor, 0.6).brake_released
    assert _run_mode(motor, 0.6) == ma.RunMode.CURRENT_LOOP
    tell(motor, ma.BrakeLock(), 0.6)  # §4.30: "the motor cannot run"
    assert status(motor, 0.7).speed_dps == 0 and not status1(motor, 0.7).brake_released


def test_a_motor_without_brake_runs_0xa1_at_once() -> None:
    motor = MyActuatorMotor(1, has_brake=False)
    ask(motor, ma.TorqueControl(current_a=1.0), 0.0, ma.StatusReply)
    assert status(motor, 0.2).current_a == pytest.approx(1.0, abs=0.02)


# ---- motion (MIT) mode ----


def test_motion_mode_applies_the_mit_law_to_the_plant() -> None:
    """§5.1: torque = kp (p_des - p) + kd (v_des - v) + t_ff, output side; reply on 0x500+ID."""
    motor = MyActuatorMotor(4)
    pure_ff = ma.MotionCommand(position_rad=0.0, velocity_rad_s=0.0, kp=0.0, kd=0.0, torque_ff_nm=2.0)
    reply = ask(motor, pure_ff, 0.0, ma.MotionReply)
    assert reply.motor_id == 4
    assert isinstance(motor.plant.control, Impedance)
    after = ask(motor, pure_ff, 0.005, ma.MotionReply)
    torque_code = 24.0 * 2 / 4095  # one t code at ±24 N·m
    assert after.torque_nm == pytest.approx(2.0, abs=torque_code)  # kp = kd = 0: torque = t_ff
    assert motor.plant.current_a == pytest.approx(2.0 / motor.plant.params.torque_constant_nm_per_a, rel=1e-3)

    spring = ma.MotionCommand(position_rad=1.0, velocity_rad_s=0.0, kp=30.0, kd=2.0, torque_ff_nm=0.0)
    ask(motor, spring, 0.01, ma.MotionReply)
    settled = ask(motor, spring, 3.0, ma.MotionReply)
    # At rest the law balances: kp (p_des - p) + kd v_des + t_ff = 0, with the values as the motor
    # decoded them (12-bit v and t cannot carry an exact 0: v_des = 0.011 rad/s, t_ff = 0.006 N·m).
    got = ma.MotionCommand.decode(spring.encode(), motor.motion_scales)
    rest = got.position_rad + (got.kd * got.velocity_rad_s + got.torque_ff_nm) / got.kp
    p_code = 2 * motor.motion_scales.p_max_rad / 65535
    assert settled.position_rad == pytest.approx(rest, abs=p_code)
    assert settled.velocity_rad_s == pytest.approx(0.0, abs=0.03)
    assert angle(motor, 3.0) == pytest.approx(math.degrees(rest), abs=0.006)
    # A load: the spring answers with kp x deflection, as the law says.
    motor.plant.external_torque_nm = 3.0
    loaded = ask(motor, spring, 6.0, ma.MotionReply)
    assert loaded.position_rad - rest == pytest.approx(3.0 / got.kp, abs=0.002)
    assert loaded.torque_nm == pytest.approx(-3.0, abs=0.05)


def test_motion_mode_positions_are_relative_to_the_zero() -> None:
    motor = MyActuatorMotor(1)
    motor.plant.position_deg = 50.0
    ask(motor, ma.WriteCurrentPositionAsZero(), 0.0, ma.ZeroOffsetReply)
    motor.receive(frame_for(motor, ma.SystemReset()), 0.0)
    hold = ma.MotionCommand(position_rad=0.0, velocity_rad_s=0.0, kp=50.0, kd=2.0, torque_ff_nm=0.0)
    assert ask(motor, hold, 0.01, ma.MotionReply).position_rad == pytest.approx(0.0, abs=1e-3)
    ask(motor, hold, 2.0, ma.MotionReply)
    assert motor.plant.position_deg == pytest.approx(50.0, abs=0.05)  # held where the zero is


# ---- errors (§4.14, §7) ----


def test_injected_error_shows_in_0x9a_cuts_the_output_and_control_is_refused() -> None:
    motor = MyActuatorMotor(1)
    ask(motor, ma.SpeedControl(speed_dps=300.0), 0.0, ma.StatusReply)
    motor.inject_error(ErrorFlags.OVER_VOLTAGE | ErrorFlags.MOTOR_OVER_TEMPERATURE, 0.5)
    assert isinstance(motor.plant.control, Off)
    reply = status1(motor, 0.5)
    assert reply.errors == ErrorFlags.OVER_VOLTAGE | ErrorFlags.MOTOR_OVER_TEMPERATURE
    # Output cut, but 0x70 still reports one of the three defined modes (§4.27): the last loop's.
    assert _run_mode(motor, 0.5) == ma.RunMode.SPEED_LOOP
    # §0: control commands run "when the motor has no fault": answered with the status, not executed.
    for command in (
        ma.SpeedControl(speed_dps=100.0),
        ma.TorqueControl(current_a=1.0),
        ma.AbsolutePositionControl(angle_deg=10.0, max_speed_dps=100.0),
        ma.IncrementalPositionControl(angle_deg=10.0, max_speed_dps=100.0),
        ma.ForcePositionControl(angle_deg=10.0, max_speed_dps=100.0, max_torque_pct=50),
        ma.PositionSpeedFeedforward(angle_deg=10.0, max_speed_dps=100.0, feedforward_speed_pct=0),
        ma.PositionTorqueFeedforward(angle_deg=10.0, max_speed_dps=100.0, feedforward_torque_pct=0),
        ma.SingleTurnPositionControl(
            angle_deg=10.0, max_speed_dps=100.0, direction=ma.SpinDirection.CLOCKWISE
        ),
    ):
        ask(motor, command, 0.6, ma.SingleTurnStatusReply if command.code == 0xA6 else ma.StatusReply)
    ask(
        motor,
        ma.MotionCommand(position_rad=1.0, velocity_rad_s=0.0, kp=10.0, kd=1.0, torque_ff_nm=1.0),
        0.6,
        ma.MotionReply,
    )
    assert motor.counters["refused_fault"] == 9
    assert isinstance(motor.plant.control, Off) and status(motor, 2.0).speed_dps == 0
    # Level 2 (§7): recovers when the condition ends; the motor then runs new commands.
    motor.clear_error(ErrorFlags.OVER_VOLTAGE | ErrorFlags.MOTOR_OVER_TEMPERATURE, 2.0)
    assert status1(motor, 2.0).errors == ErrorFlags.NONE
    ask(motor, ma.SpeedControl(speed_dps=100.0), 2.0, ma.StatusReply)
    assert status(motor, 2.5).speed_dps == 100


def test_latched_errors_stay_until_restart_and_v44_index_8_stops_auto_recovery() -> None:
    motor = MyActuatorMotor(1)
    motor.inject_error(ErrorFlags.STALL, 0.0)  # level 1: "not auto-recoverable"
    motor.clear_error(ErrorFlags.STALL, 0.1)
    assert status1(motor, 0.1).errors == ErrorFlags.STALL
    motor.reboot(0.2)
    assert status1(motor, 0.2).errors == ErrorFlags.NONE
    motor.inject_error(ErrorFlags.ENCODER_DATA_ERROR, 0.3)  # condition persists over a restart
    motor.reboot(0.4)
    assert status1(motor, 0.4).errors == ErrorFlags.ENCODER_DATA_ERROR
    motor.clear_error(ErrorFlags.ENCODER_DATA_ERROR, 0.5)
    motor.reboot(0.6)

    tell(motor, ma.FunctionControl.error_auto_recovery(False), 0.7)
    motor.inject_error(ErrorFlags.LOW_VOLTAGE | ErrorFlags.MOTOR_OVER_TEMPERATURE, 0.8)
    motor.clear_error(ErrorFlags.LOW_VOLTAGE | ErrorFlags.MOTOR_OVER_TEMPERATURE, 0.9)
    assert status1(motor, 0.9).errors == ErrorFlags.LOW_VOLTAGE  # index 8 covers voltage and speed only
    v43 = MyActuatorMotor(1, revision=ma.Revision.V4_3)  # no index 8: always recovers
    v43.inject_error(ErrorFlags.LOW_VOLTAGE, 0.0)
    v43.clear_error(ErrorFlags.LOW_VOLTAGE, 0.1)
    assert status1(v43, 0.1).errors == ErrorFlags.NONE


# ---- ROM and RAM ----


def test_pid_ram_write_is_lost_at_restart_and_rom_write_kept() -> None:
    motor = MyActuatorMotor(1)

    def kp(at: float) -> float:
        return ask(motor, ma.ReadPid(index=ma.PidIndex.SPEED_KP), at, ma.PidReply).value

    tell(motor, ma.WritePidRam(index=ma.PidIndex.SPEED_KP, value=1.5), 0.0)
    assert kp(0.0) == 1.5
    motor.reboot(0.1)
    assert kp(0.1) == 0.5  # the default
    tell(motor, ma.WritePidRom(index=ma.PidIndex.SPEED_KP, value=2.25), 0.2)
    assert kp(0.2) == 2.25
    motor.reboot(0.3)
    assert kp(0.3) == 2.25


@pytest.mark.parametrize("revision", list(ma.Revision), ids=str)
def test_rom_saves_while_running_fail_only_on_v44(revision: ma.Revision) -> None:
    """[000]: "the parameters can only be saved to ROM successfully when the motor is disabled";
    [002] has no such rule."""
    motor = MyActuatorMotor(1, revision=revision)
    ask(motor, ma.SpeedControl(speed_dps=10.0), 0.0, ma.StatusReply)
    tell(motor, ma.WritePidRom(index=ma.PidIndex.POSITION_KP, value=4.0), 0.1)
    accel = ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=500)
    tell(motor, accel, 0.1)
    tell(motor, ma.SetCommTimeout(timeout_ms=300), 0.1)  # not in [000]'s list: always saved
    motor.reboot(0.2)
    saved = revision is ma.Revision.V4_3
    pid = ask(motor, ma.ReadPid(index=ma.PidIndex.POSITION_KP), 0.2, ma.PidReply).value
    assert pid == pytest.approx(4.0 if saved else 0.3)  # float32 on the wire
    read = ask(motor, ma.ReadAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION), 0.2, ma.AccelerationReply)
    assert read.acceleration_dps_s == (500 if saved else 10000)
    assert motor.ram.comm_timeout_ms == 300
    assert motor.counters["rom_write_refused"] == (0 if saved else 2)
    tell(motor, accel, 0.2)  # now disabled (output off after the restart): saved on both
    motor.reboot(0.3)
    read = ask(motor, ma.ReadAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION), 0.3, ma.AccelerationReply)
    assert read.acceleration_dps_s == 500


def test_acceleration_setting_shapes_the_speed_ramp() -> None:
    motor = MyActuatorMotor(1)
    tell(motor, ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=1000), 0.0)
    ask(motor, ma.SpeedControl(speed_dps=500.0), 0.0, ma.StatusReply)
    assert status(motor, 0.25).speed_dps == pytest.approx(250, abs=3)  # 1000 dps/s
    assert status(motor, 0.6).speed_dps == 500


def test_zero_writes_take_effect_only_after_a_restart() -> None:
    motor = MyActuatorMotor(1)
    counts = motor.encoder.counts_per_turn
    motor.plant.position_deg = 60.0  # rotor 360°: exactly one encoder turn
    assert ask(motor, ma.ReadEncoderPosition(), 0.0, ma.EncoderPositionReply).encoder_counts == counts
    tell(motor, ma.WriteEncoderZero(offset_counts=1000), 0.0)
    assert ask(motor, ma.ReadEncoderOffset(), 0.0, ma.EncoderOffsetReply).offset_counts == 0  # not yet
    motor.reboot(0.1)
    assert ask(motor, ma.ReadEncoderOffset(), 0.1, ma.EncoderOffsetReply).offset_counts == 1000
    assert ask(motor, ma.ReadEncoderPosition(), 0.1, ma.EncoderPositionReply).encoder_counts == counts - 1000
    assert ask(motor, ma.ReadEncoderRaw(), 0.1, ma.EncoderRawReply).raw_counts == counts

    written = ask(motor, ma.WriteCurrentPositionAsZero(), 0.2, ma.ZeroOffsetReply)
    assert written.offset_counts == counts
    assert angle(motor, 0.2) == pytest.approx((counts - 1000) * 360 / counts / 6, abs=0.01)
    assert motor.receive(frame_for(motor, ma.SystemReset()), 0.3) == []  # §4.28: no reply
    assert angle(motor, 0.3) == 0.0 and motor.counters["resets"] == 1
    run_time = ask(motor, ma.ReadRunTime(), 0.8, ma.RunTimeReply).run_time_ms
    assert run_time == 500  # ms since the reset


def test_multi_turn_is_kept_over_a_restart_unless_saving_is_off_or_cleared() -> None:
    motor = MyActuatorMotor(1)
    motor.plant.position_deg = 150.0  # 2.5 rotor turns
    motor.reboot(0.0)
    assert angle(motor, 0.0) == pytest.approx(150.0, abs=0.01)
    tell(motor, ma.FunctionControl.save_multi_turn(False), 0.0)
    motor.reboot(0.1)  # §4.37 index 4 off: single-turn mode after restart
    assert angle(motor, 0.1) == pytest.approx(30.0, abs=0.01)  # half a rotor turn = 30° output
    tell(motor, ma.FunctionControl.save_multi_turn(True), 0.1)
    motor.plant.position_deg += 120.0
    motor.reboot(0.2)
    assert angle(motor, 0.2) == pytest.approx(150.0, abs=0.01)
    tell(motor, ma.FunctionControl.clear_multi_turn(), 0.2)  # index 1: after restart
    assert angle(motor, 0.2) == pytest.approx(150.0, abs=0.01)
    motor.reboot(0.3)
    assert angle(motor, 0.3) == pytest.approx(30.0, abs=0.01)
    motor.reboot(0.4)  # clearing happens once
    motor.plant.position_deg += 60.0
    assert angle(motor, 0.4) == pytest.approx(90.0, abs=0.01)


def test_reboot_restores_power_up_state() -> None:
    motor = MyActuatorMotor(1)
    tell(motor, ma.FunctionControl.error_reporting(True), 0.0)  # saved: the output is off
    ask(motor, ma.SpeedControl(speed_dps=100.0), 0.0, ma.StatusReply)
    motor.reboot(0.5)
    assert motor.counters["reboots"] == 1
    assert isinstance(motor.plant.control, Brake) and not motor.brake_released  # power-off locks it
    assert _run_mode(motor, 0.5) == RUN_MODE_POWER_UP
    assert motor.ram.error_reporting  # 0x20 values are ROM values
    assert ask(motor, ma.ReadRunTime(), 0.75, ma.RunTimeReply).run_time_ms == 250


def test_unresponsive_motor_acts_but_never_replies() -> None:
    motor = MyActuatorMotor(1)
    motor.unresponsive = True
    assert motor.receive(frame_for(motor, ma.SpeedControl(speed_dps=100.0)), 0.0) == []
    assert (
        motor.receive(
            frame_for(
                motor, ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=10)
            ),
            0.0,
        )
        == []
    )
    assert motor.poll(0.5) == [] and motor.counters["unanswered"] >= 1
    motor.unresponsive = False
    motor.receive(frame_for(motor, ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=False)), 0.5)
    assert status(motor, 0.5).speed_dps == 100
    assert motor.counters["replied"] == 1

"""The simulated hollow-series motor (servobus.protocols.hollow.sim.device) against hollow.md §3-§7 and §13.

Requests are built and replies read with the family codec (the host's side), so every test is also
a round trip through the protocol's second implementation. Network tests run in virtual time.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from _spec import hexbytes, load_vectors
from servobus.frame import Frame
from servobus.protocols.hollow import (
    DEFAULT_HOST_ID,
    DEFAULT_MODEL,
    CanMode,
    CanModeSwitch,
    ControlMode,
    ExtendedReply,
    FdCommand,
    FdReply,
    HollowCommand,
    HollowReply,
    IncrementalSetpoint,
    ModbusReadReply,
    ModbusWriteAck,
    NormalReply,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    Start,
    Stop,
    TransparentReply,
)
from servobus.protocols.hollow.codec import decode_reply_frame, request_frame
from servobus.protocols.hollow.rs485 import decode_modbus_reply
from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import DEFAULT_TURNAROUND_S, HOLLOW_PLANT_PARAMS, HollowMotor
from servobus.sim.canbus import CanBusModel
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import CurrentControl, Off, PlantParams, PositionControl, SpeedControl
from servobus.timing import frame_time_s
from test_layering import violations

from .._standins import Sniffer

HOST = DEFAULT_HOST_ID
TURNAROUND = DEFAULT_TURNAROUND_S
FD_BUS = {"bitrate": 1_000_000, "data_bitrate": 5_000_000}  # A28

# ---- helpers ----


def _setpoint(**overrides: Any) -> Setpoint:
    fields: dict[str, Any] = {"position_deg": 0.0, "speed_rad_s": 0.0, "kp": 0, "kd": 0, "current_a": 2.0}
    return Setpoint(**(fields | overrides))


def _ask(motor: HollowMotor, command: HollowCommand, at: float) -> HollowReply:
    """Deliver ``command`` to ``motor`` at ``at``; return its one reply, decoded by the host codec."""
    emissions = motor.receive(request_frame(motor.motor_id, command), at)
    assert len(emissions) == 1
    frame = emissions[0].frame
    assert frame.arbitration_id == motor.host_id and not frame.is_extended_id
    return decode_reply_frame(frame, model=motor.model)


def _normal(motor: HollowMotor, command: HollowCommand, at: float) -> NormalReply:
    reply = _ask(motor, command, at)
    assert isinstance(reply, NormalReply)
    return reply


def _extended(motor: HollowMotor, command: HollowCommand, at: float) -> ExtendedReply:
    reply = _ask(motor, command, at)
    assert isinstance(reply, ExtendedReply)
    return reply


def _fd(motor: HollowMotor, command: FdCommand, at: float) -> FdReply:
    reply = _ask(motor, command, at)
    assert isinstance(reply, FdReply)
    return reply


def _sender(reply: HollowReply) -> int:
    """The motor id a reply carries: D0 in classic CAN, the Slave ID byte in CAN FD."""
    assert isinstance(reply, NormalReply | ExtendedReply | FdReply)
    return reply.slave_id if isinstance(reply, FdReply) else reply.motor_id


POLL_EXT = IncrementalSetpoint(step_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0)  # A11: a status poll

# ---- every request vector of the manual, from the device side ----

VECTORS = [v for v in load_vectors("hollow") if v["direction"] == "request"]
# Request vectors that are not frames to the motor or its converter's RS-485 modes, and why.
EXCLUDED = {
    "H22": "converter P/D configuration frame: its port and baud rate are not stated (§9.3, A19)",
    "H23": "SLCAN ASCII 'S8\\r' to the USB adapter (§8): tests/sim/test_slcan.py",
    "H24": "SLCAN ASCII 'Y5\\r' to the USB adapter (§8): tests/sim/test_slcan.py",
    "H25": "SLCAN ASCII 'O\\r\\n' to the USB adapter (§8, A38): tests/sim/test_slcan.py",
}
# The reply each request gets from a motor fresh from power-up (normal mode), with its length.
EXPECTED_REPLY: dict[str, tuple[type[object], int]] = {
    "H1": (NormalReply, 6),
    "H2": (NormalReply, 6),
    "H3": (NormalReply, 6),
    "H4": (NormalReply, 6),
    "H5": (NormalReply, 6),
    "H6": (NormalReply, 6),
    "H7": (NormalReply, 6),
    "H8": (NormalReply, 6),
    "H9": (ExtendedReply, 8),  # the switch to extended mode answers in the new format (§5.1 [C])
    "H10": (NormalReply, 6),
    "H11": (NormalReply, 6),
    "H12": (TransparentReply, 21),
    "H14": (ModbusWriteAck, 8),
    "H16": (ModbusReadReply, 37),
    "H18": (TransparentReply, 21),
    "H20": (FdReply, 16),
}
VECTOR_MOTOR = 1  # the examples' motor where the vector leaves the id open


def test_every_request_vector_is_either_answered_or_excluded_on_purpose() -> None:
    assert {v["id"] for v in VECTORS} == set(EXPECTED_REPLY) | set(EXCLUDED)
    assert not set(EXPECTED_REPLY) & set(EXCLUDED)
    assert {v["transport"] for v in VECTORS if v["id"] in EXCLUDED} == {"slcan-ascii", "unspecified"}


@pytest.mark.parametrize("vector", [v for v in VECTORS if v["id"] not in EXCLUDED], ids=lambda v: v["id"])
def test_request_vector_gets_a_reply_of_the_documented_layout(vector: dict[str, Any]) -> None:
    data = hexbytes(vector["data"])
    expected_class, expected_length = EXPECTED_REPLY[vector["id"]]
    transport = vector["transport"]
    if transport in ("can", "canfd"):
        fd = transport == "canfd"
        motor = HollowMotor(VECTOR_MOTOR, fd_enabled=fd)
        frame = Frame(
            arbitration_id=VECTOR_MOTOR,
            data=data,
            is_extended_id="EXTENDED" in vector["can_id"],
            is_fd=fd,
            bitrate_switch=fd,
        )
        emissions = motor.receive(frame, 0.25)
        assert len(emissions) == 1
        assert emissions[0].ready_s == pytest.approx(0.25 + TURNAROUND, abs=1e-12)
        reply_frame = emissions[0].frame
        assert (reply_frame.arbitration_id, reply_frame.is_extended_id, reply_frame.is_fd) == (
            HOST,
            False,
            fd,
        )
        assert len(reply_frame.data) == expected_length
        reply = decode_reply_frame(reply_frame)
        assert isinstance(reply, expected_class)
        assert _sender(reply) == VECTOR_MOTOR
        assert motor.counters["accepted"] == 1
        return
    mode = ConverterMode.TRANSPARENT if transport == "rs485-transparent" else ConverterMode.MODBUS
    converter = HollowConverter([HollowMotor(VECTOR_MOTOR, fd_enabled=True)], mode=mode)
    out = converter.receive_bytes(data, 0.25)
    assert len(out) == 1 and out[0].ready_s > 0.25
    assert len(out[0].data) == expected_length
    if mode is ConverterMode.TRANSPARENT:
        reply_t = TransparentReply.decode(out[0].data)
        assert (reply_t.header_id, reply_t.motor_id) == (HOST, VECTOR_MOTOR)
    else:
        reply_m = decode_modbus_reply(out[0].data)
        assert isinstance(reply_m, expected_class)
        assert reply_m.slave_id == VECTOR_MOTOR


def test_h20_poll_gets_the_manual_reply_h21_byte_for_byte() -> None:
    """[H20] -> [H21]: a stopped torque-mode motor at 34 counts and 30 °C answers exactly the vector."""
    vectors = {v["id"]: v for v in load_vectors("hollow")}
    motor = HollowMotor(1, fd_enabled=True, plant_params=PlantParams(ambient_c=30.0))
    motor.plant.position_deg = 34 * 360.0 / (1 << 20)
    frame = Frame(arbitration_id=1, data=hexbytes(vectors["H20"]["data"]), is_fd=True, bitrate_switch=True)
    (emission,) = motor.receive(frame, 0.0)
    assert emission.frame.data == hexbytes(vectors["H21"]["data"])


# ---- timing and addressing on the simulated bus ----


def test_one_request_one_reply_after_the_turnaround_in_virtual_time() -> None:
    motor = HollowMotor(7)
    network = SimCanNetwork([motor])
    request = request_frame(7, _setpoint(position_deg=10.0))
    network.send(request, 0.0)
    received = network.run_until_idle()
    assert len(received) == 1
    at, reply = received[0]
    # §3: one reply, on the host id, 500 µs after the request has been received (A13).
    assert at == pytest.approx(frame_time_s(request) + TURNAROUND + frame_time_s(reply), abs=1e-12)
    assert reply.arbitration_id == HOST and len(reply.data) == 6 and reply.data[0] == 7


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
def test_thirty_two_motors_each_answer_once_with_their_own_id_after_the_turnaround(fd: bool) -> None:
    motors = [HollowMotor(i, fd_enabled=fd) for i in range(1, 33)]
    sniffer = Sniffer()
    network = SimCanNetwork([*motors, sniffer], bus=CanBusModel(**FD_BUS) if fd else None)
    for i in range(1, 33):
        command: HollowCommand = FdCommand(mode=ControlMode.POSITION) if fd else _setpoint(position_deg=i)
        network.send(request_frame(i, command), 0.0)
    received = network.run_until_idle()

    assert len(received) == 32
    assert {f.arbitration_id for _, f in received} == {HOST}
    replies = [decode_reply_frame(f) for _, f in received]
    ids = [_sender(r) for r in replies]
    assert sorted(ids) == list(range(1, 33))
    assert all(isinstance(r, FdReply if fd else NormalReply) for r in replies)
    request_end = {f.arbitration_id: t for t, f in sniffer.seen if f.arbitration_id != HOST}
    bus = network.bus
    for (at, frame), motor_id in zip(received, ids, strict=True):
        # The reply cannot start before the motor's turnaround has passed (it may wait for the bus).
        started = at - bus.frame_time_s(frame)
        assert started >= request_end[motor_id] + TURNAROUND - 1e-12
    assert all(m.counters["replied"] == 1 for m in motors)
    # Every motor saw the 31 other requests and 31 other replies and ignored them by id (§3).
    assert all(m.counters["ignored_id"] == 62 for m in motors)


def test_a_motor_ignores_frames_that_are_not_its_own_or_not_its_kind() -> None:
    classic = HollowMotor(5)
    fd = HollowMotor(5, fd_enabled=True)
    setpoint = _setpoint().encode()
    not_ours = [
        (classic, Frame(arbitration_id=6, data=setpoint), "ignored_id"),
        (classic, Frame(arbitration_id=5, data=bytes(16), is_fd=True), "ignored_kind"),
        (classic, Frame(arbitration_id=5, data=setpoint[:7]), "undecodable"),  # §3: DLC 8 only
        (classic, Frame(arbitration_id=5, data=b"\x04" + bytes(7), is_extended_id=True), "undecodable"),
        (fd, Frame(arbitration_id=5, data=setpoint), "ignored_kind"),  # classic setpoint to an FD motor
        (fd, Frame(arbitration_id=5, data=bytes(12), is_fd=True), "undecodable"),
        (fd, Frame(arbitration_id=5, data=bytes(8), is_extended_id=True), "ignored_kind"),  # mode switch
        (fd, Frame(arbitration_id=4, data=bytes(16), is_fd=True), "ignored_id"),
    ]
    for motor, frame, counter in not_ours:
        before = motor.counters[counter]
        assert motor.receive(frame, 0.0) == []
        assert motor.counters[counter] == before + 1
    assert classic.counters["accepted"] == fd.counters["accepted"] == 0
    assert not classic.enabled and not fd.enabled


def test_pi_multiplier_frames_are_stored_and_answered_in_both_interfaces() -> None:
    classic = HollowMotor(3)
    pi = PiMultiplier(gain=PiGain.CURRENT_KI, multiplier=0.5)
    # A17: a PI frame of DLC 6 is accepted too.
    short = Frame(arbitration_id=3, data=pi.encode()[:6], is_extended_id=True)
    (emission,) = classic.receive(short, 0.0)
    assert len(emission.frame.data) == 6
    assert classic.pi_multipliers[PiGain.CURRENT_KI] == 0.5
    fd = HollowMotor(3, fd_enabled=True)
    fd_pi = Frame(arbitration_id=3, data=pi.encode(), is_extended_id=True, is_fd=True)
    (emission,) = fd.receive(fd_pi, 0.0)
    assert emission.frame.is_fd and len(emission.frame.data) == 16
    assert fd.pi_multipliers == {**dict.fromkeys(PiGain, 1.0), PiGain.CURRENT_KI: 0.5}


# ---- modes and state (§4, §5, §13) ----


def test_mode_switch_to_extended_gives_8_byte_replies_and_back() -> None:
    motor = HollowMotor(2)
    assert isinstance(_ask(motor, CanModeSwitch(mode=CanMode.EXTENDED), 0.0), ExtendedReply)
    assert motor.can_mode is CanMode.EXTENDED
    assert isinstance(_ask(motor, Stop(), 0.01), ExtendedReply)
    assert isinstance(_ask(motor, CanModeSwitch(mode=CanMode.NORMAL), 0.02), NormalReply)


def test_extended_mode_setpoints_are_increments_and_normal_mode_setpoints_absolute() -> None:
    step = IncrementalSetpoint(step_deg=90.0, speed_rad_s=10.0, kp=100, kd=10, current_a=2.0)
    extended = HollowMotor(1)  # position mode at power-up
    _ask(extended, CanModeSwitch(mode=CanMode.EXTENDED), 0.0)
    _ask(extended, Start(), 0.01)  # §5.2: locks at the present position
    assert isinstance(extended.plant.control, PositionControl)
    _ask(extended, step, 0.02)
    _ask(extended, step, 0.03)  # A11: each frame adds its step once
    assert _extended(extended, POLL_EXT, 1.5).position_deg == pytest.approx(180.0, abs=0.5)
    assert _extended(extended, POLL_EXT, 2.0).position_deg == pytest.approx(180.0, abs=0.5)  # 0 moves nothing

    # The same bytes in normal mode are an absolute target: twice 90° is still 90°.
    normal = HollowMotor(1)
    absolute = Frame(arbitration_id=1, data=step.encode())
    _normal(normal, Start(), 0.0)
    normal.receive(absolute, 0.01)
    normal.receive(absolute, 0.02)
    assert _normal(normal, _setpoint(position_deg=90.0, speed_rad_s=10.0), 1.5).position_deg == pytest.approx(
        90.0, abs=0.5
    )


def test_extended_reply_carries_the_multi_turn_position() -> None:
    motor = HollowMotor(1)
    _ask(motor, CanModeSwitch(mode=CanMode.EXTENDED), 0.0)
    motor.plant.position_deg = 3 * 360.0 + 45.0  # beyond normal mode's ±1 turn (Pmax = 1)
    reply = _extended(motor, POLL_EXT, 0.01)
    assert reply.position_deg == pytest.approx(1125.0, abs=1e-3)
    assert reply.position_counts == round(1125.0 / 360.0 * (1 << 20))


def test_normal_reply_saturates_outside_pmax() -> None:
    motor = HollowMotor(1)
    motor.plant.position_deg = 400.0
    reply = _normal(motor, Stop(), 0.0)
    assert reply.position_saturated and reply.position_deg == pytest.approx(360.0, abs=0.02)  # A34
    motor.plant.position_deg = -500.0
    reply = _normal(motor, Stop(), 0.01)
    assert reply.position_saturated and reply.position_deg == -360.0


def test_special_commands_select_the_control_mode_and_the_plant_control() -> None:
    motor = HollowMotor(1, control_mode=ControlMode.TORQUE)
    _ask(motor, _setpoint(position_deg=30.0, speed_rad_s=1.0, current_a=0.5), 0.0)
    _ask(motor, Start(), 0.001)
    assert motor.plant.control == CurrentControl(current_a=pytest.approx(0.5, abs=0.002))  # type: ignore[arg-type]
    _ask(motor, SelectMode(mode=ControlMode.VELOCITY), 0.002)
    assert isinstance(motor.plant.control, SpeedControl)
    _ask(motor, SelectMode(mode=ControlMode.POSITION), 0.003)
    assert isinstance(motor.plant.control, PositionControl)
    assert motor.ctrl_mode is ControlMode.POSITION
    _ask(motor, Stop(), 0.004)
    assert motor.plant.control == Off() and not motor.enabled


def test_position_mode_is_limited_by_the_setpoint_speed() -> None:
    """§4.4: in position mode V is the maximum speed: 1 rad/s to a 180° target takes over 3 s."""
    motor = HollowMotor(1)
    _ask(motor, _setpoint(position_deg=180.0, speed_rad_s=1.0, kp=2048, kd=100), 0.0)
    _ask(motor, Start(), 0.0)
    reply = _normal(motor, Stop(), 1.0)
    assert 50.0 < reply.position_deg < 58.0  # 57.3°/s at most
    assert reply.speed_rad_s == pytest.approx(1.0, abs=0.1)


def test_torque_mode_drives_the_target_current() -> None:
    motor = HollowMotor(1, control_mode=ControlMode.TORQUE)
    _ask(motor, _setpoint(current_a=1.0), 0.0)
    _ask(motor, Start(), 0.0)
    first = _normal(motor, _setpoint(current_a=1.0), 0.05)
    second = _normal(motor, _setpoint(current_a=1.0), 0.1)
    assert first.current_a == pytest.approx(1.0, abs=0.01)
    assert second.speed_rad_s > first.speed_rad_s > 0.0  # free shaft, constant torque: it accelerates


def test_speed_mode_moves_only_when_enabled_and_the_position_integrates_the_speed() -> None:
    motor = HollowMotor(4, control_mode=ControlMode.VELOCITY)
    command = _setpoint(speed_rad_s=2.0, current_a=2.0)
    # Setpoint stored, motor not started: nothing moves (§4.1: FC starts it).
    _ask(motor, command, 0.0)
    idle = _normal(motor, command, 0.5)
    assert (idle.position_deg, idle.speed_rad_s) == (0.0, 0.0)
    _ask(motor, Start(), 0.5)
    early = _normal(motor, command, 1.0)
    late = _normal(motor, command, 1.5)
    assert late.speed_rad_s == pytest.approx(command.speed_rad_s, abs=0.1)
    travelled = late.position_deg - early.position_deg
    # The reported position is the integral of the reported speed (12-bit speed: ±0.1 rad/s).
    assert travelled == pytest.approx(late.speed_rad_s * 180 / 3.141592653589793 * 0.5, rel=0.02)
    # FD: no output power; friction stops the shaft and the position stays put.
    _ask(motor, Stop(), 1.5)
    stopped = _normal(motor, command, 5.0)
    assert stopped.speed_rad_s == 0.0
    assert _normal(motor, command, 6.0).position_deg == stopped.position_deg


def test_start_without_a_setpoint_commands_no_current() -> None:
    """§4.1: undefined motion; the simulator's safe choice is zero current, counted."""
    motor = HollowMotor(1, control_mode=ControlMode.VELOCITY)
    _ask(motor, Start(), 0.0)
    assert motor.enabled and motor.plant.control == CurrentControl(current_a=0.0)
    assert motor.counters["start_without_setpoint"] == 1
    reply = _normal(motor, Stop(), 1.0)
    assert (reply.position_deg, reply.speed_rad_s, reply.current_a) == (0.0, 0.0, 0.0)


def test_zero_is_set_only_while_disabled_and_clears_the_multi_turn_count() -> None:
    motor = HollowMotor(1)
    _ask(motor, CanModeSwitch(mode=CanMode.EXTENDED), 0.0)
    motor.plant.position_deg = 2 * 360.0 + 30.0
    _ask(motor, Start(), 0.0)  # locks at 750°
    refused = _extended(motor, SetZero(), 0.01)  # still answered (A37), but not applied (A33)
    assert refused.position_deg == pytest.approx(750.0, abs=0.01)
    assert motor.counters["zero_refused"] == 1
    _ask(motor, Stop(), 0.02)
    zeroed = _extended(motor, SetZero(), 0.03)
    assert zeroed.position_deg == pytest.approx(0.0, abs=0.01)
    # The stored target is relative to the new zero: a move of +10° goes to 10°, not 760°.
    _ask(motor, Start(), 0.04)
    _ask(motor, IncrementalSetpoint(step_deg=10.0, speed_rad_s=5.0, kp=9, kd=9, current_a=2.0), 0.05)
    assert _extended(motor, POLL_EXT, 1.5).position_deg == pytest.approx(10.0, abs=0.2)


def test_reboot_restores_the_power_up_state() -> None:
    motor = HollowMotor(9, control_mode=ControlMode.VELOCITY)
    _ask(motor, CanModeSwitch(mode=CanMode.EXTENDED), 0.0)
    _ask(motor, SelectMode(mode=ControlMode.TORQUE), 0.0)
    _ask(motor, PiMultiplier(gain=PiGain.SPEED_KP, multiplier=3.0), 0.0)
    _ask(motor, IncrementalSetpoint(step_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0), 0.0)
    _ask(motor, Start(), 0.0)
    motor.plant.position_deg = 2 * 360.0 + 30.0  # multi-turn position in RAM

    motor.reboot(0.1)
    assert (motor.enabled, motor.can_mode, motor.ctrl_mode, motor.setpoint) == (
        False,
        CanMode.NORMAL,
        ControlMode.VELOCITY,
        None,
    )
    assert motor.pi_multipliers[PiGain.SPEED_KP] == 1.0
    assert motor.plant.control == Off()
    # Normal mode again (6 bytes); the multi-turn count is gone: the single-turn angle remains.
    assert _normal(motor, Stop(), 0.2).position_deg == pytest.approx(30.0, abs=0.02)
    assert motor.counters["reboots"] == 1


def test_an_unresponsive_motor_applies_commands_but_never_replies() -> None:
    motor = HollowMotor(1, control_mode=ControlMode.VELOCITY)
    motor.unresponsive = True
    network = SimCanNetwork([motor])
    network.send(request_frame(1, _setpoint(speed_rad_s=1.0)), 0.0)
    network.send(request_frame(1, Start()), 0.001)
    assert network.run_until_idle() == []
    assert motor.enabled and motor.counters["unanswered"] == 2
    motor.unresponsive = False
    assert isinstance(_ask(motor, Stop(), 0.5), NormalReply)


# ---- CAN FD (§7) ----


def test_fd_frames_carry_mode_run_and_zero() -> None:
    motor = HollowMotor(6, fd_enabled=True, control_mode=ControlMode.TORQUE)
    run = FdCommand(mode=ControlMode.VELOCITY, velocity_rpm=60.0, current_raw=2000, run=True, kp=10, kd=20)
    reply = _fd(motor, run, 0.0)
    assert (reply.mode, reply.running, reply.slave_id) == (ControlMode.VELOCITY, True, 6)
    assert motor.setpoint is not None and (motor.setpoint.kp, motor.setpoint.kd) == (10, 20)
    moving = _fd(motor, run, 1.0)
    assert moving.velocity_rpm == pytest.approx(60.0, rel=0.01)  # 360 dps
    assert moving.position_deg > 200.0
    # Zero with Run Cmd 1: refused (only while not enabled, A33).
    refused = _fd(motor, FdCommand(mode=ControlMode.VELOCITY, velocity_rpm=60.0, run=True, zero=True), 1.1)
    assert refused.position_deg > 200.0 and motor.counters["zero_refused"] == 1
    stopped = _fd(motor, FdCommand(mode=ControlMode.POSITION, run=False, zero=True), 1.2)
    assert (stopped.mode, stopped.running, stopped.position_deg) == (ControlMode.POSITION, False, 0.0)
    assert stopped.temperature_c == round(motor.plant.temperature_c)


def test_fd_position_mode_goes_to_the_absolute_target() -> None:
    motor = HollowMotor(6, fd_enabled=True)
    go = FdCommand(
        mode=ControlMode.POSITION, position_deg=-120.0, velocity_rpm=50.0, current_raw=3000, run=True
    )
    _fd(motor, go, 0.0)
    assert _fd(motor, go, 2.0).position_deg == pytest.approx(-120.0, abs=0.5)  # A29: absolute


# ---- construction, jitter, layering ----


def test_turnaround_jitter_stays_within_the_bound_and_is_reproducible() -> None:
    def delays(seed: int) -> list[float]:
        motor = HollowMotor(1, turnaround_jitter_s=200e-6, seed=seed)
        return [motor.receive(request_frame(1, Stop()), t)[0].ready_s - t for t in (0.0, 0.1, 0.2, 0.3)]

    first = delays(1)
    assert first == delays(1)
    assert all(300e-6 - 1e-12 <= d <= 500e-6 + 1e-12 for d in first)
    assert len(set(first)) > 1


@pytest.mark.parametrize(
    "kwargs",
    [{"motor_id": 101}, {"motor_id": 1, "host_id": 0x800}, {"motor_id": 1, "turnaround_jitter_s": 1e-3}],
)
def test_invalid_configuration_is_refused(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError):
        HollowMotor(**kwargs)


def test_defaults_follow_the_manual() -> None:
    motor = HollowMotor(1)
    assert (motor.host_id, motor.turnaround_s, motor.model) == (100, 500e-6, DEFAULT_MODEL)
    assert (motor.enabled, motor.can_mode, motor.fd_enabled) == (False, CanMode.NORMAL, False)
    assert motor.name == "hollow1" and motor.next_deadline_s() is None and motor.poll(1.0) == []
    # The plant's current limit is the model's current full scale, so replies never clip.
    assert HOLLOW_PLANT_PARAMS.max_current_a == DEFAULT_MODEL.current_full_scale_a


def test_device_models_are_sans_io() -> None:
    package = Path(__file__).resolve().parents[3] / "src" / "servobus" / "protocols" / "hollow" / "sim"
    sources = sorted(package.glob("*.py"))
    assert {p.name for p in sources} >= {"__init__.py", "device.py", "converter.py"}
    for path in sources:
        assert violations(path.read_text()) == [], path.name

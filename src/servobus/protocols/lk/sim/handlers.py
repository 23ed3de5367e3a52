"""What the simulated LK motor does on each command, and the reply it builds (one per request).

The dispatch is :data:`HANDLERS`, filled by the handlers themselves (``@_handles``), so the command
list is the codec's, never a second one here (the declarations test sends each).
:class:`~servobus.protocols.lk.sim.device.LkMotor` decodes a request, filters it and looks its
handler up; a handler works on the motor's state through the names a C twin keeps in step
(``state``, ``held``, ``angles``: :mod:`~servobus.protocols.lk.sim.twin`) and returns its reply.

* status and angle reads: 0x9A/0x9B, 0x9C, 0x9D, 0x90, 0x92, 0x94;
* run state: 0x80 (OFF), 0x81 (STOPPED), 0x88 (ON), 0x95 (zero in RAM), 0x8C (brake);
* set-points (0xA0..0xA8, 0x280): a plant control by :mod:`~servobus.protocols.lk.sim.control`,
  run unless a fault is latched (or, V2.36, the motor is OFF);
* the encoder zero and calibration (0x18, 0x19, 0x91) and the parameters (ROM/RAM,
  :mod:`~servobus.protocols.lk.sim.state`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from servobus.protocols import lk
from servobus.protocols.lk import BrakeAction, BrakeState, LkCommand, LkReply, Revision
from servobus.protocols.lk.codec import check_available
from servobus.protocols.lk.ids import MULTI_MOTOR_REPLY_CODE
from servobus.protocols.lk.model import LkModel
from servobus.protocols.lk.sim.control import CONTROL_COMMANDS, MotionContext, plant_control
from servobus.protocols.lk.sim.replies import encoder_reply, single_turn_deg, status1, status3
from servobus.protocols.lk.sim.state import MEMORY_COMMANDS, AngleFrame, LkMemory, RunState
from servobus.sim.plant import Control, CurrentControl, Plant, PositionControl

__all__ = ["HANDLERS", "LkMotor", "handle"]


class LkMotor(Protocol):
    """What the handlers read and change of the simulated LK motor (the model's LkMotor is one):
    typed here, so the model imports its handlers and nothing here imports the model."""

    model: LkModel
    memory: LkMemory
    motor_id: int
    brake_engaged: bool
    calibration_s: float
    busy_until_s: float
    latched_errors: int
    state: RunState
    held: Control | None

    @property
    def revision(self) -> Revision: ...
    @property
    def plant(self) -> Plant: ...
    @property
    def angles(self) -> AngleFrame: ...
    @property
    def multi_turn_deg(self) -> float: ...
    @property
    def amps_per_count(self) -> float: ...
    def total_counts(self) -> int: ...
    def clear_errors(self) -> None: ...
    def status2_reply(self, code: int) -> LkReply: ...
    def apply_acceleration(self) -> None: ...
    def tally(self, kind: str, n: int = 1) -> None: ...


_H = TypeVar("_H", bound=Callable[..., LkReply])

#: The motor's behaviour per command class: each handler registers the classes it answers.
HANDLERS: dict[type, Callable[[LkMotor, Any, float], LkReply]] = {}


def _handles(*classes: type[LkCommand]) -> Callable[[_H], _H]:
    def register(handler: _H) -> _H:
        for cls in classes:
            if cls in HANDLERS:  # pragma: no cover - a wiring error, caught at import
                raise AssertionError(f"{cls.__name__} has two handlers")
            HANDLERS[cls] = handler
        return handler

    return register


def handle(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    """Act on ``command`` (decoded, accepted) at ``now_s``; return the reply."""
    handler = HANDLERS.get(type(command))
    if handler is None:  # pragma: no cover - the declarations test sends every command class
        raise AssertionError(f"no handler for {type(command).__name__}")
    return handler(motor, command, now_s)


@_handles(lk.ReadStatus1, lk.ClearErrors)
def _status1(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    if isinstance(command, lk.ClearErrors):
        motor.clear_errors()  # spec §4.2: persisting faults stay set
    code = type(command).CODE
    assert code is not None
    return status1(
        code, motor.model, motor.plant, off=motor.state is RunState.OFF, errors=motor.latched_errors
    )


@_handles(lk.ReadStatus2)
def _read_status2(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    return motor.status2_reply(0x9C)


@_handles(lk.ReadStatus3)
def _read_status3(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    return status3(motor.model, motor.plant)


@_handles(lk.MotorOff)
def _off(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    motor.state, motor.held = RunState.OFF, None
    if motor.revision is Revision.V2_36:
        motor.angles.clear_turns(motor.total_counts())  # [001] §5: "clear the number of turns"
    return lk.EchoReply(command=0x80)


@_handles(lk.MotorStop)
def _stop(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    if motor.state is RunState.ON:
        motor.state = RunState.STOPPED
    return lk.EchoReply(command=0x81)


@_handles(lk.MotorRun)
def _run(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    # [001]: OFF -> ON only; [003]: resume the mode held before 0x81 (or after 0x80: idle).
    if motor.state is RunState.OFF or motor.revision is Revision.V2_35:
        motor.state = RunState.ON
    return lk.EchoReply(command=0x88)


@_handles(lk.SetZeroRam)
def _zero_ram(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    motor.angles.zero_here(motor.total_counts())
    if motor.revision is Revision.V2_36 and motor.state is RunState.ON:
        motor.state = RunState.STOPPED  # [001] §25, A30
    return lk.EchoReply(command=0x95)


@_handles(lk.BrakeControl)
def _brake(motor: LkMotor, command: lk.BrakeControl, now_s: float) -> LkReply:
    if command.action is not BrakeAction.READ:
        motor.brake_engaged = command.action is BrakeAction.ENGAGE
    return lk.BrakeReply(state=BrakeState.ENGAGED if motor.brake_engaged else BrakeState.RELEASED)


@_handles(lk.MultiMotorTorque)
def _multi_motor(motor: LkMotor, command: lk.MultiMotorTorque, now_s: float) -> LkReply:
    slot = motor.motor_id - 1
    if command.currents_a is not None:
        current = command.currents_a[slot]
    else:
        current = (command.iq_counts or (0, 0, 0, 0))[slot] * motor.amps_per_count
    _execute(motor, command, CurrentControl(current_a=current))
    return motor.status2_reply(MULTI_MOTOR_REPLY_CODE)


@_handles(*CONTROL_COMMANDS)
def _set_point(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    code = type(command).CODE
    assert code is not None
    _execute(motor, command, plant_control(command, _motion_context(motor)))
    return motor.status2_reply(code)


@_handles(lk.CalibrateEncoder)
def _calibrate(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    # [001] §21: busy for several seconds, then the result (ROM). The sim does not rotate the
    # shaft; the calibration always succeeds.
    motor.busy_until_s = now_s + motor.calibration_s
    motor.held = None
    raw = motor.angles.raw(motor.total_counts())
    return lk.CalibrationReply(align_value=raw, align_ratio=1000, align_state=lk.AlignState.SUCCESS)


@_handles(lk.ReadEncoder)
def _read_encoder(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    return encoder_reply(motor.model, motor.angles, motor.total_counts())


@_handles(lk.SetZeroRom)
def _zero_rom(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    # spec §4.22: ROM only, "needs to be powered on again before it can take effect".
    offset = motor.memory.rom_encoder_offset_counts = motor.angles.raw(motor.total_counts())
    return lk.EncoderOffsetReply(command=0x19, encoder_bits=motor.model.encoder_bits, offset_counts=offset)


@_handles(lk.WriteEncoderOffset)
def _write_offset(motor: LkMotor, command: lk.WriteEncoderOffset, now_s: float) -> LkReply:
    motor.memory.rom_encoder_offset_counts = command.offset_counts  # A21: read as RAM and ROM
    motor.angles.set_offset(command.offset_counts)
    return lk.EncoderOffsetReply(
        command=0x91, encoder_bits=motor.model.encoder_bits, offset_counts=command.offset_counts
    )


@_handles(lk.ReadMultiTurnAngle)
def _read_multi_turn(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    return lk.MultiTurnAngleReply(angle_deg=motor.multi_turn_deg)


@_handles(lk.ReadSingleTurnAngle)
def _read_single_turn(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    angle = single_turn_deg(motor.revision, motor.plant.params.gear_ratio, motor.multi_turn_deg)
    if motor.revision is Revision.V2_36:
        return lk.SingleTurnAngleReply(angle_deg=angle)
    return lk.SingleTurnAngleReplyV235(angle_deg=angle)


@_handles(*MEMORY_COMMANDS)
def _parameter(motor: LkMotor, command: LkCommand, now_s: float) -> LkReply:
    reply = motor.memory.answer(command)
    assert reply is not None  # registered for MEMORY_COMMANDS only
    if isinstance(reply, lk.ParamWriteReply) and not reply.ok:
        motor.tally("refused")
    motor.apply_acceleration()  # 0xC1, 0x42/0x44 (V2.35) and 0x34 may change it
    return reply


def _execute(motor: LkMotor, command: LkCommand, control: Control) -> None:
    try:
        check_available(command, model=motor.model)
    except ValueError:
        motor.tally("not_implemented")  # [001] 0xA0 on MF/MH/MG: "invalid"
        return
    if motor.latched_errors:
        motor.tally("not_executed_fault")
        return
    if motor.revision is Revision.V2_36 and motor.state is RunState.OFF:
        motor.tally("not_executed_off")  # [001] §5: replies, "will not perform the action"
        return
    motor.state, motor.held = RunState.ON, control


def _motion_context(motor: LkMotor) -> MotionContext:
    held = motor.held if motor.state is RunState.ON else None
    return MotionContext(
        revision=motor.revision,
        gear_ratio=motor.plant.params.gear_ratio,
        amps_per_count=motor.amps_per_count,
        limits=motor.memory.limits(),
        multi_turn_deg=motor.multi_turn_deg,
        origin_deg=motor.angles.origin_deg(),
        position_deg=motor.plant.position_deg,
        held_target_deg=held.position_deg if isinstance(held, PositionControl) else None,
    )

"""How the simulated MyActuator motor takes the writes: ROM and RAM, zeros, ids, protection, reset.

0x31 and 0x43 change the running values at once; 0x32/0x43/0xB3/0x20 and the zero commands also
write the ROM. On V4.4 a ROM save succeeds only while the output is off ("disabled", [000]),
otherwise only RAM changes (``rom_write_refused``). The id, the zero, multi-turn clearing/saving and
the baud index act after a restart (0x76, or a power cycle).
"""

from __future__ import annotations

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import Revision
from servobus.protocols.myactuator.sim.handlers import HandledMotor, handles
from servobus.protocols.myactuator.sim.state import int32

__all__: list[str] = []  # the handlers register themselves (handlers.py)

# 0x20 indexes that act at once: the Settings attribute and how the 32-bit value is read.
_IMMEDIATE: dict[ma.FunctionIndex, tuple[str, type[bool] | type[int]]] = {
    ma.FunctionIndex.CAN_ID_FILTER: ("can_id_filter", bool),
    ma.FunctionIndex.ERROR_REPORTING: ("error_reporting", bool),
    ma.FunctionIndex.MAX_POSITIVE_ANGLE: ("max_positive_angle", int),
    ma.FunctionIndex.MAX_NEGATIVE_ANGLE: ("max_negative_angle", int),
    ma.FunctionIndex.ERROR_AUTO_RECOVERY: ("error_auto_recovery", bool),
}


def _rom_ok(motor: HandledMotor) -> bool:
    # [000]: "the parameters can only be saved to ROM successfully when the motor is disabled".
    if motor.revision is Revision.V4_4 and motor.enabled:
        motor.tally("rom_write_refused")
        return False
    return True


@handles(ma.FunctionControl)
def _function(motor: HandledMotor, command: ma.FunctionControl, now_s: float, _rs485: bool = False) -> None:
    index, value = command.index, command.value
    saved = _rom_ok(motor)
    if index is ma.FunctionIndex.CLEAR_MULTI_TURN:
        motor.rom.clear_multi_turn = motor.rom.clear_multi_turn or saved
    elif index is ma.FunctionIndex.SAVE_MULTI_TURN:
        if saved:
            motor.rom.save_multi_turn = bool(value)
    elif index is ma.FunctionIndex.SET_CAN_ID:
        if saved:
            motor.rom.motor_id = value
    else:
        attribute, typed = _IMMEDIATE[index]
        for image in (motor.ram, motor.rom) if saved else (motor.ram,):
            setattr(image, attribute, typed(value))
    motor.update_reports(now_s)


@handles(ma.WritePidRam, ma.WritePidRom)
def _on_write_pid(
    motor: HandledMotor, command: ma.WritePidRam | ma.WritePidRom, _now_s: float, _rs485: bool
) -> None:
    motor.ram.pid[command.index] = command.value
    if isinstance(command, ma.WritePidRom) and _rom_ok(motor):
        motor.rom.pid[command.index] = command.value


@handles(ma.WriteAcceleration)
def _on_write_acceleration(
    motor: HandledMotor, command: ma.WriteAcceleration, _now_s: float, _rs485: bool
) -> None:
    accel = 0.0 if command.acceleration_dps_s is None else command.acceleration_dps_s  # None: 0
    motor.ram.acceleration_dps_s[command.index] = accel
    if _rom_ok(motor):
        motor.rom.acceleration_dps_s[command.index] = accel
    motor.apply_plant()


@handles(ma.WriteEncoderZero)
def _on_encoder_zero(motor: HandledMotor, command: ma.WriteEncoderZero, _now_s: float, _rs485: bool) -> None:
    if _rom_ok(motor):  # takes effect after a restart (§4.9)
        motor.rom.encoder_offset_counts = command.offset_counts


@handles(ma.WriteCurrentPositionAsZero)
def _on_position_as_zero(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    offset = int32(motor.encoder.raw_counts(motor.plant.motor_position_deg))
    if _rom_ok(motor):  # takes effect after 0x76 (§4.10)
        motor.rom.encoder_offset_counts = offset
    return ma.ZeroOffsetReply(offset_counts=offset)


@handles(ma.SetCommTimeout)
def _on_comm_timeout(motor: HandledMotor, command: ma.SetCommTimeout, _now_s: float, _rs485: bool) -> None:
    # ROM, and not in [000]'s "only when disabled" list (§8 item 15).
    timeout = 0 if command.timeout_ms is None else command.timeout_ms  # None: protection off
    motor.ram.comm_timeout_ms = motor.rom.comm_timeout_ms = timeout


@handles(ma.SetCanId)
def _on_set_can_id(motor: HandledMotor, command: ma.SetCanId, _now_s: float, _rs485: bool) -> None:
    motor.rom.motor_id = command.motor_id  # V4.3 only, which has no "only when disabled" rule


@handles(ma.SetBaudRate)
def _on_baud_rate(motor: HandledMotor, command: ma.SetBaudRate, _now_s: float, _rs485: bool) -> None:
    if _rom_ok(motor):  # used from the next power-up (§4.34)
        motor.rom.baud_index = command.baud_index


@handles(ma.SystemReset)
def _on_reset(motor: HandledMotor, _command: Command, now_s: float, _rs485: bool) -> None:
    motor.tally("resets")
    motor.power_up(now_s)  # §4.28: the program restarts

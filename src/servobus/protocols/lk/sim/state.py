"""The memory of a simulated LK motor: ROM and RAM parameters, the limits they set, the angle frame.

Kept apart from the protocol model (:mod:`servobus.protocols.lk.sim.device`) so the persistence rules read
in one place (spec §4.18..§4.31, §6):

* V2.36 [001]: setting parameters (0x40/0x42, spec §6.2) have a RAM copy that 0x42 writes and 0x40
  reads, and a ROM copy that 0x44 replaces by the whole RAM copy. Control parameters (0xC0/0xC1,
  spec §6.1) live in RAM only and are what the loops use; at power-up they are loaded from the ROM
  settings (Max Power -> torque limit, Max Speed -> speed limit, ±Max Angle -> angle limits, Speed
  Ramp -> speed ramp, PIDs -> PIDs). So a setting written with 0x42 is read back at once but acts
  only after 0x44 and a power cycle ([001] §28: "power on again or send a restart command") —
  **inferred**: the manual does not say whether 0x42 acts at once (spec §4.28).
* V2.35 [003]: one ParamID table (spec §6.3) in RAM and ROM; 0x42 writes RAM (acts at once, lost
  at power-off), 0x44 writes ROM *and* RAM (persists, and — inferred — acts at once too). The
  acceleration (0x34) is RAM only; its power-up value is the constructor's.
* Encoder zero: the RAM offset is what the encoder reading subtracts; 0x19 writes the *ROM* offset
  (acts after a power cycle, spec §4.22), 0x91 (V2.35) writes both (RAM/ROM not stated, A21:
  read as "the zero, now and after power-up"), 0x95 writes RAM only (spec §4.26).

Units the manuals leave open (spec A27) are fixed here once, **inferred**: speed limits 0.01 dps/LSB
and angle limits 0.01 °/LSB (spec §6.1's guess, the scales of speedControl and angleControl); the
V2.36 speed ramp 1 dps/s per LSB -- not §6.1's guess of 0.01 dps/s, but the one acceleration unit a
manual states ([003] 0x34 Accel), which also lets the ramp's range (600000) cover real motors;
torque limits in iq counts (spec §8.2). Angles and speeds in the LK protocol are **motor-shaft**
values (0x94's range "0 .. 36000 x reduction ratio - 1", spec §4.25): this module works in
motor degrees and the device converts to the plant's output shaft with ``gear_ratio``.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from servobus.protocols import lk
from servobus.protocols.lk import (
    IQ_AMPS_PER_COUNT,
    BusType,
    CanBaud,
    ControlParam,
    LkCommand,
    LkModel,
    LkReply,
    MotorType,
    ParamId,
    ParamResult,
    ParamValue,
    PidGains,
    Revision,
    Rs485Baud,
    SettingParam,
)
from servobus.protocols.lk.params import (
    CONTROL_LAYOUTS,
    PARAM_LAYOUTS,
    SETTING_LAYOUTS,
    check_value,
    max_angle_from_halves,
    max_angle_halves,
)
from servobus.sim.plant import PlantParams

__all__ = [
    "ANGLE_DEG_PER_COUNT",
    "LK_PLANT_PARAMS",
    "MEMORY_COMMANDS",
    "MH_AMPS_PER_COUNT",
    "RAMP_DPS2_PER_COUNT",
    "SPEED_DPS_PER_COUNT",
    "AngleFrame",
    "Limits",
    "LkMemory",
    "RunState",
    "amps_per_count",
    "default_settings",
    "single_turn_period_deg",
]

SPEED_DPS_PER_COUNT = 0.01  # Max Speed / speed limit (inferred, spec §6.1)
ANGLE_DEG_PER_COUNT = 0.01  # Max Angle / angle limits (inferred, spec §6.1)
RAMP_DPS2_PER_COUNT = 1.0  # V2.36 speed ramp (inferred, as [003] 0x34 Accel)
# MH: no A/LSB in either manual (A23). The simulator needs amperes for its plant and takes MG's.
MH_AMPS_PER_COUNT = 66 / 4096
# MS reports and takes an output *power* (-1000..1000, unitless, A24). The simulator reads full
# scale (1000) as the plant's current limit, so "power" drives the plant like a current.
MS_FULL_SCALE_COUNTS = 1000

_INT32_MAX = 2**31 - 1
_A = TypeVar("_A", bound=Callable[..., LkReply])
_SETTING_LIMIT = 600_000  # Max Speed / Speed Ramp range (spec §6.2)

# An MG-class direct-drive motor (no gear: the LK MF/MG bodies without "-i" reducer): 33 A, the
# MG iq full scale (spec §8.2); a 24 V supply. Plausible values, not a datasheet. The acceleration
# is high for a reason: the plant's position loop brakes at 2*pi*bandwidth*speed and overshoots
# when the ramp cannot follow, so 60000 dps/s keeps it exact up to 2400 dps at 4 Hz.
LK_PLANT_PARAMS = PlantParams(
    inertia_kgm2=0.002,
    viscous_friction_nm_s_per_rad=0.005,
    torque_constant_nm_per_a=0.3,
    gear_ratio=1.0,
    max_current_a=33.0,
    max_speed_dps=2000.0,
    max_acceleration_dps2=60000.0,
    position_bandwidth_hz=4.0,
    winding_resistance_ohm=0.5,
    thermal_resistance_c_per_w=2.0,
    thermal_capacity_j_per_c=60.0,
    supply_v=24.0,
    supply_resistance_ohm=0.05,
)


def single_turn_period_deg(revision: Revision, gear_ratio: float) -> float:
    """Where the single-turn angle wraps, in motor degrees (spec §4.25, §9 D9).

    [001] §24: 0 .. 36000 x reduction ratio - 1 (one output turn); [003]'s uint16 holds one motor
    turn only, 0..35999.
    """
    return 360.0 * gear_ratio if revision is Revision.V2_36 else 360.0


def amps_per_count(motor_type: MotorType, params: PlantParams) -> float:
    """Amperes of plant current per count of the motor type's int16 iq / power field (spec §8.2)."""
    if motor_type is MotorType.MS:
        return params.max_current_a / MS_FULL_SCALE_COUNTS
    return IQ_AMPS_PER_COUNT.get(motor_type, MH_AMPS_PER_COUNT)


def default_settings(model: LkModel, motor_id: int, params: PlantParams) -> dict[enum.IntEnum, ParamValue]:
    """The factory ROM parameters of a motor (V2.36: spec §6.2 settings; V2.35: §6.3 ParamIDs).

    Limits default to what the plant can do, so they do not bite until a test lowers them; PID
    gains are stored and reported only (the plant's loops have fixed bandwidths).
    """
    ratio = params.gear_ratio
    max_speed = min(_SETTING_LIMIT, round(params.max_speed_dps * ratio / SPEED_DPS_PER_COUNT))
    ramp = min(_SETTING_LIMIT, round(params.max_acceleration_dps2 * ratio / RAMP_DPS2_PER_COUNT))
    torque = 850 if model.motor_type is MotorType.MS else 2000  # spec §6.1/§6.2 ranges
    position, speed, current = (
        PidGains(kp=100, ki=100, kd=0),
        PidGains(kp=50, ki=40, kd=0),
        PidGains(kp=50, ki=50, kd=0),
    )
    if model.revision is Revision.V2_36:
        return {
            SettingParam.DRIVER_ID: motor_id,
            SettingParam.BUS_TYPE: BusType.CAN,
            SettingParam.RS485_BAUD: Rs485Baud.BAUD_115200,
            SettingParam.CAN_BAUD: CanBaud.BAUD_1M,
            SettingParam.MAX_POWER: torque,
            SettingParam.MAX_SPEED: max_speed,
            SettingParam.MAX_ANGLE: _INT32_MAX,
            SettingParam.CURRENT_RAMP: 10_000,
            SettingParam.SPEED_RAMP: ramp,
            SettingParam.POSITION_PID: position,
            SettingParam.SPEED_PID: speed,
            SettingParam.CURRENT_PID: current,
        }
    low, high = max_angle_halves(_INT32_MAX)
    return {
        ParamId.ANGLE_PID: position,
        ParamId.SPEED_PID: speed,
        ParamId.CURRENT_PID: current,
        ParamId.MAX_TORQUE_CURRENT: torque,
        ParamId.MAX_SPEED: max_speed,
        ParamId.MAX_ANGLE_LOW: low,
        ParamId.MAX_ANGLE_HIGH: high,
        ParamId.CURRENT_RAMP: 10_000,
        ParamId.SPEED_RAMP: ramp,
    }


# V2.35 values a drive would refuse (reply status 0x01): negative limits and ramps (inferred; [003]
# states no ranges, but a negative maximum has no meaning).
_V235_NON_NEGATIVE = frozenset(
    {
        ParamId.MAX_TORQUE_CURRENT,
        ParamId.MAX_SPEED,
        ParamId.MAX_ANGLE_HIGH,
        ParamId.CURRENT_RAMP,
        ParamId.SPEED_RAMP,
    }
)


#: The parameter commands' behaviour by command class (registered by the LkMemory methods below).
_ANSWERS: dict[type, Callable[[LkMemory, Any], LkReply]] = {}


def _answers(*classes: type[LkCommand]) -> Callable[[_A], _A]:
    def register(handler: _A) -> _A:
        _ANSWERS.update(dict.fromkeys(classes, handler))
        return handler

    return register


class RunState(enum.Enum):
    """The motor's run state (spec §4.5..§4.7)."""

    ON = "on"
    STOPPED = "stopped"
    OFF = "off"


@dataclass(frozen=True, slots=True)
class Limits:
    """The limits the loops use now, in motor-shaft units (from RAM; spec §4.9..§4.17 remarks).

    Attributes:
        torque_counts: Max Torque Current (MS: Max Power), iq counts.
        speed_dps: Max Speed.
        angle_deg: (lower, upper) bound of multi-turn targets (Max Angle / angle limits).
        acceleration_dps2: Max Acceleration (None: the plant's own maximum).
    """

    torque_counts: int
    speed_dps: float
    angle_deg: tuple[float, float]
    acceleration_dps2: float | None


class LkMemory:
    """ROM and RAM of one LK motor.

    Args:
        model: revision (which parameter scheme) and motor type.
        rom: the ROM parameters at construction (see :func:`default_settings`).
        rom_encoder_offset_counts: the encoder zero stored in ROM.
        rom_acceleration_dps2: V2.35: the acceleration after power-up (0x34 writes RAM only).

    Raises:
        ValueError: a parameter of the other revision's scheme, or a value outside its layout.
    """

    def __init__(
        self,
        model: LkModel,
        rom: Mapping[enum.IntEnum, ParamValue],
        *,
        rom_encoder_offset_counts: int,
        rom_acceleration_dps2: float,
    ) -> None:
        self.revision = model.revision
        layouts = SETTING_LAYOUTS if self.revision is Revision.V2_36 else PARAM_LAYOUTS
        wanted = SettingParam if self.revision is Revision.V2_36 else ParamId
        for param, value in rom.items():
            if not isinstance(param, wanted):
                raise ValueError(
                    f"setting {param!r} is not a {wanted.__name__} ({self.revision.name} scheme)"
                )
            check_value(param, value, layouts)
        missing = set(wanted) - set(rom)
        if missing:
            raise ValueError(f"settings missing: {', '.join(sorted(p.name for p in missing))}")
        self.rom: dict[enum.IntEnum, ParamValue] = dict(rom)
        self.rom_encoder_offset_counts = rom_encoder_offset_counts
        self.rom_acceleration_dps2 = rom_acceleration_dps2
        # RAM, set by power_up().
        self.ram: dict[enum.IntEnum, ParamValue] = {}
        self.control: dict[ControlParam, ParamValue] = {}
        self.encoder_offset_counts = 0
        self.acceleration_dps2 = 0.0
        self.power_up()

    def power_up(self) -> None:
        """RAM <- ROM, and (V2.36) the control parameters from the ROM settings."""
        self.ram = dict(self.rom)
        self.encoder_offset_counts = self.rom_encoder_offset_counts
        self.acceleration_dps2 = self.rom_acceleration_dps2
        self.control = {}
        if self.revision is Revision.V2_36:
            rom = self.rom
            max_angle = _as_int(rom[SettingParam.MAX_ANGLE])
            self.control = {
                ControlParam.POSITION_PID: rom[SettingParam.POSITION_PID],
                ControlParam.SPEED_PID: rom[SettingParam.SPEED_PID],
                ControlParam.CURRENT_PID: rom[SettingParam.CURRENT_PID],
                ControlParam.TORQUE_LIMIT: rom[SettingParam.MAX_POWER],
                ControlParam.SPEED_LIMIT: rom[SettingParam.MAX_SPEED],
                ControlParam.ANGLE_UPPER_LIMIT: max_angle,
                ControlParam.ANGLE_LOWER_LIMIT: -max_angle,
                ControlParam.SPEED_RAMP: rom[SettingParam.SPEED_RAMP],
            }
            for param, value in self.control.items():
                check_value(param, value, CONTROL_LAYOUTS)

    def _write_v235(self, param: ParamId, value: ParamValue, *, rom: bool) -> bool:
        """V2.35 0x42 (RAM) / 0x44 (ROM and RAM); False if the drive refuses the value."""
        if param in _V235_NON_NEGATIVE and _as_int(value) < 0:
            return False
        self.ram[param] = value
        if rom:
            self.rom[param] = value
        return True

    def answer(self, command: LkCommand) -> LkReply | None:
        """Apply a parameter command (0xC0/0xC1, 0x40/0x42/0x44, 0x33/0x34) and build its reply.

        Returns:
            The reply, or None if ``command`` is not a parameter command (:data:`MEMORY_COMMANDS`).
        """
        handler = _ANSWERS.get(type(command))
        return None if handler is None else handler(self, command)

    @_answers(lk.ReadControlParam)
    def _read_control(self, command: lk.ReadControlParam) -> LkReply:
        return lk.ControlParamReply(command=0xC0, param=command.param, value=self.control[command.param])

    @_answers(lk.WriteControlParam)
    def _write_control(self, command: lk.WriteControlParam) -> LkReply:
        self.control[command.param] = command.value  # RAM, effective at once (spec §4.19)
        return lk.ControlParamReply(command=0xC1, param=command.param, value=command.value)

    @_answers(lk.ReadSetting)
    def _read_setting(self, command: lk.ReadSetting) -> LkReply:
        return lk.SettingReply(command=0x40, param=command.param, value=self.ram[command.param])

    @_answers(lk.WriteSetting)
    def _write_setting(self, command: lk.WriteSetting) -> LkReply:
        self.ram[command.param] = command.value
        return lk.SettingReply(command=0x42, param=command.param, value=command.value)

    @_answers(lk.SaveSettings)
    def _save_settings(self, command: lk.SaveSettings) -> LkReply:
        self.rom = dict(self.ram)  # spec §4.29: every written setting at once
        return lk.SaveSettingsReply(result=ParamResult.SUCCESS)

    @_answers(lk.ReadParam)
    def _read_param(self, command: lk.ReadParam) -> LkReply:
        return lk.ParamReply(param=command.param, value=self.ram[command.param])

    @_answers(lk.WriteParamRam, lk.WriteParamRom)
    def _write_param(self, command: lk.WriteParamRam) -> LkReply:
        ok = self._write_v235(command.param, command.value, rom=isinstance(command, lk.WriteParamRom))
        result = ParamResult.SUCCESS if ok else ParamResult.FAILURE
        return lk.ParamWriteReply(command=type(command).CODE, param=command.param, result=result)

    @_answers(lk.ReadAcceleration)
    def _read_acceleration(self, command: lk.ReadAcceleration) -> LkReply:
        return lk.AccelerationReply(command=0x33, acceleration_dps2=self.acceleration_dps2)

    @_answers(lk.WriteAcceleration)
    def _write_acceleration(self, command: lk.WriteAcceleration) -> LkReply:
        self.acceleration_dps2 = command.acceleration_dps2  # RAM (spec §4.31)
        return lk.AccelerationReply(command=0x34, acceleration_dps2=command.acceleration_dps2)

    def limits(self) -> Limits:
        """The limits in effect now (motor-shaft units)."""
        if self.revision is Revision.V2_36:
            c = self.control
            ramp = _as_int(c[ControlParam.SPEED_RAMP]) * RAMP_DPS2_PER_COUNT
            return Limits(
                torque_counts=_as_int(c[ControlParam.TORQUE_LIMIT]),
                speed_dps=_as_int(c[ControlParam.SPEED_LIMIT]) * SPEED_DPS_PER_COUNT,
                angle_deg=(
                    _as_int(c[ControlParam.ANGLE_LOWER_LIMIT]) * ANGLE_DEG_PER_COUNT,
                    _as_int(c[ControlParam.ANGLE_UPPER_LIMIT]) * ANGLE_DEG_PER_COUNT,
                ),
                # A ramp of 0 would never move the motor; read as "no ramp" (inferred).
                acceleration_dps2=ramp if ramp > 0 else None,
            )
        r = self.ram
        max_angle = max_angle_from_halves(
            _as_int(r[ParamId.MAX_ANGLE_LOW]), _as_int(r[ParamId.MAX_ANGLE_HIGH])
        )
        return Limits(
            torque_counts=_as_int(r[ParamId.MAX_TORQUE_CURRENT]),
            speed_dps=_as_int(r[ParamId.MAX_SPEED]) * SPEED_DPS_PER_COUNT,
            angle_deg=(-max_angle * ANGLE_DEG_PER_COUNT, max_angle * ANGLE_DEG_PER_COUNT),
            acceleration_dps2=self.acceleration_dps2 if self.acceleration_dps2 > 0 else None,
        )


#: The commands :meth:`LkMemory.answer` answers (the parameter, acceleration and setting commands).
MEMORY_COMMANDS: tuple[type[LkCommand], ...] = tuple(_ANSWERS)


def _as_int(value: ParamValue) -> int:
    if isinstance(value, PidGains):  # pragma: no cover - the tables give limits int layouts
        raise TypeError(f"{value!r} is not a single value")
    return int(value)


@dataclass(slots=True)
class AngleFrame:
    """Encoder counts and the zero points of the encoder and of the multi-turn angle.

    Everything is integer counts of the motor shaft's encoder, as the drive counts them:
    ``total`` (the shaft's cumulative count, from the plant), ``raw = total mod per_turn``
    (encoderRaw), ``encoder = (raw - offset) mod per_turn`` (spec §4.20), and the multi-turn angle
    ``(total - origin)`` counts (spec §4.24).

    Attributes:
        per_turn: counts per motor turn on the wire (spec §2; 18-bit: 65536, codec inference).
        offset: encoderOffset in RAM.
        origin: the total count at which the multi-turn angle is 0.
    """

    per_turn: int
    offset: int = 0
    origin: int = 0

    def total(self, motor_deg: float) -> int:
        """The cumulative encoder count of a motor-shaft angle (the encoder truncates)."""
        return math.floor(motor_deg / 360.0 * self.per_turn)

    def raw(self, total: int) -> int:
        return total % self.per_turn

    def encoder(self, total: int) -> int:
        return (self.raw(total) - self.offset) % self.per_turn

    def multi_turn_deg(self, total: int) -> float:
        return (total - self.origin) * 360.0 / self.per_turn

    def origin_deg(self) -> float:
        return self.origin * 360.0 / self.per_turn

    def clear_turns(self, total: int) -> None:
        """Power-up and V2.36 0x80: the multi-turn angle restarts as the encoder angle, 0..360°."""
        self.origin = total - self.encoder(total)

    def zero_here(self, total: int) -> None:
        """0x95: the present position becomes the zero of the encoder and of both angles."""
        self.offset = self.raw(total)
        self.origin = total

    def set_offset(self, offset: int) -> None:
        """0x91: a new encoder zero; the multi-turn origin moves with it, so the turns are kept."""
        self.origin += offset - self.offset
        self.offset = offset

"""The simulated MyActuator motor's memory: ROM/RAM parameters, encoder frame, error latch and readings.

Kept apart from the protocol handling in :mod:`~servobus.protocols.myactuator.sim.device` so each part stays
small. Everything here is sans-IO data and arithmetic over a :class:`~servobus.sim.plant.Plant`.

* :class:`Settings`: one image of the parameters (the ROM, or the RAM copy the motor runs with).
  Which command writes which image is :mod:`~servobus.protocols.myactuator.sim.device`'s job (spec §4, §0).
* :class:`EncoderFrame`: the multi-turn encoder counts (0x60-0x64, 0x90) and the output angle they
  give (0x92, R2), over the plant's physical shaft angle.
* :class:`ErrorLatch`: which fault conditions are present and which 0x9A flags are reported
  (spec §4.14 recovery rules, §7 levels).
* :class:`Stream`: one 0xB6 active-reply stream's timer (the handler is in ``streams``).
* :func:`status_reply`, :func:`status1_reply`, ...: replies filled from the plant, every field
  clamped to what its integer holds (a reply reports what the motor measured).

Values the manuals do not state are marked [I] (inference) with the reason.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

from servobus.protocols.myactuator import (
    AccelIndex,
    CircleAngleReply,
    ErrorFlags,
    MotionReply,
    MotionScales,
    PidIndex,
    Revision,
    SingleTurnAngleReply,
    SingleTurnEncoderReply,
    SingleTurnStatusReply,
    Status1Reply,
    Status3Reply,
    StatusCommand,
    StatusReply,
)
from servobus.sim.plant import PlantParams

__all__ = [
    "AUTO_RECOVERABLE",
    "DEFAULT_ACCELERATION_DPS_S",
    "DEFAULT_ENCODER_COUNTS_PER_TURN",
    "DEFAULT_MODEL",
    "DEFAULT_PID",
    "DEFAULT_POLE_PAIRS",
    "DEFAULT_VERSION_DATES",
    "MYACTUATOR_PLANT_PARAMS",
    "RECOVERY_SWITCHABLE",
    "STREAM_STEP_S",
    "EncoderFrame",
    "ErrorLatch",
    "Readings",
    "Settings",
    "Stream",
    "int32",
    "motion_reply",
    "phase_currents",
    "single_turn_encoder_reply",
    "single_turn_reply",
    "single_turn_status_reply",
    "status1",
    "status1_reply",
    "status3_reply",
    "status_reply",
]

# The manuals' own examples: "X8S2V10" (0xB5, §4.35; seven characters fit both layouts).
DEFAULT_MODEL = "X8S2V10"
# 0xB2 dates consistent with ``revision_from_version_date``'s default rule: V4.4 from the V4.4 manual's
# change-log date (2026-03-25), V4.3 the V4.3 manual's date (2025-05-12).
DEFAULT_VERSION_DATES: dict[Revision, int] = {Revision.V4_3: 20250512, Revision.V4_4: 20260325}
# [I] 14-bit single-turn encoder: the 0x90 example (raw 11454, offset 9355) fits it, and 0x90/0xA6
# carry the single-turn encoder in a uint16 (§4.11, §3.2). The manuals state no resolution.
DEFAULT_ENCODER_COUNTS_PER_TURN = 16384
# [I] pole pairs only shape the 0x9D phase currents; the manuals do not give them.
DEFAULT_POLE_PAIRS = 14
# An RMD-X8 class geared actuator: the plant's own defaults (gear 6, 2 N·m/A at the output, 30 A).
MYACTUATOR_PLANT_PARAMS = PlantParams()
# [I] factory PID values: no manual prints them; the 0x30 example reads current KP = 1.0.
DEFAULT_PID: dict[PidIndex, float] = {
    PidIndex.CURRENT_KP: 1.0,
    PidIndex.CURRENT_KI: 0.05,
    PidIndex.SPEED_KP: 0.5,
    PidIndex.SPEED_KI: 0.01,
    PidIndex.POSITION_KP: 0.3,
    PidIndex.POSITION_KI: 0.0,
    PidIndex.POSITION_KD: 0.1,
}
# The 0x42 example reads 10000 dps/s (§4.4); used for every index [I].
DEFAULT_ACCELERATION_DPS_S = 10000.0

# Flags that clear by themselves when their condition ends (§4.14 [000] recovery column; power
# overrun has no 0x9A conditions but is a level-2, self-recovering fault in the §7 table).
AUTO_RECOVERABLE = (
    ErrorFlags.LOW_VOLTAGE
    | ErrorFlags.OVER_VOLTAGE
    | ErrorFlags.OVER_SPEED
    | ErrorFlags.POWER_OVERRUN
    | ErrorFlags.COMPONENT_OVER_TEMPERATURE
    | ErrorFlags.MOTOR_OVER_TEMPERATURE
)
# 0x20 index 8 (V4.4) switches auto-recovery of these three on or off (§4.37).
RECOVERY_SWITCHABLE = ErrorFlags.LOW_VOLTAGE | ErrorFlags.OVER_VOLTAGE | ErrorFlags.OVER_SPEED

_INT8 = (-128, 127)
_UINT8 = (0, 255)
_INT16 = (-32768, 32767)
_INT32 = (-(1 << 31), (1 << 31) - 1)
_RAD_PER_DEG = math.pi / 180.0


@dataclass(slots=True, kw_only=True)
class Settings:
    """One image of the motor's parameters: the ROM, or the RAM copy the motor runs with.

    Attributes:
        motor_id: the CAN/RS485 id (0x20 index 5 and 0x79 write it to ROM, used after a restart).
        pid: 0x30/0x31/0x32 values by index (stored and reported; the plant's loops have their own
            fixed bandwidths, so the values do not shape the motion).
        acceleration_dps_s: 0x42/0x43 values by index; index 0 (position) and 2 (speed) set the
            plant's slew limit, 0 meaning "limited only by the current" (§4.20, §4.21).
        comm_timeout_ms: 0xB3, 0 = protection off (§4.33).
        can_id_filter: 0x20 index 2; on, the motor does not receive 0x280 or 0x300 (§1.1).
        error_reporting: 0x20 index 3; 0x9A every 100 ms while an error is present.
        save_multi_turn: 0x20 index 4; off, the multi-turn count is lost at each start (single-turn).
        max_positive_angle, max_negative_angle: 0x20 index 6/7, raw int32 (unit unstated, §9 item 17:
            stored, not applied).
        error_auto_recovery: 0x20 index 8 (V4.4): voltage and over-speed errors clear by themselves.
        baud_index: 0xB4, raw index (meaning differs between the manuals, §4.34), used after a restart.
        encoder_offset_counts: the multi-turn zero (0x62 reads it, 0x63/0x64 write it to ROM).
        clear_multi_turn: 0x20 index 1 is pending: the next start clears the multi-turn count.
    """

    motor_id: int
    pid: dict[PidIndex, float] = field(default_factory=lambda: dict(DEFAULT_PID))
    acceleration_dps_s: dict[AccelIndex, float] = field(
        default_factory=lambda: dict.fromkeys(AccelIndex, DEFAULT_ACCELERATION_DPS_S)
    )
    comm_timeout_ms: int = 0
    can_id_filter: bool = False
    error_reporting: bool = False
    save_multi_turn: bool = True
    max_positive_angle: int = 0
    max_negative_angle: int = 0
    error_auto_recovery: bool = True
    baud_index: int = 1  # [002]'s mapping: CAN 1 Mbit/s, the rate both manuals start from (§1.1)
    encoder_offset_counts: int = 0
    clear_multi_turn: bool = False

    def copy(self) -> Settings:
        """An independent copy (the dicts are copied too)."""
        return replace(self, pid=dict(self.pid), acceleration_dps_s=dict(self.acceleration_dps_s))


class EncoderFrame:
    """Multi-turn encoder counts over the plant's rotor angle, and the output angle they give.

    ``raw = rotor counts + base`` (``base``: where the multi-turn count started at power-up);
    0x60 position = raw - offset (§4.6); the output angle (0x92, R2) is that position in degrees
    divided by the gear ratio, since the encoder sits on the rotor and angles are output-side (§0).

    Args:
        counts_per_turn: encoder counts per rotor turn.
        gear_ratio: rotor turns per output turn (the plant's).
        offset_counts: the active zero offset.
    """

    def __init__(self, counts_per_turn: int, gear_ratio: float, offset_counts: int = 0) -> None:
        if counts_per_turn <= 0:
            raise ValueError(f"counts_per_turn={counts_per_turn!r} must be > 0")
        self.counts_per_turn = counts_per_turn
        self.gear_ratio = gear_ratio
        self.offset_counts = offset_counts
        self.base_counts = 0

    def raw_exact(self, rotor_deg: float) -> float:
        """Raw multi-turn counts, unquantised."""
        return rotor_deg * self.counts_per_turn / 360.0 + self.base_counts

    def raw_counts(self, rotor_deg: float) -> int:
        """0x61: raw multi-turn counts."""
        return math.floor(self.raw_exact(rotor_deg))

    def position_counts(self, rotor_deg: float) -> int:
        """0x60: raw - zero offset."""
        return self.raw_counts(rotor_deg) - self.offset_counts

    def angle_deg(self, rotor_deg: float) -> float:
        """Output-shaft angle from the zero (0x92, R2, motion mode)."""
        counts = self.raw_exact(rotor_deg) - self.offset_counts
        return counts * 360.0 / self.counts_per_turn / self.gear_ratio

    def output_deg_for(self, angle_deg: float) -> float:
        """The plant's (physical) output angle at which :meth:`angle_deg` reads ``angle_deg``."""
        shift = (self.offset_counts - self.base_counts) * 360.0 / self.counts_per_turn / self.gear_ratio
        return angle_deg + shift

    def power_up(self, rotor_deg: float, *, keep_turns: bool) -> None:
        """A start: without multi-turn saving (0x20 index 4 off, or index 1 pending) the count
        keeps only the present rotor turn, so the raw value restarts in ``0..counts_per_turn``."""
        if not keep_turns:
            turns = math.floor(self.raw_exact(rotor_deg) / self.counts_per_turn)
            self.base_counts -= turns * self.counts_per_turn


class ErrorLatch:
    """Fault conditions present and the 0x9A flags reported (spec §4.14, §7).

    A condition sets its flag at once. When it ends, an auto-recoverable flag (level 2) clears, unless
    0x20 index 8 has switched recovery off for it; a latched flag (level 1: stall, phase over-current,
    encoder and calibration errors) stays until the next start, which re-detects only the conditions
    still present.
    """

    def __init__(self) -> None:
        self.conditions = ErrorFlags.NONE
        self.flags = ErrorFlags.NONE

    def start(self, flags: ErrorFlags) -> None:
        self.conditions |= flags
        self.flags |= flags

    def end(self, flags: ErrorFlags, *, auto_recovery: bool) -> None:
        self.conditions &= ~flags
        recoverable = AUTO_RECOVERABLE if auto_recovery else AUTO_RECOVERABLE & ~RECOVERY_SWITCHABLE
        self.flags &= ~(flags & recoverable)

    def power_up(self) -> None:
        self.flags = self.conditions


@dataclass(frozen=True, slots=True)
class Readings:
    """What the motor measures at one instant, in reply units (output side)."""

    temperature_c: float
    current_a: float
    speed_dps: float
    angle_deg: float
    voltage_v: float
    rotor_deg: float
    position_counts: int
    counts_per_turn: int


def _clamp(value: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, value))


def _int(value: float, limits: tuple[int, int]) -> int:
    return int(_clamp(round(value), *limits))


def status_reply(code: StatusCommand, r: Readings) -> StatusReply:
    """R2 (§3.1). The int16 degree field saturates at ±32767° (wrap or saturate is unstated, §9 item 28)."""
    current = _clamp(round(r.current_a, 2), -327.68, 327.67)
    return _status_reply(
        code,
        _int(r.temperature_c, _INT8),
        current,
        math.copysign(1.0, current),  # 0.0 and -0.0 are equal keys, not equal values
        _int(r.speed_dps, _INT16),
        _int(r.angle_deg, _INT16),
    )


# Replies are frozen and their fields are the rounded values above, so motors polled again and again
# share one reply per distinct content instead of building (and validating) a new one each time.
@functools.lru_cache(maxsize=4096)
def _status_reply(
    code: StatusCommand, temperature: int, current: float, _sign: float, speed: int, angle: int
) -> StatusReply:
    return StatusReply(
        command=code, temperature_c=temperature, current_a=current, speed_dps=speed, angle_deg=angle
    )


def single_turn_status_reply(r: Readings) -> SingleTurnStatusReply:
    """R2-A6 (§3.2): the encoder counts from the zero within one rotor turn."""
    return SingleTurnStatusReply(
        temperature_c=_int(r.temperature_c, _INT8),
        current_a=_clamp(round(r.current_a, 2), -327.68, 327.67),
        speed_dps=_int(r.speed_dps, _INT16),
        encoder_counts=r.position_counts % r.counts_per_turn,
    )


def status1_reply(r: Readings, *, brake_released: bool, errors: ErrorFlags) -> Status1Reply:
    """0x9A (§4.14). [I] The MOS temperature is reported as the winding's: the plant has one thermal
    mass (clamped to its uint8 field, 0..255 °C)."""
    return status1(r.temperature_c, r.voltage_v, brake_released=brake_released, errors=errors)


def status1(
    temperature_c: float, voltage_v: float, *, brake_released: bool, errors: ErrorFlags
) -> Status1Reply:
    """:func:`status1_reply` from the only two readings it carries."""
    return _status1(
        _int(temperature_c, _INT8),
        _int(temperature_c, _UINT8),
        brake_released,
        _clamp(round(voltage_v, 1), 0.0, 6553.5),
        int(errors),  # hashed as a plain int (an enum's hash runs in Python)
    )


@functools.lru_cache(maxsize=1024)
def _status1(temperature: int, mos: int, brake_released: bool, voltage: float, errors: int) -> Status1Reply:
    return Status1Reply(
        temperature_c=temperature,
        mos_temperature_c=mos,
        brake_released=brake_released,
        voltage_v=voltage,
        errors=ErrorFlags(errors),
    )


def phase_currents(current_a: float, rotor_deg: float, pole_pairs: int) -> tuple[float, float, float]:
    """Phase currents of a q-axis current at the rotor's electrical angle (inverse Park/Clarke, d = 0).

    They sum to zero and their amplitude is the q-axis current.
    """
    theta = rotor_deg * _RAD_PER_DEG * pole_pairs
    third = 2.0 * math.pi / 3.0
    return (
        -current_a * math.sin(theta),
        -current_a * math.sin(theta - third),
        -current_a * math.sin(theta + third),
    )


def status3_reply(r: Readings, pole_pairs: int) -> Status3Reply:
    """0x9D (§4.16)."""
    a, b, c = (
        _clamp(round(i, 2), -327.68, 327.67) for i in phase_currents(r.current_a, r.rotor_deg, pole_pairs)
    )
    return Status3Reply(
        temperature_c=_int(r.temperature_c, _INT8),
        phase_a_current_a=a,
        phase_b_current_a=b,
        phase_c_current_a=c,
    )


def single_turn_encoder_reply(r: Readings, raw_counts: int, offset_counts: int) -> SingleTurnEncoderReply:
    """0x90 (V4.3, §4.11): encoder = raw - offset within one rotor turn."""
    cpt = r.counts_per_turn
    return SingleTurnEncoderReply(
        encoder_counts=r.position_counts % cpt % 65536,
        raw_counts=raw_counts % cpt % 65536,
        offset_counts=offset_counts % cpt % 65536,
    )


def single_turn_reply(r: Readings, revision: Revision) -> SingleTurnAngleReply | CircleAngleReply:
    """0x94 (§4.13): V4.4 int32 in -180..+180°; V4.3 uint16 0..359.99° (increasing clockwise, which
    the simulator takes as the positive direction [I])."""
    centi = round(r.angle_deg * 100)
    if revision is Revision.V4_4:
        return SingleTurnAngleReply(angle_deg=((centi + 18000) % 36000 - 18000) / 100)
    return CircleAngleReply(angle_deg=(centi % 36000) / 100)


def motion_reply(motor_id: int, r: Readings, torque_nm: float, scales: MotionScales) -> MotionReply:
    """0x500+ID (§5.3): position, velocity, torque clamped to the motion ranges."""
    return MotionReply(
        motor_id=motor_id,
        position_rad=_clamp(r.angle_deg * _RAD_PER_DEG, -scales.p_max_rad, scales.p_max_rad),
        velocity_rad_s=_clamp(r.speed_dps * _RAD_PER_DEG, -scales.v_max_rad_s, scales.v_max_rad_s),
        torque_nm=_clamp(torque_nm, -scales.t_max_nm, scales.t_max_nm),
        scales=scales,
    )


def int32(value: float) -> int:
    """``value`` rounded and saturated to int32 (the 0x60-0x64 and 0x92 fields)."""
    return _int(value, _INT32)


STREAM_STEP_S = 0.01  # 0xB6 interval unit: 10 ms/LSB (§4.36, §9 item 29)


@dataclass(slots=True)
class Stream:
    """One 0xB6 active-reply stream: the next frame is due at ``origin_s + count * interval_s``."""

    interval_s: float
    origin_s: float
    count: int = 1

    @property
    def next_s(self) -> float:
        return self.origin_s + self.count * self.interval_s

    def advance_past(self, now_s: float) -> int:
        """Move the schedule past ``now_s``; return how many due slots were skipped (late poll)."""
        due = math.floor((now_s - self.origin_s) / self.interval_s + 1e-9) + 1
        skipped = max(0, due - self.count - 1)
        self.count = max(self.count + 1, due)
        return skipped

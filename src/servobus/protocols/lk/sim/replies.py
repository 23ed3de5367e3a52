"""What a simulated LK motor reports: status 1/2/3 and angle replies built from the plant's state.

The codec's reply classes (spec §4.1..§4.4, §4.20, §4.24, §4.25, §8) filled from the
:class:`~servobus.sim.plant.Plant` (output shaft) and the motor's angle frame (motor shaft, see
:mod:`~servobus.protocols.lk.sim.state`). Values are clamped to what their wire field holds, as a
drive's firmware saturates a reading rather than wrapping it.
"""

from __future__ import annotations

import math

from servobus.protocols import lk
from servobus.protocols.lk import (
    ErrorState,
    ErrorStateV235,
    LkModel,
    LkReply,
    MotorState,
    MotorType,
    Revision,
)
from servobus.protocols.lk.replies import status2_slot, torque_range
from servobus.protocols.lk.sim.state import AngleFrame, amps_per_count, single_turn_period_deg
from servobus.sim.plant import Plant

__all__ = ["encoder_reply", "single_turn_deg", "status1", "status2", "status3"]

_INT8 = (-128, 127)
_INT16 = (-(1 << 15), (1 << 15) - 1)
# The pole count is not in the protocol; 14 pole pairs, typical of LK's flat motors, is assumed.
_POLE_PAIRS = 14


def _clamp(value: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, value))


def _temperature(plant: Plant) -> int:
    return int(_clamp(round(plant.temperature_c), *_INT8))


def status1(code: int, model: LkModel, plant: Plant, *, off: bool, errors: int) -> LkReply:
    """0x9A / 0x9B reply (spec §4.1, §4.2): temperature, voltage, (V2.36) bus current and state."""
    if model.revision is Revision.V2_35:
        return lk.Status1ReplyV235(
            command=code,
            temperature_c=_temperature(plant),
            voltage_v=_clamp(plant.voltage_v, 0.0, 6553.5),
            error_state=ErrorStateV235(errors),
        )
    # Bus current from the power balance: copper loss plus mechanical power, over the bus voltage.
    p = plant.params
    power_w = plant.current_a**2 * p.winding_resistance_ohm + plant.torque_nm * math.radians(plant.speed_dps)
    voltage = plant.voltage_v
    return lk.Status1Reply(
        command=code,
        temperature_c=_temperature(plant),
        voltage_v=_clamp(voltage, -327.68, 327.67),
        current_a=_clamp(power_w / voltage if voltage > 0 else 0.0, -327.68, 327.67),
        motor_state=MotorState.OFF if off else MotorState.ON,
        error_state=ErrorState(errors),
    )


def status2(code: int, model: LkModel, plant: Plant, *, encoder_counts: int) -> LkReply:
    """The status-2 shape (spec §8.1): temperature, iq (MS: power), motor speed, encoder."""
    motor_type = model.motor_type
    apc = amps_per_count(motor_type, plant.params)
    # The manuals' stated range of the reply's iq (``torque_range``), else the int16 range.
    limits = torque_range(model.revision, motor_type, code) or _INT16
    counts = int(_clamp(round(plant.current_a / apc), *limits))
    # Exactly the one DATA[2..3] field the motor type has (spec §8.2); the 0xA0 reply's is power on
    # every motor type (spec §4.9): the plant's current in the counts 0xA0 drove it with.
    slot = status2_slot(code)
    values = slot.from_counts(motor_type, counts)
    return lk.Status2Reply(
        command=code,
        motor_type=motor_type,
        encoder_bits=model.encoder_bits,
        temperature_c=_temperature(plant),
        speed_dps=_clamp(round(plant.speed_dps * plant.params.gear_ratio), *_INT16),
        encoder_counts=encoder_counts,
        current_a=values.get("current_a"),
        power_counts=_int_or_none(values.get("power_counts")),
        iq_counts=_int_or_none(values.get("iq_counts")),
    )


def _int_or_none(value: float | int | None) -> int | None:
    return None if value is None else int(value)


def status3(model: LkModel, plant: Plant) -> LkReply:
    """0x9D reply (spec §4.4): the phase currents of the q-axis current at the electrical angle."""
    theta = math.radians(plant.motor_position_deg * _POLE_PAIRS)
    iq = plant.current_a
    phases = [-iq * math.sin(theta - k * 2 * math.pi / 3) for k in (0, 1, -1)]
    if model.revision is Revision.V2_35:
        a, b, c = (_clamp(x, -512.0, 511.98) for x in phases)
        return lk.Status3ReplyV235(currents_a=(a, b, c))
    motor_type, temperature = model.motor_type, _temperature(plant)
    if motor_type is MotorType.MS:  # [001] §4: MS has no phase-current sampling ("no effect")
        return lk.Status3Reply(motor_type=motor_type, temperature_c=temperature, currents_counts=(0, 0, 0))
    apc = amps_per_count(motor_type, plant.params)
    ia, ib, ic = (int(_clamp(round(x / apc), *_INT16)) for x in phases)
    if motor_type is MotorType.MH:  # no A/LSB in the manual (A23): raw counts
        return lk.Status3Reply(motor_type=motor_type, temperature_c=temperature, currents_counts=(ia, ib, ic))
    return lk.Status3Reply(
        motor_type=motor_type, temperature_c=temperature, currents_a=(ia * apc, ib * apc, ic * apc)
    )


def encoder_reply(model: LkModel, angles: AngleFrame, total: int) -> LkReply:
    """0x90 reply (spec §4.20): encoder, encoderRaw, encoderOffset."""
    return lk.EncoderReply(
        encoder_bits=model.encoder_bits,
        encoder_counts=angles.encoder(total),
        raw_counts=angles.raw(total),
        offset_counts=angles.offset,
    )


def single_turn_deg(revision: Revision, gear_ratio: float, multi_turn_deg: float) -> float:
    """0x94's circleAngle: the multi-turn angle wrapped to the revision's period, 0.01° steps."""
    period_centi = round(single_turn_period_deg(revision, gear_ratio) * 100)
    return (math.floor(multi_turn_deg * 100 + 1e-6) % period_centi) / 100

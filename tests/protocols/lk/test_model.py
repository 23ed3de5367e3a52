"""LK model parameters (model.py) and named state values (states.py)."""

from __future__ import annotations

import pytest

from servobus.protocols.lk import (
    DEFAULT_MODEL,
    IQ_AMPS_PER_COUNT,
    AlignState,
    ErrorState,
    ErrorStateV235,
    LkModel,
    MotorType,
    ParamResult,
    Revision,
)
from servobus.protocols.lk.model import encoder_counts_per_turn, encoder_max_count, iq_field


def test_default_model_is_documented() -> None:
    assert LkModel(revision=Revision.V2_36, motor_type=MotorType.MG, encoder_bits=14) == DEFAULT_MODEL


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"revision": "V2_36"}, "revision='V2_36' is not one of Revision.V2_36, Revision.V2_35"),
        ({"motor_type": "MF"}, "motor_type='MF' is not one of MotorType.MS"),
        ({"encoder_bits": 17}, "encoder_bits=17 is not one of 14, 15, 16, 18"),
        ({"encoder_bits": 14.0}, "encoder_bits=14.0 is not an integer"),
    ],
)
def test_model_fields_are_validated(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        LkModel(**kwargs)  # type: ignore[arg-type]


def test_iq_scales_of_spec_8_2() -> None:
    assert IQ_AMPS_PER_COUNT[MotorType.MF] * 2048 == 16.5
    assert IQ_AMPS_PER_COUNT[MotorType.MG] * 2048 == 33.0
    assert MotorType.MH not in IQ_AMPS_PER_COUNT  # A23: not stated
    assert MotorType.MS not in IQ_AMPS_PER_COUNT  # MS reports power
    field = iq_field("current_a", MotorType.MG, -2048, 2048)
    assert field is not None
    assert field.limits == (-33.0, 33.0)
    assert field.to_code(33.0) == 2048
    assert iq_field("current_a", MotorType.MH, -2048, 2048) is None


@pytest.mark.parametrize(
    ("bits", "top", "per_turn"),
    [(14, 16383, 16384), (15, 32767, 32768), (16, 65535, 65536), (18, 65535, 65536)],
)
def test_encoder_widths(bits: int, top: int, per_turn: int) -> None:
    assert encoder_max_count(bits) == top
    assert encoder_counts_per_turn(bits) == per_turn


def test_state_flags_keep_unknown_bits_and_name_known_ones() -> None:
    assert (
        ErrorState(0xFF)
        == ErrorState.LOW_VOLTAGE
        | ErrorState.HIGH_VOLTAGE
        | ErrorState.DRIVER_OVER_TEMPERATURE
        | ErrorState.MOTOR_OVER_TEMPERATURE
        | ErrorState.MOTOR_OVER_CURRENT
        | ErrorState.MOTOR_SHORT_CIRCUIT
        | ErrorState.MOTOR_STALL
        | ErrorState.INPUT_SIGNAL_LOSS
    )
    # Bits 0 and 3 mean the same in both revisions (spec §7.2).
    assert int(ErrorStateV235.LOW_VOLTAGE) == int(ErrorState.LOW_VOLTAGE)
    assert int(ErrorStateV235.OVER_TEMPERATURE) == int(ErrorState.MOTOR_OVER_TEMPERATURE)
    assert int(ErrorStateV235(0x06)) == 0x06  # "invalid" bits kept
    assert AlignState(0x13) & AlignState.SUCCESS
    assert {r.name for r in ParamResult} == {"SUCCESS", "FAILURE"}

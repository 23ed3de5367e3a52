"""Named values of the LK state and flag bytes (spec §7).

Decoding rule: an :class:`enum.IntEnum` byte with a value the manual does not list is a
ProtocolError (the decoders check it); an :class:`enum.IntFlag` keeps unknown bits (Python's
``KEEP`` boundary), because a flag byte with an undocumented bit set is still a valid report and the
documented bits in it still mean what they say.
"""

from __future__ import annotations

import enum

__all__ = [
    "AlignState",
    "BrakeAction",
    "BrakeState",
    "ErrorState",
    "ErrorStateV235",
    "MotorState",
    "ParamResult",
    "SpinDirection",
]


class MotorState(enum.IntEnum):
    """0x9A/0x9B reply DATA[6], V2.36 only (spec §7.3)."""

    ON = 0x00  # running state: default after power-on, and after 0x88
    OFF = 0x10  # after 0x80


class ErrorState(enum.IntFlag):
    """0x9A/0x9B reply DATA[7], V2.36 (spec §7.1). A set bit is a fault; 0 is normal."""

    LOW_VOLTAGE = 0x01
    HIGH_VOLTAGE = 0x02
    DRIVER_OVER_TEMPERATURE = 0x04
    MOTOR_OVER_TEMPERATURE = 0x08
    MOTOR_OVER_CURRENT = 0x10
    MOTOR_SHORT_CIRCUIT = 0x20
    MOTOR_STALL = 0x40
    INPUT_SIGNAL_LOSS = 0x80


class ErrorStateV235(enum.IntFlag):
    """0x9A/0x9B reply DATA[7], V2.35 (spec §7.2): bits 0 and 3 defined; the "invalid" others are kept."""

    LOW_VOLTAGE = 0x01
    OVER_TEMPERATURE = 0x08


class BrakeAction(enum.IntEnum):
    """0x8C request DATA[1], V2.36 (spec §4.8, §7.4)."""

    ENGAGE = 0x00  # brake de-energised -> brake engaged (holding)
    RELEASE = 0x01  # brake energised -> brake released
    READ = 0x10  # read the brake state, change nothing


class BrakeState(enum.IntEnum):
    """0x8C reply DATA[1], V2.36 (spec §7.4)."""

    ENGAGED = 0x00  # de-energised, holding
    RELEASED = 0x01  # energised


class SpinDirection(enum.IntEnum):
    """0xA5/0xA6 request DATA[1] (spec §7.6; the viewing side is not defined in either manual)."""

    CLOCKWISE = 0x00
    COUNTER_CLOCKWISE = 0x01


class AlignState(enum.IntFlag):
    """0x18 reply DATA[7], V2.36 (spec §7.5): bit0 success, bit4 phase order inverted; others kept."""

    SUCCESS = 0x01
    PHASE_INVERTED = 0x10


class ParamResult(enum.Enum):
    """Outcome of a parameter write/save (spec §7.7).

    The wire bytes are opposite in the two revisions — V2.36 0x44 reply: 0x01 = saved, 0x00 = failed;
    V2.35 0x42/0x44 reply: 0x00 = written, 0x01 = failed — so the enum has no integer value of its
    own; the reply classes map it per revision.
    """

    SUCCESS = "success"
    FAILURE = "failure"

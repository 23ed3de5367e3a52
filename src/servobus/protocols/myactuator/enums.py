"""Enumerations and reference tables of the MyActuator protocol: indexes, modes, error flags, faults.

Everything here is data taken from myactuator-v4.md (section cited on each item); the commands and
replies use these types for their fields.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from servobus.protocols.myactuator.revision import ALL_REVISIONS, ONLY_V4_4, Revision

__all__ = [
    "ACCELERATION_MIN_DPS_S",
    "BAUD_RATE_INDEXES",
    "ERROR_FLAG_INFO",
    "FAULTS",
    "FUNCTION_VALUES",
    "STATUS_COMMAND_REVISIONS",
    "AccelIndex",
    "BaudRateSetting",
    "ErrorFlagInfo",
    "ErrorFlags",
    "Fault",
    "FunctionIndex",
    "FunctionValue",
    "IndicatorLevel",
    "PidIndex",
    "Rs485MotionMode",
    "RunMode",
    "SpinDirection",
    "StatusCommand",
    "StreamableCommand",
]


class PidIndex(enum.IntEnum):
    """0x30/0x31/0x32 parameter index (§4.1, identical in both manuals; 0x03 and 0x06 are undefined)."""

    CURRENT_KP = 0x01
    CURRENT_KI = 0x02
    SPEED_KP = 0x04
    SPEED_KI = 0x05
    POSITION_KP = 0x07
    POSITION_KI = 0x08
    POSITION_KD = 0x09


# §4.4: the manuals' acceleration range is 100..60000 dps/s (0, "no planning", is asked for apart).
ACCELERATION_MIN_DPS_S = 100


class AccelIndex(enum.IntEnum):
    """0x42/0x43 acceleration index (§4.4)."""

    POSITION_ACCELERATION = 0x00
    POSITION_DECELERATION = 0x01
    SPEED_ACCELERATION = 0x02
    SPEED_DECELERATION = 0x03


class FunctionIndex(enum.IntEnum):
    """0x20 function-control index (§4.37): 1..7 in both manuals, 8 only in V4.4."""

    CLEAR_MULTI_TURN = 0x01
    CAN_ID_FILTER = 0x02
    ERROR_REPORTING = 0x03
    SAVE_MULTI_TURN = 0x04
    SET_CAN_ID = 0x05
    MAX_POSITIVE_ANGLE = 0x06
    MAX_NEGATIVE_ANGLE = 0x07
    ERROR_AUTO_RECOVERY = 0x08


@dataclass(frozen=True, slots=True)
class FunctionValue:
    """What the 32-bit Value of a 0x20 index means and accepts (§4.37)."""

    lo: int
    hi: int
    signed: bool
    meaning: str
    revisions: frozenset[Revision] = ALL_REVISIONS


_INT32 = (-(1 << 31), (1 << 31) - 1)

FUNCTION_VALUES: dict[FunctionIndex, FunctionValue] = {
    # Value not described; the example sends 0. Clears the multi-turn count and saves (after restart).
    FunctionIndex.CLEAR_MULTI_TURN: FunctionValue(
        0, 0, False, "0 (clears the multi-turn value; after restart)"
    ),
    FunctionIndex.CAN_ID_FILTER: FunctionValue(
        0, 1, False, "1 = filter on; 0 = off, needed for 0x280 broadcasts (saved in FLASH)"
    ),
    FunctionIndex.ERROR_REPORTING: FunctionValue(
        0, 1, False, "1 = send 0x9A every 100 ms while an error is present; 0 = off"
    ),
    FunctionIndex.SAVE_MULTI_TURN: FunctionValue(
        0, 1, False, "1 = save the multi-turn value at power-off; 0 = single-turn mode (after restart)"
    ),
    FunctionIndex.SET_CAN_ID: FunctionValue(1, 32, False, "new CAN ID 1..32 (ROM, after reboot)"),
    # §9 item 17: unit and signedness unstated; raw int32 (0.01° is likely, UNVERIFIED).
    FunctionIndex.MAX_POSITIVE_ANGLE: FunctionValue(
        *_INT32, True, "max positive angle, raw int32 (unit unstated)"
    ),
    FunctionIndex.MAX_NEGATIVE_ANGLE: FunctionValue(
        *_INT32, True, "max negative angle, raw int32 (unit unstated)"
    ),
    FunctionIndex.ERROR_AUTO_RECOVERY: FunctionValue(
        0, 1, False, "1 = over/under-voltage and over-speed errors recover automatically; 0 = not", ONLY_V4_4
    ),
}


class SpinDirection(enum.IntEnum):
    """0xA6 spin direction (§4.22)."""

    CLOCKWISE = 0x00
    COUNTER_CLOCKWISE = 0x01


class RunMode(enum.IntEnum):
    """0x70 operating mode (§4.27). Other values (after 0x80, in motion mode) are undefined and are
    passed through as plain ints (§9 item 27)."""

    CURRENT_LOOP = 0x01
    SPEED_LOOP = 0x02
    POSITION_LOOP = 0x03


class StatusCommand(enum.IntEnum):
    """Commands whose reply is the shared "status 2" layout R2 (§3.1).

    Its members are the commands declared ``MyActuatorCommand[StatusReply]``: ``codec.py`` checks at
    import that the two agree (an enum keeps its members typed for a user's mypy)."""

    READ_STATUS_2 = 0x9C
    TORQUE_CONTROL = 0xA1
    SPEED_CONTROL = 0xA2
    ABSOLUTE_POSITION = 0xA4
    INCREMENTAL_POSITION = 0xA8
    FORCE_POSITION = 0xA9
    POSITION_SPEED_FEEDFORWARD = 0x72  # V4.4 only
    POSITION_TORQUE_FEEDFORWARD = 0x73  # V4.4 only


#: The revisions of each command answered with the shared R2 layout (its reply's availability): the
#: command classes' ``REVISIONS``, said here, below the replies, for ``StatusReply`` to read;
#: ``codec.py`` checks at import that the two agree.
STATUS_COMMAND_REVISIONS: dict[StatusCommand, frozenset[Revision]] = {
    StatusCommand.READ_STATUS_2: ALL_REVISIONS,
    StatusCommand.TORQUE_CONTROL: ALL_REVISIONS,
    StatusCommand.SPEED_CONTROL: ALL_REVISIONS,
    StatusCommand.ABSOLUTE_POSITION: ALL_REVISIONS,
    StatusCommand.INCREMENTAL_POSITION: ALL_REVISIONS,
    StatusCommand.FORCE_POSITION: ALL_REVISIONS,
    StatusCommand.POSITION_SPEED_FEEDFORWARD: ONLY_V4_4,
    StatusCommand.POSITION_TORQUE_FEEDFORWARD: ONLY_V4_4,
}


class StreamableCommand(enum.IntEnum):
    """Commands 0xB6 can stream (§4.36). 0x9E is listed by the manuals but never defined, so it is
    left out (§9 item 18: do not stream it). Its members are the commands declared ``STREAMABLE``
    (checked at import by ``codec.py``)."""

    ENCODER_POSITION = 0x60
    ENCODER_RAW = 0x61
    ENCODER_OFFSET = 0x62
    MULTI_TURN_ANGLE = 0x92
    STATUS_1 = 0x9A
    STATUS_2 = 0x9C
    STATUS_3 = 0x9D


class ErrorFlags(enum.IntFlag, boundary=enum.KEEP):
    """0x9A ``errorState`` bits (§4.14: codes from [002], conditions from [000]).

    Unknown bits (0x0001, 0x0020, 0x0200, 0x0400, 0x8000 are undefined) are kept, not rejected
    (``boundary=KEEP``), so a reply from newer firmware still decodes; ``ErrorFlags(0x8000)`` shows as
    an unnamed value.
    """

    NONE = 0
    STALL = 0x0002
    LOW_VOLTAGE = 0x0004
    OVER_VOLTAGE = 0x0008
    PHASE_OVERCURRENT = 0x0010
    POWER_OVERRUN = 0x0040
    CALIBRATION_WRITE_ERROR = 0x0080
    OVER_SPEED = 0x0100
    COMPONENT_OVER_TEMPERATURE = 0x0800
    MOTOR_OVER_TEMPERATURE = 0x1000
    ENCODER_CALIBRATION_ERROR = 0x2000
    ENCODER_DATA_ERROR = 0x4000

    @property
    def known(self) -> ErrorFlags:
        """The defined bits of this value."""
        return ErrorFlags(self & _KNOWN_BITS)

    @property
    def unknown_bits(self) -> int:
        """The bits no manual defines."""
        return int(self) & ~_KNOWN_BITS

    def names(self) -> list[str]:
        """The names of the defined bits set, lowest first (``["LOW_VOLTAGE"]``)."""
        return [f.name for f in ErrorFlags if f and f in self and f.name is not None]


_KNOWN_BITS = 0
for _flag in ErrorFlags:
    _KNOWN_BITS |= int(_flag)


@dataclass(frozen=True, slots=True)
class ErrorFlagInfo:
    """What one 0x9A error bit means, and when it sets and clears (§4.14)."""

    description: str
    trigger: str
    recovery: str
    auto_recoverable: bool | None  # None: the manuals do not say


ERROR_FLAG_INFO: dict[ErrorFlags, ErrorFlagInfo] = {
    ErrorFlags.STALL: ErrorFlagInfo(
        "motor stall", "current above Stall Current for longer than Stall Time", "not auto-recoverable", False
    ),
    ErrorFlags.LOW_VOLTAGE: ErrorFlagInfo(
        "low voltage", "bus voltage below Undervoltage Protection Voltage", "clears when it rises above", True
    ),
    ErrorFlags.OVER_VOLTAGE: ErrorFlagInfo(
        "over-voltage", "bus voltage above Overvoltage Protection Voltage", "clears when it drops below", True
    ),
    ErrorFlags.PHASE_OVERCURRENT: ErrorFlagInfo(
        "phase over-current", "current above Maximum Current", "latched, not auto-recoverable", False
    ),
    ErrorFlags.POWER_OVERRUN: ErrorFlagInfo("power overrun", "not stated", "not stated", None),
    ErrorFlags.CALIBRATION_WRITE_ERROR: ErrorFlagInfo(
        "calibration parameter write error", "not stated", "not stated", None
    ),
    ErrorFlags.OVER_SPEED: ErrorFlagInfo(
        "over-speed", "input speed above Maximum Speed", "clears when below", True
    ),
    ErrorFlags.COMPONENT_OVER_TEMPERATURE: ErrorFlagInfo(
        "component (PCB) over-temperature", "PCB above 110 °C", "clears below 90 °C", True
    ),
    ErrorFlags.MOTOR_OVER_TEMPERATURE: ErrorFlagInfo(
        "motor over-temperature",
        "stator above Overtemperature Protection Temperature",
        "clears below Overtemperature Recovery Temperature",
        True,
    ),
    ErrorFlags.ENCODER_CALIBRATION_ERROR: ErrorFlagInfo(
        "encoder calibration error", "calibration failed", "not auto-recoverable", False
    ),
    ErrorFlags.ENCODER_DATA_ERROR: ErrorFlagInfo(
        "encoder data error", "abnormal encoder data", "not auto-recoverable", False
    ),
}
# Auto-recovery of LOW_VOLTAGE, OVER_VOLTAGE and OVER_SPEED can be switched off with 0x20 index 8 (V4.4).


class IndicatorLevel(enum.IntEnum):
    """Fault level shown by the indicator light (§7)."""

    LEVEL_1 = 1  # fast flashing: not recoverable, check the motor and restart it
    LEVEL_2 = 2  # slow flashing: recovers when the condition clears, light returns to solid


@dataclass(frozen=True, slots=True)
class Fault:
    """One row of the manuals' fault table (§7) and the 0x9A bit that reports it, if any."""

    name: str
    description: str
    level: IndicatorLevel
    flag: ErrorFlags | None


FAULTS: tuple[Fault, ...] = (
    Fault(
        "hardware over-current",
        "current over limit: short circuit, phase loss, loss of control, damage",
        IndicatorLevel.LEVEL_1,
        None,  # no 0x9A bit is documented for it
    ),
    Fault(
        "stall error",
        "current reached the stall current at very low speed for some time (overload)",
        IndicatorLevel.LEVEL_1,
        ErrorFlags.STALL,
    ),
    Fault(
        "under-voltage",
        "input below the set undervoltage value",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.LOW_VOLTAGE,
    ),
    Fault(
        "over-voltage",
        "input above the set overvoltage value",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.OVER_VOLTAGE,
    ),
    Fault(
        "phase-current over-current",
        "software-detected over-current",
        IndicatorLevel.LEVEL_1,
        ErrorFlags.PHASE_OVERCURRENT,
    ),
    Fault(
        "power overrun",
        "input current over limit (overload or over-speed)",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.POWER_OVERRUN,
    ),
    Fault(
        # The fault table says "read" error where 0x9A says "write" error (§9 item 25).
        "calibration parameter read error",
        "parameter write failure caused parameter loss",
        IndicatorLevel.LEVEL_1,
        ErrorFlags.CALIBRATION_WRITE_ERROR,
    ),
    Fault(
        "over-speed",
        "speed over limit (over-voltage, being back-driven)",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.OVER_SPEED,
    ),
    Fault(
        "motor over-temperature",
        "temperature over the set value",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.MOTOR_OVER_TEMPERATURE,
    ),
    Fault(
        # Level 2 in the fault table although 0x9A calls it non-recoverable (§9 item 25).
        "encoder calibration error",
        "calibration result deviates too much",
        IndicatorLevel.LEVEL_2,
        ErrorFlags.ENCODER_CALIBRATION_ERROR,
    ),
)


@dataclass(frozen=True, slots=True)
class BaudRateSetting:
    """The link rates one 0xB4 index selects. ``None``: the interface is off or not stated."""

    rs485_bps: int | None
    can_bps: int | None


# §4.34: [002]'s mapping, the consistent one ([000]'s table and examples contradict each other). The
# command carries the raw index; indexes 3 and 4 (third-party: RS485 1.5 M / 2.5 M) are UNVERIFIED.
BAUD_RATE_INDEXES: dict[int, BaudRateSetting] = {
    0: BaudRateSetting(115_200, 500_000),
    1: BaudRateSetting(500_000, 1_000_000),
    2: BaudRateSetting(1_000_000, None),
}


class Rs485MotionMode(enum.IntEnum):
    """Mode byte of the RS485 motion-mode frame ([000] §6)."""

    STOP = 0x00
    SERVO = 0x0A

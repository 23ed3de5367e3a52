"""MyActuator replies: one frozen dataclass per reply layout of myactuator-v4.md §3-§4, plus ``Echo``.

Echo replies (§0: the reply DATA equals the request DATA; 0x20, 0x31, 0x32, 0x43, 0x63, 0x77, 0x78,
0x79 write, 0x80, 0x81, 0xB3) are represented by :class:`Echo` holding the decoded command itself, so a
caller gets the same typed object it sent (``Echo(command=MotorShutdown())``).

Layouts that differ by revision have one class per layout, and ``codec.decode_reply`` picks by revision:

* 0x94: :class:`SingleTurnAngleReply` (V4.4, int32 ±180°) / :class:`CircleAngleReply` (V4.3, uint16).
* 0xB5: :class:`ModelPartReply` (V4.4, 5 characters of three) / :class:`ModelReply` (V4.3, 7 characters).

Reply fields are bounded by their integer types and, where a manual states a range for the reported
value, by that range (0x94's angle, 0x70's modes, 0x42's acceleration): a value outside it is not data,
so decoding it raises ProtocolError naming the field and the value (each range cites its section).
Command limits do not bound replies otherwise: a reply reports what the motor measured. NULL bytes are
ignored on decode.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from typing import Any, ClassVar, Generic, Self

if sys.version_info >= (3, 13):
    from typing import TypeVar
else:  # a default, so a command declares its reply as a bare ``Echo``
    from typing_extensions import TypeVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._message import Reply
from servobus.protocols.myactuator._layout import (
    PAYLOAD_SIZE,
    AsciiField,
    BoolField,
    EnumField,
    Fixed,
    FlagsField,
    Float32Field,
    LayoutMismatch,
    MyActuatorCommand,
    MyActuatorMessage,
    check_payload,
)
from servobus.protocols.myactuator.enums import (
    ACCELERATION_MIN_DPS_S,
    STATUS_COMMAND_REVISIONS,
    AccelIndex,
    ErrorFlags,
    PidIndex,
    RunMode,
    StatusCommand,
)
from servobus.protocols.myactuator.revision import (
    ONLY_V4_3,
    ONLY_V4_4,
    V4_4_MANUAL_DATE,
    Revision,
    revision_from_version_date,
    revision_names,
)

__all__ = [
    "EVENTS",
    "AccelerationReply",
    "CanIdLayout",
    "CanIdReply",
    "CircleAngleReply",
    "CommunicationTimeoutTripped",
    "Echo",
    "EncoderOffsetReply",
    "EncoderPositionReply",
    "EncoderRawReply",
    "ModelPartReply",
    "ModelReply",
    "MultiTurnAngleReply",
    "MyActuatorReply",
    "PidReply",
    "RunModeReply",
    "RunTimeReply",
    "SingleTurnAngleReply",
    "SingleTurnEncoderReply",
    "SingleTurnStatusReply",
    "Status1Reply",
    "Status3Reply",
    "StatusReply",
    "VersionDateReply",
    "ZeroOffsetReply",
    "guess_single_turn_revision",
    "join_model",
]

C = TypeVar("C", bound=MyActuatorCommand[Any], default=MyActuatorCommand[Any])


class MyActuatorReply(Fixed, Reply):
    """A MyActuator reply with the standard 8-byte layout."""

    __slots__ = ()


# ---- echo ----


@dataclass(frozen=True, slots=True, kw_only=True)
class Echo(MyActuatorMessage, Reply, Generic[C]):
    """The reply of a command answered by repeating its data: holds that command, decoded.

    ``decode`` is per command class (``Echo.decode(data, MotorShutdown)``); ``codec.decode_reply`` knows
    which commands echo.
    """

    TITLE: ClassVar[str] = "echo"
    command: C

    def __post_init__(self) -> None:
        if not isinstance(self.command, MyActuatorCommand):
            raise ValueError(f"command={self.command!r} is not a MyActuator command")

    @property
    def code(self) -> int | None:
        return self.command.code

    def encode(self) -> bytes:
        return self.command.encode()

    @classmethod
    def decode(cls, data: bytes, command_type: type[C]) -> Echo[C]:
        """Decode the echo of a ``command_type`` request.

        Raises:
            ProtocolError: the data is not a valid ``command_type`` payload.
        """
        return cls(command=command_type.decode(data))

    def unavailable_reason(self, revision: Revision) -> str | None:
        return self.command.unavailable_reason(revision)


# ---- shared field specs ----

_TEMPERATURE = IntField("temperature_c", 1, signed=True)  # int8, 1 °C/LSB
_IQ = ScaledField("current_a", size=2, signed=True, counts_per_unit=100)  # 0.01 A/LSB
_SPEED_I16 = ScaledField("speed_dps", size=2, signed=True, counts_per_unit=1)  # 1 dps/LSB
_DEGREE_I16 = ScaledField("angle_deg", size=2, signed=True, counts_per_unit=1)  # 1 °/LSB, "max ±32767°"
_ANGLE_I32 = ScaledField("angle_deg", size=4, signed=True, counts_per_unit=100)  # 0.01 °/LSB


# ---- 0x30, 0x42 ----

_ACCEL_READ = ScaledField("acceleration_dps_s", size=4, signed=True, counts_per_unit=1, lo=0, hi=60000)


@dataclass(frozen=True, slots=True, kw_only=True)
class PidReply(MyActuatorReply):
    """0x30 reply: the PID parameter ``index`` and its float32 value (§4.1)."""

    CODE: ClassVar[int] = 0x30
    TITLE: ClassVar[str] = "read PID parameter"
    FIELDS = ((1, EnumField("index", 1, PidIndex)), (4, Float32Field("value")))
    index: PidIndex
    value: float


@dataclass(frozen=True, slots=True, kw_only=True)
class AccelerationReply(MyActuatorReply):
    """0x42 reply: acceleration ``index`` and its value, int32 1 dps/s (§4.4)."""

    CODE: ClassVar[int] = 0x42
    TITLE: ClassVar[str] = "read acceleration"
    # [000]/[002] §2.4 (spec §4.4): Accel 100..60000 dps/s; 0 also reads back, as 0x43 accepts it
    # (it has a documented meaning, spec §9 item 19), so 0 or 100..60000.
    FIELDS = ((1, EnumField("index", 1, AccelIndex)), (4, _ACCEL_READ))
    index: AccelIndex
    acceleration_dps_s: float

    def __post_init__(self) -> None:
        Fixed.__post_init__(self)
        if 0 < _ACCEL_READ.to_code(self.acceleration_dps_s) < ACCELERATION_MIN_DPS_S:
            raise ValueError(
                f"acceleration_dps_s={self.acceleration_dps_s!r} is outside [{ACCELERATION_MIN_DPS_S}, 60000]"
                " (or 0)"
            )


# ---- 0x60..0x64 encoder ----


def _int32_counts(name: str) -> tuple[tuple[int, IntField], ...]:
    """The one field of the encoder replies: int32 counts in DATA[4..7]."""
    return ((4, IntField(name, 4, signed=True)),)


@dataclass(frozen=True, slots=True, kw_only=True)
class EncoderPositionReply(MyActuatorReply):
    """0x60 reply: multi-turn encoder position = raw - zero offset, int32 counts (§4.6)."""

    CODE, TITLE = 0x60, "read multi-turn encoder position"
    FIELDS = _int32_counts("encoder_counts")
    encoder_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class EncoderRawReply(MyActuatorReply):
    """0x61 reply: raw multi-turn encoder position, int32 counts, the zero offset not taken off
    (§4.7)."""

    CODE, TITLE = 0x61, "read multi-turn encoder raw position"
    FIELDS = _int32_counts("raw_counts")
    raw_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class EncoderOffsetReply(MyActuatorReply):
    """0x62 reply: multi-turn encoder zero offset, int32 counts (§4.8)."""

    CODE, TITLE = 0x62, "read multi-turn encoder zero offset"
    FIELDS = _int32_counts("offset_counts")
    offset_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class ZeroOffsetReply(MyActuatorReply):
    """0x64 reply: the zero offset written to ROM, int32 counts (§4.10). It takes effect after 0x76:
    until then 0x62 reads the offset in use."""

    CODE, TITLE = 0x64, "write current position to ROM as zero"
    FIELDS = _int32_counts("offset_counts")
    offset_counts: int


# ---- 0x70 ----


@dataclass(frozen=True, slots=True, kw_only=True)
class RunModeReply(MyActuatorReply):
    """0x70 reply: operating mode in DATA[7], one of the three :class:`RunMode` values (§4.27).

    The manuals say the run mode "has the following 3 states" ([002] §2.25.3, [000] §2.26.3: current,
    speed, position loop). The spec (§9 item 27) chose to pass other values through; the manual is the
    authority and lists no other state, so any other byte is a ProtocolError naming it.
    """

    CODE: ClassVar[int] = 0x70
    TITLE: ClassVar[str] = "read operating mode"
    FIELDS = ((7, EnumField("mode", 1, RunMode)),)
    mode: RunMode


# ---- 0x79 (V4.3) ----


class CanIdLayout(Enum):
    """Where a 0x79 read reply puts the id (§4.38, §9 item 15: the two examples disagree)."""

    DATA7 = "data7"  # DATA[6] = 0, DATA[7] = ID (the RS485 example)
    REPLY_IDENTIFIER = "reply_identifier"  # DATA[6..7] = 0x240 + ID, LE (the CAN example, 42 02)
    BARE = "bare"  # DATA[6..7] = ID, LE (the reply table's definition)


_CAN_ID_RULES = ", ".join(("DATA[6]=0 and DATA[7] in 1..32", "LE 0x241..0x260", "LE 1..32"))


@dataclass(frozen=True, slots=True, kw_only=True)
class CanIdReply(MyActuatorReply):
    """0x79 read reply (V4.3): the motor id, decoded by the spec's ordered rule (§9 item 15, UNVERIFIED):

    1. DATA[6] = 0 and DATA[7] in 1..32: id = DATA[7] (RS485 example);
    2. v = DATA[6] + 256·DATA[7] in 0x241..0x260: id = v - 0x240 (CAN example);
    3. v in 1..32: id = v;
    4. anything else: ProtocolError.

    ``layout`` records which form arrived, so ``encode`` reproduces it.
    """

    CODE: ClassVar[int] = 0x79
    TITLE: ClassVar[str] = "CAN-ID setting"
    REVISIONS = ONLY_V4_3
    CONSTANTS = ((2, 1),)
    FIELDS = ((6, IntField("motor_id", 1, lo=1, hi=32)),)  # checked here; placed by encode()
    motor_id: int
    layout: CanIdLayout = CanIdLayout.REPLY_IDENTIFIER

    def __post_init__(self) -> None:
        Fixed.__post_init__(self)
        if not isinstance(self.layout, CanIdLayout):
            raise ValueError(f"layout={self.layout!r} is not a CanIdLayout")

    def encode(self) -> bytes:
        head = bytes([self.CODE, 0, 1, 0, 0, 0])
        if self.layout is CanIdLayout.DATA7:
            return head + bytes([0, self.motor_id])
        value = 0x240 + self.motor_id if self.layout is CanIdLayout.REPLY_IDENTIFIER else self.motor_id
        return head + value.to_bytes(2, "little")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        check_payload(data, cls.CODE, what=cls.__name__)
        if data[2] != 1:
            raise LayoutMismatch(f"{cls.__name__}: DATA[2] is not 0x01 (read)", raw=data, command=data[0])
        value = int.from_bytes(data[6:8], "little")
        if data[6] == 0 and 1 <= data[7] <= 32:
            return cls(motor_id=data[7], layout=CanIdLayout.DATA7)
        if 0x241 <= value <= 0x260:
            return cls(motor_id=value - 0x240, layout=CanIdLayout.REPLY_IDENTIFIER)
        if 1 <= value <= 32:
            return cls(motor_id=value, layout=CanIdLayout.BARE)
        raise ProtocolError(f"{cls.__name__}: DATA[6..7] fit none of {_CAN_ID_RULES}", raw=data, command=0x79)


# ---- 0x90 (V4.3), 0x92, 0x94 ----


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnEncoderReply(MyActuatorReply):
    """0x90 reply (V4.3 only): single-turn encoder = raw - offset, each uint16 counts (§4.11)."""

    CODE: ClassVar[int] = 0x90
    TITLE: ClassVar[str] = "read single-turn encoder"
    REVISIONS = ONLY_V4_3
    FIELDS = (
        (2, IntField("encoder_counts", 2)),
        (4, IntField("raw_counts", 2)),
        (6, IntField("offset_counts", 2)),
    )
    encoder_counts: int
    raw_counts: int
    offset_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiTurnAngleReply(MyActuatorReply):
    """0x92 reply: multi-turn output angle relative to zero, int32 0.01° (§4.12)."""

    CODE: ClassVar[int] = 0x92
    TITLE: ClassVar[str] = "read multi-turn angle"
    FIELDS = ((4, _ANGLE_I32),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnAngleReply(MyActuatorReply):
    """0x94 reply, V4.4 layout: int32 0.01° in DATA[4..7], -180..+180° (§4.13)."""

    CODE: ClassVar[int] = 0x94
    SINGLE_TURN: ClassVar[bool] = True  # (not the motor's position: servobus.limits)
    TITLE: ClassVar[str] = "read single-turn angle (int32 ±180°)"
    REVISIONS = ONLY_V4_4
    # [000] §2.12.1: "The single-turn angle range of the motor is -180° to +180°" (int32, 0.01°/LSB).
    FIELDS = ((4, ScaledField("angle_deg", size=4, signed=True, counts_per_unit=100, lo=-180, hi=180)),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CircleAngleReply(MyActuatorReply):
    """0x94 reply, V4.3 layout: ``circleAngle`` uint16 0.01° in DATA[6..7], 0..359.99°, from the encoder
    zero, increasing clockwise (§4.13)."""

    CODE: ClassVar[int] = 0x94
    SINGLE_TURN: ClassVar[bool] = True  # (not the motor's position: servobus.limits)
    TITLE: ClassVar[str] = "read single-turn angle (uint16 0..359.99°)"
    REVISIONS = ONLY_V4_3
    # [002] §2.13.3: circleAngle "数值范围 0~35999" (0..359.99°, 0.01°/LSB).
    FIELDS = ((6, ScaledField("angle_deg", size=2, signed=False, counts_per_unit=100, lo=0, hi=359.99)),)
    angle_deg: float


def guess_single_turn_revision(data: bytes) -> Revision | None:
    """Which revision's 0x94 layout ``data`` is, by §4.13's rule (a fallback to an explicit revision).

    Returns:
        V4_4 if DATA[4..5] ≠ 0 and DATA[6..7] = 0, or DATA[6..7] = 0xFFFF; V4_3 if DATA[4..5] = 0 and
        0 < DATA[6..7] ≤ 35999; None when it cannot tell (all zero reads 0° in both) or ``data`` is not
        an 8-byte 0x94 payload.
    """
    if len(data) != PAYLOAD_SIZE or data[0] != 0x94:
        return None
    low, high = int.from_bytes(data[4:6], "little"), int.from_bytes(data[6:8], "little")
    if (low != 0 and high == 0) or high == 0xFFFF:
        return Revision.V4_4
    if low == 0 and 0 < high <= 35999:
        return Revision.V4_3
    return None


# ---- 0x9A, R2 (0x9C and control commands), R2-A6, 0x9D ----


@dataclass(frozen=True, slots=True, kw_only=True)
class Status1Reply(MyActuatorReply):
    """0x9A reply: temperatures, brake, supply voltage and error flags (§4.14).

    ``mos_temperature_c`` (DATA[2]) is listed but not described by the manuals; the tables print it as
    ``DATA[2] = (uint8_t)(motorMOStemperature)`` ([002] §2.14.3, [000] §2.13.3), so it is read as uint8
    0..255, 1 °C/LSB like DATA[1] (the unit is §9 item 16's guess, UNVERIFIED). ``brake_released``:
    True when the brake-release command is in effect. ``errors`` keeps undefined bits (see ``ErrorFlags``).
    """

    CODE: ClassVar[int] = 0x9A
    TITLE: ClassVar[str] = "read status 1 and error flags"
    FAULTS: ClassVar[str | None] = "errors"
    FIELDS = (
        (1, _TEMPERATURE),
        (2, IntField("mos_temperature_c", 1)),  # uint8 as printed (§4.14)
        (3, BoolField("brake_released")),
        (4, ScaledField("voltage_v", size=2, signed=False, counts_per_unit=10)),
        (6, FlagsField("errors", 2, ErrorFlags)),
    )
    temperature_c: int
    mos_temperature_c: int
    brake_released: bool
    voltage_v: float
    errors: ErrorFlags = ErrorFlags.NONE


@dataclass(frozen=True, slots=True, kw_only=True)
class StatusReply(MyActuatorReply):
    """The "status 2" layout R2 (§3.1): reply to 0x9C and to 0xA1, 0xA2, 0xA4, 0xA8, 0xA9, 0x72, 0x73.

    ``command`` is the DATA[0] it answers. ``angle_deg`` is the output angle in whole degrees (int16,
    "max ±32767°"; use 0x92 for an unambiguous multi-turn angle, §9 item 28).
    """

    CODE: ClassVar[int | None] = None  # DATA[0] is the ``command`` field
    TITLE: ClassVar[str] = "status reply (R2)"
    FIELDS = (
        (0, EnumField("command", 1, StatusCommand)),
        (1, _TEMPERATURE),
        (2, _IQ),
        (4, _SPEED_I16),
        (6, _DEGREE_I16),
    )
    temperature_c: int
    current_a: float
    speed_dps: float
    angle_deg: float
    command: StatusCommand = StatusCommand.READ_STATUS_2

    @property
    def code(self) -> int:
        return int(self.command)

    def unavailable_reason(self, revision: Revision) -> str | None:
        # The revisions of the command it answers (its declaration, which codec.py checks this against).
        revisions = STATUS_COMMAND_REVISIONS[self.command]
        if revision in revisions:
            return None
        names = revision_names(revisions)
        title = f"0x{self.code:02X} reply ({self.command.name})"
        return f"{title} exists only in {names} (revision {revision.name} given)"


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnStatusReply(MyActuatorReply):
    """0xA6 reply, R2 with DATA[6..7] = encoder counts from the zero, uint16 (§3.2)."""

    CODE: ClassVar[int] = 0xA6
    TITLE: ClassVar[str] = "single-turn position control"
    FIELDS = ((1, _TEMPERATURE), (2, _IQ), (4, _SPEED_I16), (6, IntField("encoder_counts", 2)))
    temperature_c: int
    current_a: float
    speed_dps: float
    encoder_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class Status3Reply(MyActuatorReply):
    """0x9D reply: temperature and the three phase currents, int16 0.01 A (§4.16)."""

    CODE: ClassVar[int] = 0x9D
    TITLE: ClassVar[str] = "read status 3"
    FIELDS = (
        (1, _TEMPERATURE),
        (2, ScaledField("phase_a_current_a", size=2, signed=True, counts_per_unit=100)),
        (4, ScaledField("phase_b_current_a", size=2, signed=True, counts_per_unit=100)),
        (6, ScaledField("phase_c_current_a", size=2, signed=True, counts_per_unit=100)),
    )
    temperature_c: int
    phase_a_current_a: float
    phase_b_current_a: float
    phase_c_current_a: float


# ---- 0xB1, 0xB2, 0xB5 ----


@dataclass(frozen=True, slots=True, kw_only=True)
class RunTimeReply(MyActuatorReply):
    """0xB1 reply: milliseconds since power-up or reset, uint32 (§4.31)."""

    CODE: ClassVar[int] = 0xB1
    TITLE: ClassVar[str] = "read system run time"
    FIELDS = ((4, IntField("run_time_ms", 4)),)
    run_time_ms: int


@dataclass(frozen=True, slots=True, kw_only=True)
class VersionDateReply(MyActuatorReply):
    """0xB2 reply: firmware version date as the decimal YYYYMMDD, uint32 (§4.32)."""

    CODE: ClassVar[int] = 0xB2
    TITLE: ClassVar[str] = "read software version date"
    FIELDS = ((4, IntField("version_date", 4)),)
    version_date: int

    def revision(self, *, cutoff: int = V4_4_MANUAL_DATE) -> Revision:
        """The revision this firmware is taken to speak (``revision_from_version_date``'s rule).

        Raises:
            ValueError: the date is not a plausible YYYYMMDD.
        """
        return revision_from_version_date(self.version_date, cutoff=cutoff)


@dataclass(frozen=True, slots=True, kw_only=True)
class ModelReply(MyActuatorReply):
    """0xB5 reply, V4.3 layout: the model name, up to 7 ASCII characters in DATA[1..7] (§4.35)."""

    CODE: ClassVar[int] = 0xB5
    TITLE: ClassVar[str] = "read motor model (single frame)"
    REVISIONS = ONLY_V4_3
    FIELDS = ((1, AsciiField("model", 7)),)
    model: str


@dataclass(frozen=True, slots=True, kw_only=True)
class ModelPartReply(MyActuatorReply):
    """0xB5 reply, V4.4 layout: DATA[1] = 0x01, DATA[2] = ``part`` 1..3, DATA[3..7] = up to 5 characters
    of the model (§4.35). Trailing NULs and spaces are stripped (padding is not specified)."""

    CODE: ClassVar[int] = 0xB5
    TITLE: ClassVar[str] = "read motor model (indexed)"
    REVISIONS = ONLY_V4_4
    CONSTANTS = ((1, 0x01),)
    FIELDS = ((2, IntField("part", 1, lo=1, hi=3)), (3, AsciiField("text", 5)))
    part: int
    text: str


def join_model(parts: Iterable[ModelPartReply]) -> str:
    """The model name from V4.4's indexed 0xB5 replies, in part order (parts may come in any order;
    a missing part reads as empty).

    Raises:
        ValueError: the same part given twice.
    """
    by_part: dict[int, str] = {}
    for reply in parts:
        if reply.part in by_part:
            raise ValueError(f"model part {reply.part} given twice")
        by_part[reply.part] = reply.text
    return "".join(by_part.get(i, "") for i in (1, 2, 3))


# ---- frames the motor sends of itself ----


@dataclass(frozen=True, slots=True, kw_only=True)
class CommunicationTimeoutTripped(MyActuatorReply):
    """0xF1 on 0x240+ID: the motor's communication watchdog (0xB3, §4.33) tripped: output off, brake locked.

    In neither manual; reported for V3 drivers (2b-t/myactuator_rmd_ros, pull request 4): the motor
    sends 0xF1 "without data" when the protection trips and about every second while it lasts, and
    echoes the first command after communication resumes without executing it (the next one runs).
    Which bytes follow DATA[0] is not known: any length and any further bytes read as this event
    (the simulator sends ``F1 00 00 00 00 00 00 00``).
    """

    CODE: ClassVar[int] = 0xF1
    TITLE: ClassVar[str] = "communication timeout tripped"
    EVENT: ClassVar[str | None] = "comm_tripped"
    EVENT_REASON: ClassVar[str] = "communication watchdog tripped (0xF1)"
    FIELDS = ()

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Any payload whose DATA[0] is 0xF1 (see the class docstring).

        Raises:
            ProtocolError: an empty payload or another DATA[0].
        """
        if not data or data[0] != cls.CODE:
            command = data[0] if data else None
            raise ProtocolError(f"{cls.__name__}: DATA[0] is not 0xF1", raw=data, command=command)
        return cls()


#: Every frame a MyActuator motor sends of itself that answers no command (the codec's REPLIES table
#: takes them in; the bound codec classifies them REPORT). The other unsolicited frames are replies of
#: commands: 0xB6 stream frames (STREAM) and 0x9A error reports (REPORT, with 0x20 index 3 on).
EVENTS: tuple[type[MyActuatorReply], ...] = (CommunicationTimeoutTripped,)

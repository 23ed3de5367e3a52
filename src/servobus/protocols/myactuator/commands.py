"""MyActuator requests other than closed-loop control: parameters, reads, zeroing, system, ids.

One frozen, slotted, keyword-only dataclass per request of myactuator-v4.md §4 (closed-loop control
commands are in :mod:`.commands_control`, motion mode in :mod:`.motion`). Each validates its fields on
construction (ValueError naming field, value and limits), encodes to the 8 data bytes with ``encode()``
(the same bytes on CAN and inside an RS485 frame) and decodes them with ``decode(data)``.

``encode()`` knows nothing of revisions: a V4.3-only command still encodes. Sending it to a V4.4 motor
is refused by ``codec.encode_request`` / ``codec.check_available``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField, check_range, round_half_away
from servobus.protocols._message import R
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator import replies as rep
from servobus.protocols.myactuator._layout import (
    BoolField,
    EnumField,
    Fixed,
    Float32Field,
    MyActuatorCommand,
    StepField,
    check_payload,
    construct,
)
from servobus.protocols.myactuator.enums import (
    ACCELERATION_MIN_DPS_S,
    BAUD_RATE_INDEXES,
    FUNCTION_VALUES,
    AccelIndex,
    BaudRateSetting,
    FunctionIndex,
    PidIndex,
    StreamableCommand,
)
from servobus.protocols.myactuator.revision import ONLY_V4_3, ONLY_V4_4, Revision, revision_names

__all__ = [
    "ActiveReply",
    "BrakeLock",
    "BrakeRelease",
    "FunctionControl",
    "MotorShutdown",
    "MotorStop",
    "MyActuatorCommand",
    "ReadAcceleration",
    "ReadCanId",
    "ReadEncoderOffset",
    "ReadEncoderPosition",
    "ReadEncoderRaw",
    "ReadModel",
    "ReadModelPart",
    "ReadMultiTurnAngle",
    "ReadPid",
    "ReadRunMode",
    "ReadRunTime",
    "ReadSingleTurnAngle",
    "ReadSingleTurnEncoder",
    "ReadStatus1",
    "ReadStatus2",
    "ReadStatus3",
    "ReadVersionDate",
    "SetBaudRate",
    "SetCanId",
    "SetCommTimeout",
    "SystemReset",
    "WriteAcceleration",
    "WriteCurrentPositionAsZero",
    "WriteEncoderZero",
    "WritePidRam",
    "WritePidRom",
]


# ---- 0x20 function control (§4.37) ----

_FUNCTION_INDEX = EnumField("index", 1, FunctionIndex)
_UINT32 = IntField("value", 4)
_INT32 = IntField("value", 4, signed=True)


@dataclass(frozen=True, slots=True, kw_only=True)
class FunctionControl(MyActuatorCommand[rep.Echo]):
    """0x20 function control: ``index`` selects the function, ``value`` is its 32-bit argument.

    What each index accepts is :data:`enums.FUNCTION_VALUES` (1: 0; 2, 3, 4, 8: 0/1; 5: motor id 1..32;
    6, 7: raw int32, sent signed). Index 8 (error auto-recovery) exists only in V4.4. The reply is an
    echo. The classmethods build each function by name.
    """

    CODE: ClassVar[int] = 0x20
    TITLE: ClassVar[str] = "function control"
    SLOW = ECHO = NOTED = True
    FIELDS = ((1, _FUNCTION_INDEX),)
    index: FunctionIndex
    value: int = 0

    def __post_init__(self) -> None:
        Fixed.__post_init__(self)
        meaning = FUNCTION_VALUES[self.index]
        if isinstance(self.value, bool) or not isinstance(self.value, int):
            raise ValueError(f"value={self.value!r} is not an integer")
        # Every per-index range lies inside the 32-bit field, so this also bounds the encoding.
        check_range(f"value (index {self.index.name})", self.value, meaning.lo, meaning.hi)

    def encode(self) -> bytes:
        signed = FUNCTION_VALUES[self.index].signed
        return Fixed.encode(self)[:4] + self.value.to_bytes(4, "little", signed=signed)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        check_payload(data, cls.CODE, what=cls.__name__)
        try:
            index = _FUNCTION_INDEX.decode(data, 1)
        except ValueError as exc:
            raise ProtocolError(f"{cls.__name__}: {exc}", raw=data, command=data[0]) from None
        spec = _INT32 if FUNCTION_VALUES[FunctionIndex(index)].signed else _UINT32
        return construct(cls, data, {"index": index, "value": spec.decode(data, 4)})

    def unavailable_reason(self, revision: Revision) -> str | None:
        revisions = FUNCTION_VALUES[self.index].revisions
        if revision in revisions:
            return None
        return (
            f"0x20 function control index {int(self.index)} ({self.index.name}) exists only in "
            f"{revision_names(revisions)} (revision {revision.name} given)"
        )

    @property
    def meaning(self) -> str:
        """What ``value`` means for this index (§4.37)."""
        return FUNCTION_VALUES[self.index].meaning

    @classmethod
    def clear_multi_turn(cls) -> Self:
        """Index 1: clear the multi-turn value, update the zero and save (after restart)."""
        return cls(index=FunctionIndex.CLEAR_MULTI_TURN, value=0)

    @classmethod
    def can_id_filter(cls, enabled: bool) -> Self:
        """Index 2: CAN-ID filter on/off (off is needed for 0x280 broadcasts). Saved in FLASH."""
        return cls(index=FunctionIndex.CAN_ID_FILTER, value=int(enabled))

    @classmethod
    def error_reporting(cls, enabled: bool) -> Self:
        """Index 3: send 0x9A every 100 ms while an error is present."""
        return cls(index=FunctionIndex.ERROR_REPORTING, value=int(enabled))

    @classmethod
    def save_multi_turn(cls, enabled: bool) -> Self:
        """Index 4: keep the multi-turn value over power-off (off: single-turn mode)."""
        return cls(index=FunctionIndex.SAVE_MULTI_TURN, value=int(enabled))

    @classmethod
    def set_can_id(cls, motor_id: int) -> Self:
        """Index 5: new CAN id 1..32 (ROM, after reboot)."""
        return cls(index=FunctionIndex.SET_CAN_ID, value=motor_id)

    @classmethod
    def max_positive_angle(cls, raw: int) -> Self:
        """Index 6: maximum positive angle, raw int32 (unit not stated; 0.01° likely, §9 item 17)."""
        return cls(index=FunctionIndex.MAX_POSITIVE_ANGLE, value=raw)

    @classmethod
    def max_negative_angle(cls, raw: int) -> Self:
        """Index 7: maximum negative angle, raw int32 (as index 6)."""
        return cls(index=FunctionIndex.MAX_NEGATIVE_ANGLE, value=raw)

    @classmethod
    def error_auto_recovery(cls, enabled: bool) -> Self:
        """Index 8 (V4.4): over/under-voltage and over-speed errors clear by themselves."""
        return cls(index=FunctionIndex.ERROR_AUTO_RECOVERY, value=int(enabled))


# ---- 0x30..0x32 PID parameters (§4.1-4.3) ----

_PID_INDEX = EnumField("index", 1, PidIndex)
_PID_VALUE = Float32Field("value")


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadPid(MyActuatorCommand[rep.PidReply]):
    """0x30 read one PID parameter."""

    CODE: ClassVar[int] = 0x30
    TITLE: ClassVar[str] = "read PID parameter"
    READ = True
    FIELDS = ((1, _PID_INDEX),)
    index: PidIndex


@dataclass(frozen=True, slots=True, kw_only=True)
class WritePidRam(MyActuatorCommand[rep.Echo]):
    """0x31 write one PID parameter (float32) to RAM, lost at power-off."""

    CODE: ClassVar[int] = 0x31
    TITLE: ClassVar[str] = "write PID parameter to RAM"
    ECHO = True
    FIELDS = ((1, _PID_INDEX), (4, _PID_VALUE))
    index: PidIndex
    value: float


@dataclass(frozen=True, slots=True, kw_only=True)
class WritePidRom(MyActuatorCommand[rep.Echo]):
    """0x32 write one PID parameter (float32) to ROM. [000]: saved only while the motor is disabled.
    Reply: echo."""

    CODE: ClassVar[int] = 0x32
    TITLE: ClassVar[str] = "write PID parameter to ROM"
    SLOW = ECHO = True
    FIELDS = ((1, _PID_INDEX), (4, _PID_VALUE))
    index: PidIndex
    value: float


# ---- 0x42/0x43 acceleration (§4.4, §4.5) ----

_ACCEL_INDEX = EnumField("index", 1, AccelIndex)
# §9 item 19: sent as uint32; the manuals' range is 100..60000, and 0 has a documented meaning (0xA2/0xA4
# "acceleration = 0": no planning), asked for with None (issue 19). 0..99 as numbers are refused.
_ACCEL_WRITE = SpecialZero(
    ScaledField("acceleration_dps_s", size=4, signed=False, counts_per_unit=1, lo=0, hi=60000),
    meaning=(
        "means no planning: position tracks the target directly, speed is limited by the current "
        "(§4.5, §4.21)"
    ),
    unit="dps/s",
)


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadAcceleration(MyActuatorCommand[rep.AccelerationReply]):
    """0x42 read one acceleration value."""

    CODE: ClassVar[int] = 0x42
    TITLE: ClassVar[str] = "read acceleration"
    READ = True
    FIELDS = ((1, _ACCEL_INDEX),)
    index: AccelIndex


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteAcceleration(MyActuatorCommand[rep.Echo]):
    """0x43 write one acceleration (1 dps/s) to RAM and ROM: 100..60000, or ``None`` for 0 on the wire
    (no planning: direct tracking, §4.21). The number 0 is refused: ask for "no planning" with None.
    Reply: echo."""

    CODE: ClassVar[int] = 0x43
    TITLE: ClassVar[str] = "write acceleration"
    ECHO = True
    FIELDS = ((1, _ACCEL_INDEX), (4, _ACCEL_WRITE))
    index: AccelIndex
    acceleration_dps_s: float | None

    def __post_init__(self) -> None:
        Fixed.__post_init__(self)
        if self.acceleration_dps_s is None:
            return
        if 0 < _ACCEL_WRITE.to_code(self.acceleration_dps_s) < ACCELERATION_MIN_DPS_S:
            raise ValueError(
                f"acceleration_dps_s={self.acceleration_dps_s!r} is outside [{ACCELERATION_MIN_DPS_S}, "
                f"{_ACCEL_WRITE.limits[1]!r}] (acceleration_dps_s=None asks for 0: no planning)"
            )


# ---- commands without arguments ----
# One declaration a line: code and title, then what the command is (its reply type is in its base).


class _NoArgs(MyActuatorCommand[R]):
    """A request whose DATA[1..7] are all NULL."""

    __slots__ = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadEncoderPosition(_NoArgs[rep.EncoderPositionReply]):
    """0x60 read the multi-turn encoder position: the raw position (0x61) minus the zero offset
    (0x62), in encoder counts."""

    CODE, TITLE, READ, STREAMABLE = 0x60, "read multi-turn encoder position", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadEncoderRaw(_NoArgs[rep.EncoderRawReply]):
    """0x61 read the raw multi-turn encoder position."""

    CODE, TITLE, READ, STREAMABLE = 0x61, "read multi-turn encoder raw position", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadEncoderOffset(_NoArgs[rep.EncoderOffsetReply]):
    """0x62 read the multi-turn encoder zero offset."""

    CODE, TITLE, READ, STREAMABLE = 0x62, "read multi-turn encoder zero offset", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteEncoderZero(MyActuatorCommand[rep.Echo]):
    """0x63 write an encoder value (int32 counts) to ROM as the zero; effective after restart. Reply:
    echo. (§9 item 11: the manuals' ``>>8`` for DATA[6..7] is a typo; the value is int32 LE.)"""

    CODE: ClassVar[int] = 0x63
    TITLE: ClassVar[str] = "write encoder value to ROM as zero"
    SLOW = ECHO = True
    FIELDS = ((4, IntField("offset_counts", 4, signed=True)),)
    offset_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteCurrentPositionAsZero(_NoArgs[rep.ZeroOffsetReply]):
    """0x64 write the current position to ROM as the zero (effective after 0x76)."""

    CODE, TITLE, SLOW = 0x64, "write current position to ROM as zero", True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadRunMode(_NoArgs[rep.RunModeReply]):
    """0x70 read the operating mode."""

    CODE, TITLE, READ = 0x70, "read operating mode", True


@dataclass(frozen=True, slots=True, kw_only=True)
class SystemReset(_NoArgs[None]):
    """0x76 reset the system. **No reply**: the program restarts."""

    CODE, TITLE, NOTED = 0x76, "system reset", True
    NO_REPLY = "system reset: the program restarts and sends no reply (§4.28)"


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeRelease(_NoArgs[rep.Echo]):
    """0x77 open the holding brake."""

    CODE, TITLE, SLOW = 0x77, "brake release", True


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeLock(_NoArgs[rep.Echo]):
    """0x78 close the holding brake."""

    CODE, TITLE, SLOW = 0x78, "brake lock", True


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorShutdown(_NoArgs[rep.Echo]):
    """0x80 motor off: output off, running state cleared."""

    CODE, TITLE = 0x80, "motor shutdown"


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorStop(_NoArgs[rep.Echo]):
    """0x81 stop and hold; the closed loop stays active."""

    CODE, TITLE = 0x81, "motor stop"


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadSingleTurnEncoder(_NoArgs[rep.SingleTurnEncoderReply]):
    """0x90 read the single-turn encoder (V4.3 only; removed in V4.4)."""

    CODE, TITLE, READ, REVISIONS = 0x90, "read single-turn encoder", True, ONLY_V4_3


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadMultiTurnAngle(_NoArgs[rep.MultiTurnAngleReply]):
    """0x92 read the multi-turn angle."""

    CODE, TITLE, READ, STREAMABLE = 0x92, "read multi-turn angle", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadSingleTurnAngle(_NoArgs[rep.SingleTurnAngleReply | rep.CircleAngleReply]):
    """0x94 read the single-turn angle. The reply layout differs by revision: ``SingleTurnAngleReply``
    (V4.4, int32 ±180°) or ``CircleAngleReply`` (V4.3, uint16 0..359.99°)."""

    CODE, TITLE, READ = 0x94, "read single-turn angle", True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus1(_NoArgs[rep.Status1Reply]):
    """0x9A read temperature, brake, voltage and error flags."""

    CODE, TITLE, READ, STREAMABLE = 0x9A, "read status 1 and error flags", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus2(_NoArgs[rep.StatusReply]):
    """0x9C read temperature, torque current, speed and angle: the R2 layout, which the closed-loop
    commands answer with too (its angle is whole degrees; 0x92 reads the multi-turn angle exactly)."""

    CODE, TITLE, READ, STREAMABLE = 0x9C, "read status 2", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus3(_NoArgs[rep.Status3Reply]):
    """0x9D read temperature and phase currents."""

    CODE, TITLE, READ, STREAMABLE = 0x9D, "read status 3", True, True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadRunTime(_NoArgs[rep.RunTimeReply]):
    """0xB1 read the time since power-up or reset."""

    CODE, TITLE, READ = 0xB1, "read system run time", True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadVersionDate(_NoArgs[rep.VersionDateReply]):
    """0xB2 read the firmware version date (see ``revision_from_version_date``)."""

    CODE, TITLE, READ = 0xB2, "read software version date", True


# ---- 0x79 CAN-ID / RS485-ID setting (V4.3, §4.38) ----


@dataclass(frozen=True, slots=True, kw_only=True)
class SetCanId(MyActuatorCommand[rep.Echo]):
    """0x79 write the motor id (V4.3 only). Sent on CAN 0x300 or RS485 ID byte 0xCD: **every motor on the
    bus takes it**, so connect one motor. DATA[2] = 0 (write), DATA[7] = new id. Reply: echo."""

    CODE: ClassVar[int] = 0x79
    TITLE: ClassVar[str] = "CAN-ID setting"
    SLOW = True
    REVISIONS = ONLY_V4_3
    CONSTANTS = ((2, 0),)
    FIELDS = ((7, IntField("motor_id", 1, lo=1, hi=32)),)
    motor_id: int


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadCanId(MyActuatorCommand[rep.CanIdReply]):
    """0x79 read the motor id (V4.3 only; DATA[2] = 1). Sent like ``SetCanId``."""

    CODE: ClassVar[int] = 0x79
    TITLE: ClassVar[str] = "CAN-ID setting"
    READ = True
    REVISIONS = ONLY_V4_3
    CONSTANTS = ((2, 1),)


# ---- 0xB3..0xB6 ----

# §4.33: CanRecvTime_MS 0 = protection disabled; asked for with None only (issue 19).
_COMM_TIMEOUT = SpecialZero(
    IntField("timeout_ms", 4),
    meaning=(
        "turns communication-interruption protection off: the motor keeps executing the last command (§4.33)"
    ),
    unit="ms",
)
# §4.36: the interval is 10 ms/LSB; 0 is undefined while streaming. None (sent as 0) only with enabled=False.
_STREAM_INTERVAL = SpecialZero(
    StepField("interval_ms", 2, step=10),
    meaning="is not defined for an enabled stream (§4.36)",
    unit="ms",
    how="interval_ms=None with enabled=False (disabling a stream)",
)


@dataclass(frozen=True, slots=True, kw_only=True)
class SetCommTimeout(MyActuatorCommand[rep.Echo]):
    """0xB3 communication-interruption protection: without traffic for ``timeout_ms`` the motor cuts its
    output and locks the brake. Saved in ROM. Reply: echo (or all zero, §9 item 8).

    ``timeout_ms=None`` (or :meth:`protection_off`) turns the protection off: 0 on the wire, after which
    the motor keeps executing the last command when communication stops (§4.33). The number 0 is
    refused, so "0 ms" can never silently mean "no protection"."""

    CODE: ClassVar[int] = 0xB3
    TITLE: ClassVar[str] = "communication-interruption protection time"
    SLOW = True
    FIELDS = ((4, _COMM_TIMEOUT),)
    timeout_ms: int | None

    @classmethod
    def protection_off(cls) -> Self:
        """Turn communication-interruption protection off (0 on the wire, §4.33)."""
        return cls(timeout_ms=None)


@dataclass(frozen=True, slots=True, kw_only=True)
class SetBaudRate(MyActuatorCommand[None]):
    """0xB4 set the link rate by raw index (DATA[7]), used from the next power-up. The index meaning
    differs between the manuals (§4.34); :attr:`setting` gives [002]'s mapping. The reply is garbage at
    the changing rate: none is decoded."""

    CODE: ClassVar[int] = 0xB4
    TITLE: ClassVar[str] = "set communication baud rate"
    NO_REPLY = "the reply is random because the baud rate changes; discard it (§4.34)"
    FIELDS = ((7, IntField("baud_index", 1)),)
    baud_index: int

    @property
    def setting(self) -> BaudRateSetting | None:
        """The rates per [002]'s mapping, or None where no manual states them (3 and above)."""
        return BAUD_RATE_INDEXES.get(self.baud_index)


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadModel(_NoArgs[rep.ModelReply]):
    """0xB5 read the motor model, V4.3 form: all-zero request, 7 characters back (``ModelReply``)."""

    CODE: ClassVar[int] = 0xB5
    TITLE: ClassVar[str] = "read motor model (single frame)"
    READ = True
    REVISIONS = ONLY_V4_3


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadModelPart(MyActuatorCommand[rep.ModelPartReply]):
    """0xB5 read the motor model, V4.4 form: DATA[1] = 0x01, DATA[2] = ``part`` (1: characters 1-5, 2:
    6-10, 3: 11-15). Join the three replies with ``replies.join_model``."""

    CODE: ClassVar[int] = 0xB5
    TITLE: ClassVar[str] = "read motor model (indexed)"
    READ = True
    REVISIONS = ONLY_V4_4
    CONSTANTS = ((1, 0x01),)
    FIELDS = ((2, IntField("part", 1, lo=1, hi=3)),)
    part: int


@dataclass(frozen=True, slots=True, kw_only=True)
class ActiveReply(MyActuatorCommand[None]):
    """0xB6 active reply (CAN only): stream ``command``'s reply every ``interval_ms`` (10 ms/LSB).

    ``interval_ms`` is rounded to 10 ms half away from zero; one that rounds to 0 (1..4 ms) is refused,
    because interval 0 is undefined (§4.36). Leave it ``None`` (sent as 0) only to disable a stream
    (``enabled=False``); an enabled stream needs an interval of at least 5 ms (one 10 ms step).

    While any stream is on, the motor stops answering requests (§9 item 18): disable it before relying
    on request/response. The 0xB6 frame itself gets no reply. Not supported on RS485.
    """

    CODE: ClassVar[int] = 0xB6
    TITLE: ClassVar[str] = "active reply"
    NO_REPLY = "the 0xB6 frame gets no reply; the motor then streams the chosen command's replies (§4.36)"
    NOTED = True
    FIELDS = (
        (1, EnumField("command", 1, StreamableCommand)),
        (2, BoolField("enabled")),
        (3, _STREAM_INTERVAL),
    )
    command: StreamableCommand
    enabled: bool
    interval_ms: int | None = None

    def __post_init__(self) -> None:
        Fixed.__post_init__(self)
        if self.enabled is True and self.interval_ms is None:
            raise ValueError(
                "interval_ms=None sends interval 0, which is not defined for an enabled stream (§4.36): "
                "give the interval (10 ms steps)"
            )

    @property
    def interval_code(self) -> int:
        """The interval as sent, in 10 ms counts (0 for ``None``)."""
        return 0 if self.interval_ms is None else round_half_away(self.interval_ms / 10)

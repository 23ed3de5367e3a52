"""LK parameter addressing: the two revisions' parameter enums, value types and value layouts.

The messages that carry them are in :mod:`~servobus.protocols.lk.params_v236` and
:mod:`~servobus.protocols.lk.params_v235`; this module holds what both need.

* V2.36 control parameters in RAM, 0xC0 read / 0xC1 write: :class:`ControlParam` (spec §4.18,
  §4.19, §6.1).
* V2.36 setting parameters, 0x40 read / 0x42 write / 0x44 save all to ROM: :class:`SettingParam`,
  two address bytes (``05 xx`` single values from DATA[4], ``A0``/``A4``/``A8`` PID groups from
  DATA[2]) (spec §4.27..§4.29, §6.2).
* V2.35 ParamID, 0x40 read / 0x42 write RAM / 0x44 write ROM: :class:`ParamId` 0x96..0x9E, values
  from DATA[2] (spec §6.3).

The write/save status bytes have opposite polarity (spec §7.7): V2.36 0x44 reply 0x01 = saved,
V2.35 0x42/0x44 reply 0x00 = written. Both decode to :class:`~servobus.protocols.lk.states.ParamResult`.
Units of these values are not stated in either manual (spec A27): they stay raw integers.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Self, TypeAlias

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField
from servobus.protocols._message import Message, require_length
from servobus.protocols.lk._base import FRAME_LENGTH, MemberField, check_command
from servobus.protocols.lk.model import DEFAULT_MODEL, LkModel, check_member
from servobus.protocols.lk.states import ParamResult

__all__ = [
    "CONTROL_LAYOUTS",
    "PARAM_LAYOUTS",
    "SAVE_RESULT",
    "SETTING_LAYOUTS",
    "WRITE_RESULT_V235",
    "BusType",
    "CanBaud",
    "ChoiceLayout",
    "ControlParam",
    "IntLayout",
    "ParamId",
    "ParamMessage",
    "ParamValue",
    "PidGains",
    "PidLayout",
    "ResultField",
    "Rs485Baud",
    "SettingParam",
    "ValueLayout",
    "check_value",
    "decode_setting_address",
    "max_angle_from_halves",
    "max_angle_halves",
    "setting_address",
]


class ControlParam(enum.IntEnum):
    """controlParamID of 0xC0/0xC1, V2.36 (spec §6.1). Likely units (inferred, §6.1) in comments."""

    POSITION_PID = 0x0A
    SPEED_PID = 0x0B
    CURRENT_PID = 0x0C
    TORQUE_LIMIT = 0x1E  # iq counts; 0..850 MS, 0..2000 MF/MH/MG
    SPEED_LIMIT = 0x20  # 0.01 dps?
    ANGLE_UPPER_LIMIT = 0x22  # 0.01 deg?
    ANGLE_LOWER_LIMIT = 0x23  # 0.01 deg?
    SPEED_RAMP = 0x26  # 0.01 dps/s?


class SettingParam(enum.IntEnum):
    """Setting-parameter address of 0x40/0x42, V2.36 (spec §6.2): value = DATA[1] << 8 | DATA[2].

    PID groups are addressed by DATA[1] alone; DATA[2] is sent as 0x00 (A28) and, in the reply,
    carries Kp's low byte.
    """

    DRIVER_ID = 0x050A
    BUS_TYPE = 0x050B
    RS485_BAUD = 0x050C
    CAN_BAUD = 0x050D
    MAX_POWER = 0x05B0  # MS 0..850; MF/MH/MG 0..2000 (presumably the torque-current limit)
    MAX_SPEED = 0x05B2
    MAX_ANGLE = 0x05B4
    CURRENT_RAMP = 0x05BA
    SPEED_RAMP = 0x05BC
    POSITION_PID = 0xA000
    SPEED_PID = 0xA400
    CURRENT_PID = 0xA800


class ParamId(enum.IntEnum):
    """ParamID of 0x40/0x42/0x44, V2.35 (spec §6.3)."""

    ANGLE_PID = 0x96
    SPEED_PID = 0x97
    CURRENT_PID = 0x98
    MAX_TORQUE_CURRENT = 0x99
    MAX_SPEED = 0x9A
    MAX_ANGLE_LOW = 0x9B  # maxAngle bytes 0..3
    MAX_ANGLE_HIGH = 0x9C  # maxAngle bytes 4..7
    CURRENT_RAMP = 0x9D
    SPEED_RAMP = 0x9E


class BusType(enum.IntEnum):
    """Setting ``05 0B`` (spec §6.2)."""

    NONE = 0
    RS485 = 1
    CAN = 2


class Rs485Baud(enum.IntEnum):
    """Setting ``05 0C`` (spec §6.2; 8 and 9 repaired from OCR, A8)."""

    BAUD_9600 = 0
    BAUD_19200 = 1
    BAUD_38400 = 2
    BAUD_57600 = 3
    BAUD_115200 = 4
    BAUD_230400 = 5
    BAUD_460800 = 6
    BAUD_921600 = 7
    BAUD_1000000 = 8
    BAUD_2000000 = 9
    BAUD_4000000 = 10

    @property
    def bps(self) -> int:
        return int(self.name.removeprefix("BAUD_"))


class CanBaud(enum.IntEnum):
    """Setting ``05 0D`` (spec §6.2)."""

    BAUD_100K = 0
    BAUD_125K = 1
    BAUD_250K = 2
    BAUD_500K = 3
    BAUD_1M = 4

    @property
    def bps(self) -> int:
        return {0: 100_000, 1: 125_000, 2: 250_000, 3: 500_000, 4: 1_000_000}[self.value]


_UINT16_MAX = 0xFFFF


@dataclass(frozen=True, slots=True, kw_only=True)
class PidGains:
    """Kp, Ki, Kd as the drive stores them (uint16 each; V2.36 limits them to 0..2000).

    Raises:
        ValueError: a gain is not an integer in 0..65535.
    """

    kp: int
    ki: int
    kd: int

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            IntField(name, size=2, hi=_UINT16_MAX).check(getattr(self, name))


ParamValue: TypeAlias = int | PidGains
"""A parameter value: an int (or an IntEnum such as :class:`BusType`) or :class:`PidGains`."""


class ValueLayout:
    """Where and how one parameter's value sits in DATA[2..7]."""

    def check(self, name: str, value: ParamValue) -> None:
        raise NotImplementedError

    def encode(self, value: ParamValue) -> tuple[int, bytes]:
        raise NotImplementedError

    def decode(self, data: bytes, *, what: str) -> ParamValue:
        raise NotImplementedError


@dataclass(frozen=True, slots=True)
class PidLayout(ValueLayout):
    """3 x uint16 LE at DATA[2..7]: Kp, Ki, Kd (each at most ``hi``)."""

    hi: int

    def check(self, name: str, value: ParamValue) -> None:
        if not isinstance(value, PidGains):
            raise ValueError(f"{name}={value!r} is not PidGains")
        for gain in ("kp", "ki", "kd"):
            IntField(f"{name}.{gain}", size=2, hi=self.hi).check(getattr(value, gain))

    def encode(self, value: ParamValue) -> tuple[int, bytes]:
        assert isinstance(value, PidGains)
        return 2, b"".join(g.to_bytes(2, "little") for g in (value.kp, value.ki, value.kd))

    def decode(self, data: bytes, *, what: str) -> ParamValue:
        kp, ki, kd = (int.from_bytes(data[i : i + 2], "little") for i in (2, 4, 6))
        return PidGains(kp=kp, ki=ki, kd=kd)


@dataclass(frozen=True, slots=True)
class IntLayout(ValueLayout):
    """A little-endian integer at DATA[offset..], optionally narrowed to [lo, hi]."""

    offset: int
    size: int
    signed: bool = True
    lo: int | None = None
    hi: int | None = None

    def check(self, name: str, value: ParamValue) -> None:
        if isinstance(value, enum.Enum):
            raise ValueError(f"{name}={value!r} is not a plain integer")
        IntField(name, size=self.size, signed=self.signed, lo=self.lo, hi=self.hi).check(value)  # type: ignore[arg-type]

    def encode(self, value: ParamValue) -> tuple[int, bytes]:
        assert isinstance(value, int)
        return self.offset, value.to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes, *, what: str) -> ParamValue:
        return int.from_bytes(data[self.offset : self.offset + self.size], "little", signed=self.signed)


@dataclass(frozen=True, slots=True)
class ChoiceLayout(ValueLayout):
    """A uint8 at DATA[offset] naming a member of ``enum_cls``."""

    offset: int
    enum_cls: type[enum.IntEnum]

    def check(self, name: str, value: ParamValue) -> None:
        check_member(name, value, self.enum_cls)

    def encode(self, value: ParamValue) -> tuple[int, bytes]:
        assert isinstance(value, int)
        return self.offset, bytes([value])

    def decode(self, data: bytes, *, what: str) -> ParamValue:
        member: ParamValue = MemberField(what, self.enum_cls).decode(data, self.offset)
        return member


_INT32_MAX = 2**31 - 1
# Spec §6.1 (V2.36, 0xC0/0xC1): values after DATA[1] = id; single values from DATA[4] (DATA[2..3] = 0).
CONTROL_LAYOUTS: Mapping[ControlParam, ValueLayout] = {
    ControlParam.POSITION_PID: PidLayout(2000),
    ControlParam.SPEED_PID: PidLayout(2000),
    ControlParam.CURRENT_PID: PidLayout(2000),
    ControlParam.TORQUE_LIMIT: IntLayout(4, 2, lo=0, hi=2000),
    ControlParam.SPEED_LIMIT: IntLayout(4, 4, lo=0, hi=600_000),
    ControlParam.ANGLE_UPPER_LIMIT: IntLayout(4, 4),
    ControlParam.ANGLE_LOWER_LIMIT: IntLayout(4, 4),
    ControlParam.SPEED_RAMP: IntLayout(4, 4, lo=0, hi=600_000),
}
# Spec §6.2 (V2.36, 0x40/0x42): single values from DATA[4] (DATA[3] = 0), PID groups from DATA[2].
SETTING_LAYOUTS: Mapping[SettingParam, ValueLayout] = {
    SettingParam.DRIVER_ID: IntLayout(4, 1, signed=False, lo=0, hi=32),
    SettingParam.BUS_TYPE: ChoiceLayout(4, BusType),
    SettingParam.RS485_BAUD: ChoiceLayout(4, Rs485Baud),
    SettingParam.CAN_BAUD: ChoiceLayout(4, CanBaud),
    SettingParam.MAX_POWER: IntLayout(4, 2, lo=0, hi=2000),
    SettingParam.MAX_SPEED: IntLayout(4, 4, lo=0, hi=600_000),
    SettingParam.MAX_ANGLE: IntLayout(4, 4, lo=0, hi=_INT32_MAX),
    SettingParam.CURRENT_RAMP: IntLayout(4, 2, lo=0, hi=30_000),
    SettingParam.SPEED_RAMP: IntLayout(4, 4, lo=0, hi=600_000),
    SettingParam.POSITION_PID: PidLayout(2000),
    SettingParam.SPEED_PID: PidLayout(2000),
    SettingParam.CURRENT_PID: PidLayout(2000),
}
# Spec §6.3 (V2.35): values from DATA[2]; no ranges stated, so the C types' ranges. maxAngle is an
# 8-byte value split in two 4-byte halves: the low half unsigned, the high half signed (int64, inferred).
PARAM_LAYOUTS: Mapping[ParamId, ValueLayout] = {
    ParamId.ANGLE_PID: PidLayout(_UINT16_MAX),
    ParamId.SPEED_PID: PidLayout(_UINT16_MAX),
    ParamId.CURRENT_PID: PidLayout(_UINT16_MAX),
    ParamId.MAX_TORQUE_CURRENT: IntLayout(2, 2),
    ParamId.MAX_SPEED: IntLayout(2, 4),
    ParamId.MAX_ANGLE_LOW: IntLayout(2, 4, signed=False),
    ParamId.MAX_ANGLE_HIGH: IntLayout(2, 4),
    ParamId.CURRENT_RAMP: IntLayout(2, 2),
    ParamId.SPEED_RAMP: IntLayout(2, 4),
}
_PID_GROUPS = {SettingParam.POSITION_PID, SettingParam.SPEED_PID, SettingParam.CURRENT_PID}


def max_angle_halves(max_angle: int) -> tuple[int, int]:
    """Split a V2.35 maxAngle (int64) into the values of ParamId MAX_ANGLE_LOW and MAX_ANGLE_HIGH.

    Raises:
        ValueError: ``max_angle`` does not fit an int64.
    """
    IntField("max_angle", size=8, signed=True).check(max_angle)
    return max_angle & 0xFFFFFFFF, max_angle >> 32


def max_angle_from_halves(low: int, high: int) -> int:
    """The V2.35 maxAngle (int64) from its MAX_ANGLE_LOW (uint32) and MAX_ANGLE_HIGH (int32) values."""
    return (high << 32) | (low & 0xFFFFFFFF)


def _param_name(param: enum.IntEnum) -> str:
    return param.name.lower()


def setting_address(param: SettingParam) -> bytes:
    """DATA[1..2] addressing ``param`` (PID groups: group byte and 0x00, spec A28)."""
    return bytes([param >> 8, 0 if param in _PID_GROUPS else param & 0xFF])


def decode_setting_address(data: bytes, *, what: str) -> SettingParam:
    """The setting parameter DATA[1..2] address (DATA[2] is ignored for PID groups).

    Raises:
        ProtocolError: the bytes address no parameter of spec §6.2.
    """
    group = data[1]
    try:
        return SettingParam(group << 8 if group != 0x05 else 0x0500 | data[2])
    except ValueError:
        raise ProtocolError(
            f"{what}: DATA[1..2]={data[1]:02X} {data[2]:02X} is not a setting parameter",
            raw=data,
            command=data[0],
        ) from None


def check_value(param: enum.IntEnum, value: ParamValue, layouts: Mapping[Any, ValueLayout]) -> None:
    """Raise ValueError unless ``value`` fits ``param``'s layout; the message names the parameter."""
    layouts[param].check(_param_name(param), value)


# Spec §7.7: V2.36 0x44 reply DATA[2]: 0x01 saved, 0x00 failed.
SAVE_RESULT = {0x01: ParamResult.SUCCESS, 0x00: ParamResult.FAILURE}
# Spec §7.7: V2.35 0x42/0x44 reply DATA[2]: 0x00 written, 0x01 failed.
WRITE_RESULT_V235 = {0x00: ParamResult.SUCCESS, 0x01: ParamResult.FAILURE}


@dataclass(frozen=True, slots=True)
class ResultField:
    """A status byte read through ``table`` (SAVE_RESULT or WRITE_RESULT_V235) as a ParamResult."""

    name: str
    table: Mapping[int, ParamResult]
    size: int = 1

    def check(self, value: Any) -> None:
        check_member(self.name, value, ParamResult)

    def encode(self, value: Any) -> bytes:
        return bytes([next(byte for byte, r in self.table.items() if r is value)])

    def decode(self, data: bytes, offset: int = 0) -> ParamResult:
        try:
            return self.table[data[offset]]
        except KeyError:
            raise ValueError(
                f"status byte DATA[{offset}]=0x{data[offset]:02X} is neither success nor failure"
            ) from None


class ParamMessage(Message):
    """The shared body of every parameter frame: ``cmd | key [| value]`` (spec §13).

    Not a fixed layout: where the value sits and what it is depends on the parameter named in the
    frame, so the value layouts are tables by parameter (``LAYOUTS``) instead of ``FIELDS``. The three
    parameter schemes (V2.36 control parameters, V2.36 settings, V2.35 ParamIDs) differ only in their
    key enum (``PARAMS``), how the key is written (:meth:`_encode_key` and :meth:`_decode_key`,
    overridden for two-byte keys) and their value layouts (``LAYOUTS``; None for a read request, which
    carries the key alone). The command byte is the class's ``CODE``, or for a reply that answers
    several requests (``CODE`` None) its ``command`` field, one of the bytes of the commands that
    declare it as their reply. A message class sets these and declares its fields; checking,
    encoding and decoding are here.
    """

    __slots__ = ()
    PARAMS: ClassVar[type[enum.IntEnum]]
    LAYOUTS: ClassVar[Mapping[Any, ValueLayout] | None] = None
    command: int
    param: Any
    value: ParamValue

    def __init_subclass__(
        cls,
        params: type[enum.IntEnum] | None = None,
        layouts: Mapping[Any, ValueLayout] | None = None,
        **kwargs: Any,
    ) -> None:
        """``class _Control(ParamMessage, params=ControlParam, layouts=CONTROL_LAYOUTS)``: a scheme."""
        super().__init_subclass__(**kwargs)
        if params is not None:
            cls.PARAMS = params
        if layouts is not None:
            cls.LAYOUTS = layouts

    @classmethod
    def _codes(cls) -> frozenset[int]:
        if cls.CODE is not None:
            return frozenset({cls.CODE})
        return cls.answers()  # type: ignore[attr-defined, no-any-return]

    def __post_init__(self) -> None:
        if self.CODE is None:
            check_command(self.command, self._codes())
        check_member("param", self.param, self.PARAMS)
        if self.LAYOUTS is not None:
            check_value(self.param, self.value, self.LAYOUTS)

    @classmethod
    def _encode_key(cls, param: Any) -> bytes:
        return bytes([param])

    @classmethod
    def _decode_key(cls, data: bytes, what: str) -> Any:
        return MemberField("param", cls.PARAMS).decode(data, 1)

    def encode(self) -> bytes:
        buf = bytearray(FRAME_LENGTH)
        buf[0] = self.command if self.CODE is None else self.CODE
        key = self._encode_key(self.param)
        buf[1 : 1 + len(key)] = key
        if self.LAYOUTS is not None:  # a PID layout from DATA[2] overwrites a setting's zero 2nd key byte
            offset, value = self.LAYOUTS[self.param].encode(self.value)
            buf[offset : offset + len(value)] = value
        return bytes(buf)

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        what = cls.__name__
        require_length(data, FRAME_LENGTH, what=what)
        codes = cls._codes()
        if data[0] not in codes:
            expected = " or ".join(f"0x{c:02X}" for c in sorted(codes))
            raise ProtocolError(f"{what}: command byte is not {expected}", raw=data, command=data[0])
        try:
            fields: dict[str, object] = {"param": cls._decode_key(data, what)}
            if cls.CODE is None:
                fields["command"] = data[0]
            if cls.LAYOUTS is not None:
                fields["value"] = cls.LAYOUTS[fields["param"]].decode(data, what=what)
            return cls(**fields)
        except ValueError as exc:
            raise ProtocolError(f"{what}: {exc}", raw=data, command=data[0]) from None

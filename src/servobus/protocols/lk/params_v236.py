"""LK V2.36 parameter messages: control parameters in RAM (0xC0/0xC1), settings (0x40/0x42/0x44).

Spec §4.18, §4.19, §6.1 (control parameters) and §4.27..§4.29, §6.2 (setting parameters, two
address bytes, saved all at once by ``44 05 FA``, whose reply says 0x01 = saved; spec §7.7).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from servobus.protocols.lk._base import V2_36_ONLY, LkCommand, LkReply
from servobus.protocols.lk.params import (
    CONTROL_LAYOUTS,
    SAVE_RESULT,
    SETTING_LAYOUTS,
    ControlParam,
    ParamMessage,
    ParamValue,
    ResultField,
    SettingParam,
    decode_setting_address,
    setting_address,
)
from servobus.protocols.lk.states import ParamResult

__all__ = [
    "ControlParamReply",
    "ReadControlParam",
    "ReadSetting",
    "SaveSettings",
    "SaveSettingsReply",
    "SettingReply",
    "WriteControlParam",
    "WriteSetting",
]


# ---- V2.36 control parameters (0xC0 / 0xC1) --------------------------------------------------


class _ControlMessage(ParamMessage, params=ControlParam, layouts=CONTROL_LAYOUTS):
    """0xC0/0xC1 frames with a value: ``cmd | id | byte1..6``."""

    __slots__ = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class ControlParamReply(_ControlMessage, LkReply):
    """0xC0 reply (the value read) and 0xC1 reply (the value written), V2.36 only (spec §4.18, §4.19).

    Attributes:
        command: 0xC0 or 0xC1.
        param: which parameter.
        value: :class:`PidGains` or int.
    """

    REVISIONS = V2_36_ONLY
    command: int
    param: ControlParam
    value: ParamValue


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadControlParam(ParamMessage, LkCommand[ControlParamReply], params=ControlParam):
    """0xC0, V2.36 only: read a control parameter from RAM (spec §4.18)."""

    CODE: ClassVar[int] = 0xC0
    REVISIONS = V2_36_ONLY
    READ = True
    param: ControlParam


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteControlParam(_ControlMessage, LkCommand[ControlParamReply]):
    """0xC1, V2.36 only: write a control parameter to RAM, effective at once (spec §4.19, §6.1).

    The reply echoes the value written, which keys it (``ECHO``).

    Attributes:
        param: which parameter.
        value: :class:`PidGains` for the PID entries, an int for the others (ranges per spec §6.1).
    """

    CODE: ClassVar[int] = 0xC1
    REVISIONS = V2_36_ONLY
    ECHO = True
    param: ControlParam
    value: ParamValue


# ---- V2.36 setting parameters (0x40 / 0x42 / 0x44) ---------------------------------------------


class _SettingKey(ParamMessage, params=SettingParam):
    """Setting frames are keyed by two address bytes (spec §6.2)."""

    __slots__ = ()

    @classmethod
    def _encode_key(cls, param: SettingParam) -> bytes:
        return setting_address(param)

    @classmethod
    def _decode_key(cls, data: bytes, what: str) -> SettingParam:
        return decode_setting_address(data, what=what)


class _SettingMessage(_SettingKey, layouts=SETTING_LAYOUTS):
    """0x40 replies and 0x42 frames: ``cmd | address | value`` (spec §6.2, §13).

    The PID layout starts at DATA[2] and overwrites the (zero) second address byte with Kp.
    """

    __slots__ = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class SettingReply(_SettingMessage, LkReply):
    """0x40 reply (value read) and 0x42 reply (value written), V2.36 layout (spec §4.27, §4.28).

    Attributes:
        command: 0x40 or 0x42.
        param: which parameter.
        value: as for :class:`WriteSetting`.
    """

    REVISIONS = V2_36_ONLY
    command: int
    param: SettingParam
    value: ParamValue


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadSetting(_SettingKey, LkCommand[SettingReply]):
    """0x40, V2.36 layout: read a setting parameter, ``40 | addr1 | addr2 | 00..`` (spec §4.27)."""

    CODE: ClassVar[int] = 0x40
    REVISIONS = V2_36_ONLY
    READ = True
    param: SettingParam


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteSetting(_SettingMessage, LkCommand[SettingReply]):
    """0x42, V2.36 layout: write a setting parameter; saved to ROM only by 0x44 (spec §4.28).

    Attributes:
        param: which parameter.
        value: int, :class:`BusType`, :class:`Rs485Baud`, :class:`CanBaud` or :class:`PidGains`.
    """

    CODE: ClassVar[int] = 0x42
    REVISIONS = V2_36_ONLY
    param: SettingParam
    value: ParamValue


@dataclass(frozen=True, slots=True, kw_only=True)
class SaveSettingsReply(LkReply):
    """0x44 reply, V2.36 layout ``44 05 flag``: 0x01 = saved, 0x00 = failed (spec §4.29, §7.7).

    DATA[7] is lost in the OCR text (A14); like every other NULL byte it is ignored on decode.

    Attributes:
        result: SUCCESS or FAILURE.
    """

    CODE: ClassVar[int] = 0x44
    REVISIONS = V2_36_ONLY
    CONSTANTS = ((1, 0x05),)
    FIELDS = ((2, ResultField("result", SAVE_RESULT)),)
    result: ParamResult

    @property
    def ok(self) -> bool:
        return self.result is ParamResult.SUCCESS


@dataclass(frozen=True, slots=True, kw_only=True)
class SaveSettings(LkCommand[SaveSettingsReply]):
    """0x44, V2.36 layout: save every written setting to ROM, ``44 05 FA 00 ..`` (spec §4.29).

    The drive needs a power cycle (or the restart command [001] mentions but does not document).
    """

    CODE: ClassVar[int] = 0x44
    REVISIONS = V2_36_ONLY
    SLOW = True
    CONSTANTS = ((1, 0x05), (2, 0xFA))

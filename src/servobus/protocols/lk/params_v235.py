"""LK V2.35 parameter messages: ParamID read (0x40), write RAM (0x42), write ROM (0x44).

Spec §4.27..§4.29, §6.3: one ParamID byte, values from DATA[2]; the 0x42/0x44 reply says 0x00 =
written, 0x01 = failed (the opposite of V2.36's save flag; spec §7.7).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from servobus.protocols.lk._base import V2_35_ONLY, CommandField, LkCommand, LkReply, MemberField
from servobus.protocols.lk.params import (
    PARAM_LAYOUTS,
    WRITE_RESULT_V235,
    ParamId,
    ParamMessage,
    ParamValue,
    ResultField,
)
from servobus.protocols.lk.states import ParamResult

__all__ = [
    "ParamReply",
    "ParamWriteReply",
    "ReadParam",
    "WriteParamRam",
    "WriteParamRom",
]


class _ParamMessage(ParamMessage, params=ParamId, layouts=PARAM_LAYOUTS):
    """V2.35 0x40 replies and 0x42/0x44 requests: ``cmd | ParamID | value``."""

    __slots__ = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class ParamReply(_ParamMessage, LkReply):
    """0x40 reply, V2.35 layout: ``40 | ParamID | value`` (spec §4.27, §6.3).

    Attributes:
        param: which parameter.
        value: :class:`PidGains` or int.
    """

    CODE: ClassVar[int] = 0x40
    REVISIONS = V2_35_ONLY
    param: ParamId
    value: ParamValue


@dataclass(frozen=True, slots=True, kw_only=True)
class ParamWriteReply(LkReply):
    """0x42/0x44 reply, V2.35 layout ``cmd | ParamID | status``: 0x00 = written, 0x01 = failed (spec §7.7).

    Attributes:
        command: 0x42 (RAM) or 0x44 (ROM).
        param: the parameter written.
        result: SUCCESS or FAILURE.
    """

    REVISIONS = V2_35_ONLY
    FIELDS = ((1, MemberField("param", ParamId)), (2, ResultField("result", WRITE_RESULT_V235)))
    MODEL_FIELDS = ((0, CommandField()),)
    command: int
    param: ParamId
    result: ParamResult

    @property
    def ok(self) -> bool:
        return self.result is ParamResult.SUCCESS


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadParam(ParamMessage, LkCommand[ParamReply], params=ParamId):
    """0x40, V2.35 layout: read a parameter, ``40 | ParamID | 00..`` (spec §4.27; worked example W4)."""

    CODE: ClassVar[int] = 0x40
    REVISIONS = V2_35_ONLY
    READ = True
    param: ParamId


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteParamRam(_ParamMessage, LkCommand[ParamWriteReply]):
    """0x42, V2.35 layout: write one parameter to RAM, lost at power-off (spec §4.28, §6.3)."""

    CODE: ClassVar[int] = 0x42
    REVISIONS = V2_35_ONLY
    param: ParamId
    value: ParamValue


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteParamRom(WriteParamRam):
    """0x44, V2.35 layout: write one parameter to ROM, kept over power-off (spec §4.29, §6.3)."""

    CODE: ClassVar[int] = 0x44
    SLOW = True

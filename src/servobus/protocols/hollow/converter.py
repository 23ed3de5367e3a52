"""The 485 & pulse -> CANFD converter's own 6-byte configuration frame (hollow.md §9.3).

It sets the stiffness (P, D: the CAN FD Kp/Kd bytes the module fills into its pulse-generated frames)
or one PI multiplier. The manual states neither the port nor the baud rate it travels on (most likely
the module's RS-485 port), so this module only turns the frame into bytes and back: no link of the
bound codec carries it, and no answer is described (``NO_REPLY``).

Byte 0 is contradictory in the manual (A19): the prose says it is fixed to 0x00, the one example has
0x01. Encoders take it as ``header`` (default 0x00, the prose); decoders accept both.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField
from servobus.protocols._layout import EnumField, Float32BEField, Layout
from servobus.protocols._message import Command
from servobus.protocols.hollow._checks import require_size
from servobus.protocols.hollow._packed import OnLinks

__all__ = [
    "CONVERTER_CONFIG_SIZE",
    "CONVERTER_HEADERS",
    "ConverterGain",
    "ConverterPdGains",
    "ConverterPiMultiplier",
    "decode_converter_config",
]

CONVERTER_CONFIG_SIZE = 6
CONVERTER_HEADERS = (0x00, 0x01)  # A19: 0x00 in the prose, 0x01 in the example [H22]
_HEADER = IntField("header", 1, lo=0x00, hi=0x01)
_PD_SELECTOR = 0x01
_NO_REPLY = "the manual describes no answer to the module's configuration frame (§9.3)"


class ConverterGain(IntEnum):
    """D1 of the converter frame for a PI multiplier: one higher than the motor's own numbering
    (§9.3 vs §6, A18); 0x01 is the P/D setting (:class:`ConverterPdGains`)."""

    SPEED_KP = 0x02
    SPEED_KI = 0x03
    CURRENT_KP = 0x04
    CURRENT_KI = 0x05


@dataclass(frozen=True, slots=True, kw_only=True)
class ConverterPdGains(Layout, OnLinks, Command[None]):
    """Set the module's position-loop P and D: ``header 01 P D 00 00`` (§9.3) [H22].

    Attributes:
        p: P, 0..255 (the CAN FD Kp range).
        d: D, 0..255 (the CAN FD Kd range).
        header: byte 0, 0x00 or 0x01 (A19).
    """

    NO_REPLY: ClassVar[str | None] = _NO_REPLY
    SIZE: ClassVar[int] = CONVERTER_CONFIG_SIZE
    CONSTANTS: ClassVar[tuple[tuple[int, int], ...]] = ((1, _PD_SELECTOR), (4, 0x00), (5, 0x00))
    FIELDS = ((0, _HEADER), (2, IntField("p", 1)), (3, IntField("d", 1)))
    p: int
    d: int
    header: int = 0x00


@dataclass(frozen=True, slots=True, kw_only=True)
class ConverterPiMultiplier(Layout, OnLinks, Command[None]):
    """Scale one of the motor's PI gains through the module: ``header gain float32-BE`` (§9.3).

    Attributes:
        gain: which gain (the converter's numbering).
        multiplier: a finite float32 >= 0; 1.0 leaves the gain unchanged (negative refused [I]).
        header: byte 0, 0x00 or 0x01 (A19).
    """

    NO_REPLY: ClassVar[str | None] = _NO_REPLY
    SIZE: ClassVar[int] = CONVERTER_CONFIG_SIZE
    FIELDS = (
        (0, _HEADER),
        (1, EnumField("gain", 1, ConverterGain)),
        (2, Float32BEField("multiplier", lo=0.0)),
    )
    gain: ConverterGain
    multiplier: float
    header: int = 0x00


def _require_config(data: bytes) -> None:
    require_size(data, CONVERTER_CONFIG_SIZE, what="converter configuration frame")
    if data[0] not in CONVERTER_HEADERS:
        raise ProtocolError("converter configuration frame: byte 0 is not 0x00 or 0x01", raw=data)


def decode_converter_config(data: bytes) -> ConverterPdGains | ConverterPiMultiplier:
    """Decode a converter configuration frame by its D1 (§9.3).

    Raises:
        ProtocolError: wrong length or header, or an unknown D1.
    """
    _require_config(data)
    if data[1] == _PD_SELECTOR:
        return ConverterPdGains.decode(data)
    return ConverterPiMultiplier.decode(data)

"""The 485 & pulse -> CANFD converter's own 6-byte configuration frame (hollow.md §9.3).

It sets the stiffness (P, D: the CAN FD Kp/Kd bytes the module fills into its pulse-generated frames)
or one PI multiplier. The manual states neither the port nor the baud rate it travels on (most likely
the module's RS-485 port), so this module only turns the frame into bytes and back: no link of the
bound codec carries it, and no answer is described (``NO_REPLY``).

Byte 0 is contradictory in the manual (A19): the prose says it is fixed to 0x00, the one example has
0x01. Encoders take it as ``header`` (default 0x00, the prose); decoders accept both.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar, Self

from servobus.errors import ProtocolError
from servobus.protocols._message import Command
from servobus.protocols.hollow._checks import (
    FLOAT32_MAX,
    build,
    check_choice_int,
    check_int,
    check_real,
    decode_enum,
    require_size,
    to_enum,
    unpack_float32_be,
)
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
_NO_REPLY = "the manual describes no answer to the module's configuration frame (§9.3)"
_PD_SELECTOR = 0x01


class ConverterGain(IntEnum):
    """D1 of the converter frame for a PI multiplier: one higher than the motor's own numbering
    (§9.3 vs §6, A18); 0x01 is the P/D setting (:class:`ConverterPdGains`)."""

    SPEED_KP = 0x02
    SPEED_KI = 0x03
    CURRENT_KP = 0x04
    CURRENT_KI = 0x05


@dataclass(frozen=True, slots=True, kw_only=True)
class ConverterPdGains(OnLinks, Command[None]):
    """Set the module's position-loop P and D: ``header 01 P D 00 00`` (§9.3) [H22].

    Attributes:
        p: P, 0..255 (the CAN FD Kp range).
        d: D, 0..255 (the CAN FD Kd range).
        header: byte 0, 0x00 or 0x01 (A19).
    """

    NO_REPLY: ClassVar[str | None] = _NO_REPLY
    p: int
    d: int
    header: int = 0x00

    def __post_init__(self) -> None:
        check_int("p", self.p, 0, 0xFF)
        check_int("d", self.d, 0, 0xFF)
        check_choice_int("header", self.header, CONVERTER_HEADERS)

    def encode(self) -> bytes:
        return bytes([self.header, _PD_SELECTOR, self.p, self.d, 0x00, 0x00])

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Decode a P/D frame.

        Raises:
            ProtocolError: wrong length or header, D1 not 0x01, or D4/D5 not zero.
        """
        _require_config(data)
        if data[1] != _PD_SELECTOR:
            raise ProtocolError("converter P/D frame: D1 is not 0x01", raw=data)
        if data[4] or data[5]:
            raise ProtocolError("converter P/D frame: D4, D5 are not zero", raw=data)
        return cls(p=data[2], d=data[3], header=data[0])


@dataclass(frozen=True, slots=True, kw_only=True)
class ConverterPiMultiplier(OnLinks, Command[None]):
    """Scale one of the motor's PI gains through the module: ``header gain float32-BE`` (§9.3).

    Attributes:
        gain: which gain (the converter's numbering).
        multiplier: a finite float32 >= 0; 1.0 leaves the gain unchanged (negative refused [I]).
        header: byte 0, 0x00 or 0x01 (A19).
    """

    NO_REPLY: ClassVar[str | None] = _NO_REPLY
    gain: ConverterGain
    multiplier: float
    header: int = 0x00

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain", to_enum("gain", self.gain, ConverterGain))
        check_real("multiplier", self.multiplier, 0.0, FLOAT32_MAX)
        check_choice_int("header", self.header, CONVERTER_HEADERS)

    def encode(self) -> bytes:
        return bytes([self.header, self.gain]) + struct.pack(">f", self.multiplier)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Decode a PI multiplier frame of the module.

        Raises:
            ProtocolError: wrong length or header, unknown gain, or a NaN/infinite/negative multiplier.
        """
        _require_config(data)
        gain = decode_enum("converter gain", data[1], ConverterGain, data)
        return build(cls, data, gain=gain, multiplier=unpack_float32_be(data, 2), header=data[0])


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

"""The converter's 6-byte configuration frame (hollow.md §9.3)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import Message
from servobus.protocols.hollow import ConverterGain, ConverterPdGains, ConverterPiMultiplier
from servobus.protocols.hollow.converter import decode_converter_config

from .._contract import decodes_or_protocol_error
from ._strategies import converter_configs


@given(converter_configs)
def test_converter_config_round_trip(command: ConverterPdGains | ConverterPiMultiplier) -> None:
    frame = command.encode()
    assert len(frame) == 6
    assert decode_converter_config(frame) == command
    assert type(command).decode(frame) == command


def test_pi_numbering_is_one_higher_than_the_motors() -> None:
    # A18: the converter's 0x02..0x05 are the motor's 0x01..0x04.
    frame = ConverterPiMultiplier(gain=ConverterGain.SPEED_KP, multiplier=1.0).encode()
    assert frame == bytes.fromhex("00 02 3F 80 00 00")


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        ("01 01 10 10 00", "expected 6 data bytes, got 5"),
        ("02 01 10 10 00 00", "byte 0 is not 0x00 or 0x01"),
        ("00 06 3F 80 00 00", "gain=0x06 is not one of ConverterGain"),
        ("00 01 10 10 00 01", r"DATA\[5\] is not 0x00"),
        ("00 02 FF 80 00 00", "multiplier="),
    ],
)
def test_converter_config_decode_errors(frame: str, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        decode_converter_config(bytes.fromhex(frame))


def test_converter_config_validation() -> None:
    with pytest.raises(ValueError, match=r"p=256 is outside \[0, 255\]"):
        ConverterPdGains(p=256, d=0)
    with pytest.raises(ValueError, match=r"header=2 is outside \[0, 1\]"):
        ConverterPdGains(p=0, d=0, header=2)
    with pytest.raises(ValueError, match=r"multiplier=-1\.0 is outside"):
        ConverterPiMultiplier(gain=ConverterGain.CURRENT_KI, multiplier=-1.0)
    with pytest.raises(ProtocolError, match=r"DATA\[1\] is not 0x01"):
        ConverterPdGains.decode(bytes.fromhex("00 02 3F 80 00 00"))


@given(st.binary(min_size=0, max_size=8))
def test_random_bytes_decode_or_raise_protocol_error(data: bytes) -> None:
    message: Message | None = decodes_or_protocol_error(decode_converter_config, data)
    if message is not None:
        assert message.encode() == data

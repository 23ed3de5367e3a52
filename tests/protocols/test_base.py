"""The pieces every family builds on: scaled fields, the message base, the family registry."""

from __future__ import annotations

import enum

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import FAMILIES, Family, Reply, get_family
from servobus.protocols._fields import IntField, ScaledField, check_choice, round_half_away
from servobus.protocols._message import decode_by_code, require_length

CURRENT = ScaledField("current_a", size=2, signed=True, counts_per_unit=100)


def test_round_half_away_matches_the_c_core_rule() -> None:
    assert [round_half_away(x) for x in (0.5, 1.5, 2.5, -0.5, -2.5, 0.49999, -0.49999)] == [
        1,
        2,
        3,
        -1,
        -3,
        0,
        0,
    ]


def test_scaled_field_encodes_little_endian_counts() -> None:
    assert CURRENT.encode(1.0) == bytes.fromhex("6400")
    assert CURRENT.encode(-1.0) == bytes.fromhex("9CFF")
    assert CURRENT.decode(bytes.fromhex("009CFF"), 1) == -1.0
    assert CURRENT.limits == (-327.68, 327.67)
    assert CURRENT.resolution == 0.01


@pytest.mark.parametrize("value", [327.68, -327.69, float("nan"), float("inf")])
def test_scaled_field_rejects_values_outside_its_range_naming_field_and_limit(value: float) -> None:
    with pytest.raises(ValueError, match=r"current_a=.* is outside \[-327\.68, 327\.67\]"):
        CURRENT.encode(value)


def test_scaled_field_rejects_non_numbers() -> None:
    with pytest.raises(ValueError, match="current_a='1' is not a number"):
        CURRENT.check("1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="not a number"):
        CURRENT.check(True)


@given(st.floats(min_value=-327.68, max_value=327.67))
def test_scaled_field_round_trip_is_quantisation(value: float) -> None:
    decoded = CURRENT.decode(CURRENT.encode(value))
    assert abs(decoded - value) <= 0.005 + 1e-12
    assert CURRENT.encode(decoded) == CURRENT.encode(value)


def test_narrowed_limits_must_fit_the_integer() -> None:
    assert ScaledField("speed_dps", size=2, signed=False, hi=1000).limits == (0.0, 1000)
    with pytest.raises(ValueError, match="do not fit"):
        ScaledField("speed_dps", size=1, signed=False, hi=1000)
    with pytest.raises(ValueError, match="do not fit"):
        IntField("index", size=1, lo=-1)


def test_int_field() -> None:
    index = IntField("index", size=1, lo=1, hi=8)
    assert index.encode(8) == b"\x08"
    assert index.decode(b"\x00\x08", 1) == 8
    with pytest.raises(ValueError, match=r"index=9 is outside \[1, 8\]"):
        index.encode(9)
    with pytest.raises(ValueError, match=r"index=1\.0 is not an integer"):
        index.check(1.0)  # type: ignore[arg-type]


def test_check_choice_lists_the_choices() -> None:
    class Mode(enum.IntEnum):
        A = 1
        B = 2

    check_choice("mode", Mode.A, Mode)
    with pytest.raises(ValueError, match=r"mode=3 is not one of <Mode.A: 1>, <Mode.B: 2>"):
        check_choice("mode", 3, list(Mode))
    with pytest.raises(ValueError, match=r"id=0 is not one of 1..32"):
        check_choice("id", 0, range(1, 33))
    # an enum class: members and their values count, anything else is a ValueError (3.11 raised TypeError)
    check_choice("mode", 2, Mode)
    for wrong in (3, "A", None):
        with pytest.raises(ValueError, match="is not one of"):
            check_choice("mode", wrong, Mode)
    with pytest.raises(ValueError, match="is not one of"):
        check_choice("mode", [1], {1, 2})


def test_protocol_error_gains_context_without_losing_what_it_knew() -> None:
    error = ProtocolError("bad length", raw=b"\x9c\x00", command=0x9C)
    richer = error.with_context(motor_id=3, command=0x11)
    assert str(richer) == "bad length (motor 3, command 0x9C, raw 9C 00)"
    assert (richer.motor_id, richer.command, richer.raw) == (3, 0x9C, b"\x9c\x00")


def test_decode_by_code_and_require_length_raise_protocol_errors() -> None:
    class Echo(Reply):
        __slots__ = ()

    def decode_echo(data: bytes) -> Echo:
        require_length(data, 8, what="echo")
        return Echo()

    table = {0x80: decode_echo}
    assert isinstance(decode_by_code(table, bytes(8).replace(b"\x00", b"\x80", 1), what="reply"), Echo)
    with pytest.raises(ProtocolError, match="empty reply"):
        decode_by_code(table, b"", what="reply")
    with pytest.raises(ProtocolError, match=r"unknown reply command byte \(command 0x81, raw 81 00\)"):
        decode_by_code(table, b"\x81\x00", what="reply")
    with pytest.raises(ProtocolError, match="echo: expected 8 data bytes, got 2"):
        decode_by_code(table, b"\x80\x00", what="reply")


def test_registry_knows_the_three_families_and_names_unknown_ones() -> None:
    assert set(FAMILIES) == {"myactuator", "lk", "hollow"}
    with pytest.raises(ValueError, match="unknown protocol family 'canopen'"):
        get_family("canopen")


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_registered_family_loads(name: str) -> None:
    family = get_family(name)
    assert isinstance(family, Family)
    assert family.name == name
    assert family.revision(family.default_revision) is family.default_revision
    assert family.revision(family.default_revision.name.lower()) is family.default_revision
    with pytest.raises(ValueError, match="has no revision"):
        family.revision("V0_0")

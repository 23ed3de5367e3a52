"""FieldScale checks its own range against a field (issue 38: the Packer no longer reads its private
``_code``): a range that maps past the field's codes is refused, naming where."""

from __future__ import annotations

import pytest

from servobus.core import FieldScale


def test_a_range_that_fits_its_field_passes() -> None:
    FieldScale.linear("position_rad", -12.5, 12.5, 16).check_fits(16, "MIT")
    FieldScale.offset_binary("current_a", 10.0, 12).check_fits(12, "hollow")  # +full scale saturates
    FieldScale.integer("id", -128, 127).check_fits(-8, "signed")


def test_a_range_past_its_field_is_refused_naming_where() -> None:
    with pytest.raises(ValueError, match=r"MIT: position_rad range \[-12.5, 12.5\] maps to codes"):
        FieldScale.linear("position_rad", -12.5, 12.5, 16).check_fits(12, "MIT")
    with pytest.raises(ValueError, match=r"beyond the 8-bit field's -128\.\.127"):
        FieldScale.integer("id", -200, 127).check_fits(-8, "signed")


def test_a_range_whose_codes_overflow_is_refused() -> None:
    scale = FieldScale(name="huge", lo=-1e308, hi=1e308, codes=1e10, span=1e-10)
    with pytest.raises(ValueError, match="overflows its codes"):
        scale.check_fits(32, "wide")

"""servobus.timing.format_duration: every duration a message prints, in the unit a person reads."""

from __future__ import annotations

import pytest

from servobus.timing import format_duration


@pytest.mark.parametrize(
    ("seconds", "text"),
    [
        (0.00677841, "6.8 ms"),  # the "no reply within 0.00677841 s"
        (1.25, "1.25 s"),
        (8.5e-5, "85 µs"),
        (0.05, "50 ms"),
        (0.0001, "100 µs"),
        (0.3, "300 ms"),  # (0.3 / 1e-3 is 299.99999999999994)
        (12.5, "12.5 s"),
        (1250.0, "1250 s"),
        (2.0, "2 s"),
        (0.00105, "1.1 ms"),
        (0.99996, "1 s"),  # rounded before the unit is chosen: not "1000 ms"
        (0.0009999, "1 ms"),
        (5e-7, "0.5 µs"),
        (0.0, "0 s"),
        (-0.0123, "-12.3 ms"),
        (float("inf"), "inf s"),
    ],
)
def test_durations_read_in_their_unit_with_three_digits_at_most(seconds: float, text: str) -> None:
    assert format_duration(seconds) == text

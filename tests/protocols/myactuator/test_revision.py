"""Protocol revision and the rule choosing it from the 0xB2 version date (revision.py)."""

from __future__ import annotations

import datetime

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.protocols import myactuator as ma


def test_members_and_names() -> None:
    assert [r.name for r in ma.Revision] == ["V4_3", "V4_4"]
    assert str(ma.Revision.V4_4) == "V4_4"
    assert ma.FAMILY.revisions[0] is ma.Revision.V4_4  # newest first


def test_rule_uses_the_v44_manual_date_as_default_cutoff() -> None:
    assert ma.V4_4_MANUAL_DATE == 20260325  # [000]'s change log, "2026.03.25"
    assert ma.revision_from_version_date(20220206) is ma.Revision.V4_3  # the manuals' 0xB2 example
    assert ma.revision_from_version_date(20260324) is ma.Revision.V4_3
    assert ma.revision_from_version_date(20260325) is ma.Revision.V4_4


def test_the_cutoff_is_overridable() -> None:
    assert ma.revision_from_version_date(20250601, cutoff=20250512) is ma.Revision.V4_4
    assert ma.revision_from_version_date(20250511, cutoff=20250512) is ma.Revision.V4_3


@pytest.mark.parametrize("bad", [0, 2022026, 20221301, 20220100, 19991231, 210001011, True, 2.022e7])
def test_implausible_dates_are_refused(bad: object) -> None:
    with pytest.raises(ValueError, match="yyyymmdd="):
        ma.revision_from_version_date(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cutoff="):
        ma.revision_from_version_date(20220206, cutoff=bad)  # type: ignore[arg-type]


DATES = st.dates(min_value=datetime.date(2000, 1, 1), max_value=datetime.date(2099, 12, 31))


@given(DATES, DATES)
def test_rule_is_a_monotonic_cutoff(date: datetime.date, cutoff: datetime.date) -> None:
    as_int = date.year * 10000 + date.month * 100 + date.day
    cut = cutoff.year * 10000 + cutoff.month * 100 + cutoff.day
    expected = ma.Revision.V4_4 if date >= cutoff else ma.Revision.V4_3
    assert ma.revision_from_version_date(as_int, cutoff=cut) is expected

"""Protocol revisions of the MyActuator V3-driver protocol, and how to pick one from a motor.

Two manual revisions are implemented (myactuator-v4.md §8 lists every difference):

* ``V4_3``: [002], "V4.3, 2025.05". Has 0x79 (CAN-ID setting) and 0x90 (single-turn encoder); 0x94 returns
  a uint16 0..359.99°; 0xB5 returns 7 characters in one frame; MIT ranges p ±12.5 rad, kd 0..5, t ±24 N·m.
* ``V4_4``: [000], change log dated 2026-03-25. Adds 0x72/0x73 and 0x20 index 8, removes 0x79 and 0x90;
  0x94 returns an int32 ±180°; 0xB5 is read in three indexed frames; MIT p ±12.566 rad, kd 0..50,
  t ±Motor Max Torque.

Choosing the revision from the motor (0xB2 software version date)
------------------------------------------------------------------
Neither manual maps a firmware version date (the YYYYMMDD that 0xB2 returns) to a protocol revision: the
change logs date the *manuals* (V4.3: 2025.5.12 in [002] and in [000]'s Chinese text, 2024.5.12 in [000]'s
English text; V4.4: 2026.03.25), not firmware releases. So no cutoff can be derived from the manuals. The
rule here is explicit and overridable rather than precise:

    a firmware dated on or after ``cutoff`` (default :data:`V4_4_MANUAL_DATE`, 20260325, the date of the
    V4.4 change log) speaks V4.4; anything older speaks V4.3.

Firmware that already implements V4.4 may predate its manual, and firmware much older than 2025 may lack
V4.3 commands (0xA9, indexed 0x30) too; the codec cannot know. Pass ``cutoff=`` when you know your
firmware, or set the revision explicitly (design.md: "a revision is a parameter, never a guess hidden in
code"). The 0x94 and 0xB5 replies also carry a hint (see ``replies.guess_single_turn_revision``).
"""

from __future__ import annotations

import enum

__all__ = ["V4_4_MANUAL_DATE", "Revision", "revision_from_version_date"]


class Revision(enum.Enum):
    """A protocol revision of the MyActuator V3-driver manuals."""

    V4_3 = "4.3"
    V4_4 = "4.4"

    def __str__(self) -> str:
        return self.name


ALL_REVISIONS: frozenset[Revision] = frozenset(Revision)
ONLY_V4_3: frozenset[Revision] = frozenset({Revision.V4_3})
ONLY_V4_4: frozenset[Revision] = frozenset({Revision.V4_4})

#: Revision date of the V4.4 manual's change log ([000], "2026.03.25" / "March 25, 2026").
V4_4_MANUAL_DATE = 20260325


def _check_date(name: str, yyyymmdd: int) -> None:
    if isinstance(yyyymmdd, bool) or not isinstance(yyyymmdd, int):
        raise ValueError(f"{name}={yyyymmdd!r} is not an integer YYYYMMDD date")
    year, month, day = yyyymmdd // 10000, yyyymmdd // 100 % 100, yyyymmdd % 100
    if not (2000 <= year <= 2099 and 1 <= month <= 12 and 1 <= day <= 31):
        raise ValueError(f"{name}={yyyymmdd!r} is not a YYYYMMDD date in 20000101..20991231")


def revision_from_version_date(yyyymmdd: int, *, cutoff: int = V4_4_MANUAL_DATE) -> Revision:
    """The protocol revision to assume for a firmware of this 0xB2 version date.

    The rule (module docstring): ``V4_4`` if ``yyyymmdd >= cutoff``, else ``V4_3``. The default cutoff is
    the V4.4 manual's date; the manuals give no firmware mapping, so override it when you know better.

    Args:
        yyyymmdd: the 0xB2 ``VersionDate`` (e.g. 20220206), or a ``VersionDateReply``'s ``version_date``.
        cutoff: first firmware date taken to speak V4.4.

    Returns:
        The revision.

    Raises:
        ValueError: ``yyyymmdd`` or ``cutoff`` is not a plausible YYYYMMDD date.
    """
    _check_date("yyyymmdd", yyyymmdd)
    _check_date("cutoff", cutoff)
    return Revision.V4_4 if yyyymmdd >= cutoff else Revision.V4_3


def revision_names(revisions: frozenset[Revision]) -> str:
    """``"V4.3"`` or ``"V4.3 and V4.4"``, for error messages."""
    return " and ".join(f"V{r.value}" for r in sorted(revisions, key=lambda r: r.value))

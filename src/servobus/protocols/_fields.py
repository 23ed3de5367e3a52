"""Little-endian integer fields with physical scaling and range checks, shared by every family.

The manuals describe payloads as integers of 1..8 bytes carrying ``value * counts_per_unit``
(0.01 A/LSB is ``counts_per_unit=100``). A field object states that once, and checks, encodes and
decodes it the same way everywhere::

    SPEED = ScaledField("speed_dps", size=4, signed=True, counts_per_unit=100)
    SPEED.check(v)            # ValueError naming the field, the value and the limits
    SPEED.encode(1.5)         # b'\\x96\\x00\\x00\\x00'
    SPEED.decode(data, 4)     # float

Encoding rounds half away from zero, as the C core does (``servobus.core.packing``), so a value
decodes to itself quantised to the field's resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum, IntEnum
from typing import TypeVar

__all__ = [
    "IntField",
    "ScaledField",
    "check_choice",
    "check_flag",
    "check_range",
    "round_half_away",
    "to_enum",
]

E = TypeVar("E", bound=IntEnum)


def round_half_away(x: float) -> int:
    """Round to the nearest integer, ties away from zero (the manuals' C casts after +0.5)."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def check_range(name: str, value: float, lo: float, hi: float) -> None:
    """Raise ValueError unless lo <= value <= hi (NaN and infinities are outside every range)."""
    if not lo <= value <= hi:
        raise ValueError(f"{name}={value!r} is outside [{lo!r}, {hi!r}]")


def check_flag(name: str, value: object) -> bool:
    """``value`` as a bool; accepts True/False and 0/1.

    Raises:
        ValueError: anything else.
    """
    if value is True or value is False:
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    raise ValueError(f"{name}={value!r} is not one of False, True")


def to_enum(name: str, value: object, enum: type[E]) -> E:
    """``value`` as a member of ``enum`` (members and their integer values are accepted).

    Raises:
        ValueError: no member has that value (the message lists the members).
    """
    # A member of another enum (CanMode.NORMAL for a ControlMode) is a mistake, not its integer.
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or (isinstance(value, IntEnum) and not isinstance(value, enum))
    ):
        raise ValueError(f"{name}={value!r} is not one of {', '.join(m.name for m in enum)}")
    try:
        return enum(value)
    except ValueError:
        members = ", ".join(f"{m.name}={m.value}" for m in enum)
        raise ValueError(f"{name}={value!r} is not one of {members}") from None


def check_choice(name: str, value: object, choices: object) -> None:
    """Raise ValueError unless ``value`` is among ``choices`` (an enum class, a set, a range).

    For an enum class, a member or a member's value counts (Python 3.12's ``in``; 3.11 raises
    TypeError for non-members instead).
    """
    if isinstance(choices, type) and issubclass(choices, Enum):
        found = isinstance(value, choices) or any(value == member.value for member in choices)
    else:
        try:
            found = value in choices  # type: ignore[operator]
        except TypeError:  # unhashable value for a set, a str for a range...
            found = False
    if not found:
        raise ValueError(f"{name}={value!r} is not one of {_describe(choices)}")


def _describe(choices: object) -> str:
    if isinstance(choices, range):
        return f"{choices.start}..{choices.stop - 1}"
    try:
        return ", ".join(repr(c) for c in choices)  # type: ignore[attr-defined]
    except TypeError:
        return repr(choices)


def _int_limits(size: int, signed: bool) -> tuple[int, int]:
    if not 1 <= size <= 8:
        raise ValueError(f"field size {size} is not 1..8 bytes")
    bits = 8 * size
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)


@dataclass(frozen=True, slots=True)
class IntField:
    """An integer carried as-is in ``size`` little-endian bytes, optionally narrowed to [lo, hi]."""

    name: str
    size: int
    signed: bool = False
    lo: int | None = None
    hi: int | None = None
    _limits: tuple[int, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        code_lo, code_hi = _int_limits(self.size, self.signed)
        lo = code_lo if self.lo is None else self.lo
        hi = code_hi if self.hi is None else self.hi
        if not code_lo <= lo <= hi <= code_hi:
            raise ValueError(f"{self.name}: limits [{lo}, {hi}] do not fit {self.size} bytes")
        object.__setattr__(self, "_limits", (lo, hi))

    @property
    def limits(self) -> tuple[int, int]:
        return self._limits

    def check(self, value: int) -> None:
        """Raise ValueError unless ``value`` is an int within the field's limits."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{self.name}={value!r} is not an integer")
        check_range(self.name, value, *self._limits)

    def encode(self, value: int) -> bytes:
        self.check(value)
        return value.to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes, offset: int = 0) -> int:
        return int.from_bytes(data[offset : offset + self.size], "little", signed=self.signed)


@dataclass(frozen=True, slots=True)
class ScaledField:
    """A physical value carried as ``round(value * counts_per_unit)`` in ``size`` little-endian bytes.

    ``lo``/``hi`` narrow the physical range (the manuals' stated limits); by default the range is
    what the integer holds.
    """

    name: str
    size: int
    signed: bool = True
    counts_per_unit: float = 1.0
    lo: float | None = None
    hi: float | None = None
    _limits: tuple[float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        code_lo, code_hi = _int_limits(self.size, self.signed)
        if not self.counts_per_unit > 0:
            raise ValueError(f"{self.name}: counts_per_unit must be > 0")
        lo = code_lo / self.counts_per_unit if self.lo is None else self.lo
        hi = code_hi / self.counts_per_unit if self.hi is None else self.hi
        if (
            not code_lo
            <= round_half_away(lo * self.counts_per_unit)
            <= round_half_away(hi * self.counts_per_unit)
            <= code_hi
        ):
            raise ValueError(f"{self.name}: limits [{lo}, {hi}] do not fit {self.size} bytes")
        object.__setattr__(self, "_limits", (lo, hi))

    @property
    def limits(self) -> tuple[float, float]:
        return self._limits

    @property
    def resolution(self) -> float:
        """The value of one count, in the field's unit."""
        return 1.0 / self.counts_per_unit

    def check(self, value: float) -> None:
        """Raise ValueError unless ``value`` is a real number within the field's limits."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name}={value!r} is not a number")
        check_range(self.name, value, *self._limits)

    def to_code(self, value: float) -> int:
        self.check(value)
        return round_half_away(value * self.counts_per_unit)

    def encode(self, value: float) -> bytes:
        return self.to_code(value).to_bytes(self.size, "little", signed=self.signed)

    def from_code(self, code: int) -> float:
        return code / self.counts_per_unit

    def decode(self, data: bytes, offset: int = 0) -> float:
        code = int.from_bytes(data[offset : offset + self.size], "little", signed=self.signed)
        return code / self.counts_per_unit

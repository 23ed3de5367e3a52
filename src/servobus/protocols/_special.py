"""Raw values with a meaning of their own, and the one rule that keeps numbers out of them.

Some fields give one raw value a meaning other than its number: MyActuator's maxSpeed 0 is "no limit",
its 0xB3 timeout 0 is "protection off". A number that lands there by accident (``max_speed_dps=0.4``
rounds to 0) asks for the opposite of what was meant. The rule, the same in every family:

* the special meaning is requested only explicitly: ``None`` for the field (``max_speed_dps=None``), or
  a named builder or enum member where a field has several;
* a number that would encode to the special raw value, or to a raw value the manual leaves undefined,
  raises ValueError naming the field, the value, what it would have meant and how to ask for it;
* numbers are rounded to the field's step half away from zero (:func:`~._fields.round_half_away`), so a
  non-zero value that rounds onto the special code is refused like the code itself;
* decoding maps the special raw value back to the explicit form (a decoded maxSpeed 0 is
  ``max_speed_dps=None``), so the device side keeps understanding it; an undefined raw value does not
  decode.

Each family lists its fields in ``protocols/<family>/special.py`` (:class:`SpecialValue` rows, with the
manual section); ``docs/special-values.md`` is :func:`render_markdown` of them, checked by a test.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any

from servobus.protocols._fields import IntField, ScaledField, round_half_away

__all__ = ["SpecialValue", "SpecialZero", "all_special_values", "render_markdown"]


@dataclass(frozen=True, slots=True)
class SpecialZero:
    """A numeric field whose raw ``raw`` (0 unless told) is not the number it looks like.

    ``inner`` is the plain field (IntField, ScaledField or a MyActuator StepField). With
    ``explicit=True`` the value ``None`` encodes to ``raw`` and ``raw`` decodes to ``None``; with
    ``explicit=False`` the manual leaves ``raw`` undefined: nothing encodes to it and it does not decode.
    Any number whose code is ``raw`` is refused.
    """

    inner: Any
    meaning: str
    explicit: bool = True
    raw: int = 0
    unit: str = ""
    how: str = ""  # how to ask for it, when more than ``name=None`` is needed
    _step: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        inner = self.inner
        if isinstance(inner, ScaledField):
            step = 1.0 / inner.counts_per_unit
        elif isinstance(inner, IntField):
            step = 1.0
        else:
            step = float(inner.step)
        object.__setattr__(self, "_step", step)

    @property
    def name(self) -> str:
        return str(self.inner.name)

    @property
    def size(self) -> int:
        return int(self.inner.size)

    @property
    def signed(self) -> bool:
        return bool(getattr(self.inner, "signed", False))

    @property
    def limits(self) -> tuple[float, float]:
        """The ordinary values' range (the plain field's; ``raw`` itself is refused within it)."""
        lo, hi = self.inner.limits
        return (lo, hi)

    @property
    def resolution(self) -> float:
        """The value of one count: numbers round to a multiple of it, half away from zero."""
        return self._step

    @property
    def request(self) -> str:
        """How to ask for the special meaning, or "" when it cannot be sent."""
        if not self.explicit:
            return ""
        return self.how or f"{self.name}=None"

    def code_of(self, value: float) -> int:
        """The code a (checked) number encodes to, special or not."""
        if isinstance(self.inner, IntField):
            return int(value)
        if isinstance(self.inner, ScaledField):
            return self.inner.to_code(value)
        return round_half_away(value / self._step)

    def check(self, value: Any) -> None:
        """Raise ValueError unless ``value`` is ``None`` (when explicit) or a number off the special code."""
        if value is None:
            if not self.explicit:
                raise ValueError(
                    f"{self.name}=None asks for raw {self.raw}, which {self.meaning}: it cannot be sent"
                )
            return
        self.inner.check(value)
        if self.code_of(value) != self.raw:
            return
        unit = f" {self.unit}" if self.unit else ""
        step = f"{self._step:g}{unit}"
        if value != self.raw * self._step:
            how = f"rounds (half away from zero, to the field's step of {step}) to raw {self.raw}"
        else:
            how = f"encodes to raw {self.raw}"
        if self.explicit:
            ask = f"ask for that explicitly with {self.request}"
        else:
            ask = "the manual leaves it undefined, so it cannot be sent"
        nearest = (self.raw + 1) * self._step
        raise ValueError(
            f"{self.name}={value!r} {how}, which {self.meaning}; {ask} "
            f"(a number must round to at least {nearest:g}{unit})"
        )

    def to_code(self, value: Any) -> int:
        self.check(value)
        return self.raw if value is None else self.code_of(value)

    def encode(self, value: Any) -> bytes:
        return self.to_code(value).to_bytes(self.size, "little", signed=self.signed)

    def from_code(self, code: int) -> Any:
        if code == self.raw:
            if not self.explicit:
                raise ValueError(f"{self.name}: raw {code} {self.meaning}")
            return None
        if isinstance(self.inner, ScaledField):
            return self.inner.from_code(code)
        if isinstance(self.inner, IntField):
            return code
        return code * self.inner.step

    def decode(self, data: bytes, offset: int = 0) -> Any:
        code = int.from_bytes(data[offset : offset + self.size], "little", signed=self.signed)
        return self.from_code(code)


@dataclass(frozen=True, slots=True)
class SpecialValue:
    """One row of a family's audit: a raw value of one command's field that is not its number.

    ``request`` says how to ask for it ("" when it cannot be sent: the manual leaves it undefined).
    ``offset`` and ``spec`` let the test check the row: where the raw code sits in ``encode()`` and the
    numeric field (a :class:`SpecialZero`) whose ordinary values must never reach it; rows of fields
    whose every value is named (flags, enums, frame patterns) have ``spec`` None.
    """

    family: str
    cls: type
    field: str
    raw: str
    meaning: str
    section: str
    request: str
    offset: int | None = None
    spec: SpecialZero | None = None

    @property
    def command(self) -> str:
        code = getattr(self.cls, "CODE", None)
        prefix = f"0x{code:02X} " if isinstance(code, int) else ""
        return f"{prefix}{self.cls.__name__}"

    @classmethod
    def of(cls, family: str, command: type, spec: SpecialZero, *, offset: int, section: str) -> SpecialValue:
        """The row of a :class:`SpecialZero` field (meaning and request come from the field itself)."""
        request = spec.request or "cannot be sent (refused); decoding refuses it too"
        meaning = spec.meaning
        return cls(
            family, command, spec.name, str(spec.raw), meaning, section, request, offset=offset, spec=spec
        )


def all_special_values() -> tuple[SpecialValue, ...]:
    """Every built-in family's rows (its ``special`` module's ``SPECIAL_VALUES``), in registry order."""
    from servobus.protocols import FAMILIES

    rows: list[SpecialValue] = []
    for target in FAMILIES.values():
        package = target.partition(":")[0]
        rows += importlib.import_module(f"{package}.special").SPECIAL_VALUES
    return tuple(rows)


_HEADER = """\
# Special values: raw field values that are not their number

Some fields give one raw value a meaning of its own (MyActuator's maxSpeed 0 is "no speed limit"), or
the manual leaves a raw value undefined. servobus applies one rule to all of them (see
`src/servobus/protocols/_special.py`):

* the special meaning is asked for **only explicitly**: `None` for the field (`max_speed_dps=None`),
  or a named builder, class or enum member where the "Request" column says so;
* a number that would encode to the special raw value, or to an undefined one, raises `ValueError`
  naming the field, the value, what it would have meant and how to ask for it explicitly;
* numbers are rounded to the field's step **half away from zero** (the C core's rule), and a non-zero
  number that rounds onto the special code is refused like the code itself (`max_speed_dps=0.4` on a
  1 dps field, `interval_ms=3` on the 10 ms 0xB6 field);
* decoding turns the special raw value back into the explicit form (a received maxSpeed 0 is
  `max_speed_dps=None`), so the simulator keeps understanding it; an undefined raw value does not decode.

Sections refer to the specs in `shared/spec/` (the manuals they were written from are the authority).
This table is generated from the `SPECIAL_VALUES` rows in `protocols/<family>/special.py`
(`python -c "from servobus.protocols._special import render_markdown; print(render_markdown(), end='')"`);
`tests/protocols/test_special.py` fails when the two differ.

"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def render_markdown() -> str:
    """``docs/special-values.md``: the header and one table row per special field of every family."""
    lines = [
        "| family | command | field | raw | meaning | section | request |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in all_special_values():
        request = f"`{row.request}`" if row.request and not row.request.startswith("cannot") else row.request
        lines.append(
            "| "
            + " | ".join(
                _cell(c)
                for c in (
                    row.family,
                    row.command,
                    f"`{row.field}`",
                    row.raw,
                    row.meaning,
                    row.section,
                    request,
                )
            )
            + " |"
        )
    return _HEADER + "\n".join(lines) + "\n"

"""Hollow payloads declared once (private): the fields a C-core packer carries, and the class that
derives validation, ``encode`` and ``decode`` from them.

The hollow frames are bit-packed (16/12/12/12/12 setpoints, 40-bit FD positions) and their scales
depend on the motor model, so they are not the byte-aligned layouts of :mod:`servobus.protocols._layout`:
a :class:`Packed` class names its packer in :class:`~servobus.protocols.hollow.model.Packers` and lists
its fields in the packer's order, each with its kind and limits (a function of the model where the
manual leaves the scale per motor). The C core keeps the packing fast; the field list keeps the
validation, the decoders and the fast paths of :mod:`servobus.protocols.hollow.bound` in step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from operator import attrgetter
from typing import Any, ClassVar, Protocol, Self

from servobus.protocols._message import Message
from servobus.protocols.hollow._checks import (
    build,
    check_flag,
    check_int,
    check_real,
    decode_enum,
    require_size,
    to_enum,
)
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel, packers

__all__ = [
    "Choice",
    "Flag",
    "Int",
    "OnLinks",
    "Packed",
    "PackedField",
    "Real",
    "check_model",
    "fd_position_limits_deg",
    "fd_velocity_limits_rpm",
]


def check_model(model: object) -> None:
    """Raise ValueError unless ``model`` is a :class:`HollowModel`."""
    if not isinstance(model, HollowModel):
        raise ValueError(f"model={model!r} is not a HollowModel")


def fd_position_limits_deg(model: HollowModel | None = None) -> tuple[float, float]:
    """The 40-bit signed position in degrees (1,048,576 counts per turn, §7.2); the same for every model."""
    top = 1 << 39
    return (-top * 360.0 / COUNTS_PER_TURN, (top - 1) * 360.0 / COUNTS_PER_TURN)


def fd_velocity_limits_rpm(model: HollowModel) -> tuple[float, float]:
    """The int32 velocity in shaft rpm for ``model``'s pole pairs (§7.4)."""
    per_rpm = model.fd_velocity_counts_per_rpm
    return (-(1 << 31) / per_rpm, ((1 << 31) - 1) / per_rpm)


class PackedField(Protocol):
    """One field of a packed payload: its attribute name, its check and its decoded value."""

    @property
    def name(self) -> str: ...

    def check(self, value: Any, model: HollowModel, /) -> Any:
        """``value`` as stored (an enum member, a bool); ValueError naming field and limits."""

    def decode(self, raw: float, data: bytes, /) -> Any:
        """The packer's number as the constructor's argument (ProtocolError for a bad enum code)."""


@dataclass(frozen=True, slots=True)
class Real:
    """A real number within limits that may depend on the model (a scaled bit field)."""

    name: str
    limits: Callable[[HollowModel], tuple[float, float]]

    def check(self, value: Any, model: HollowModel) -> Any:
        check_real(self.name, value, *self.limits(model))
        return value

    def decode(self, raw: float, data: bytes) -> Any:
        return raw


@dataclass(frozen=True, slots=True)
class Int:
    """An integer code within [lo, hi] (gains, ids, raw currents)."""

    name: str
    lo: int
    hi: int

    def check(self, value: Any, model: HollowModel) -> Any:
        check_int(self.name, value, self.lo, self.hi)
        return value

    def decode(self, raw: float, data: bytes) -> Any:
        return int(raw)


@dataclass(frozen=True, slots=True)
class Flag:
    """A 0/1 byte stored as a bool; any other byte does not decode."""

    name: str

    def check(self, value: Any, model: HollowModel) -> Any:
        return check_flag(self.name, value)

    def decode(self, raw: float, data: bytes) -> Any:
        return int(raw)


class _Getter(Protocol):
    """A getter of field values (an ``attrgetter``): a callable object, not a method."""

    def __call__(self, message: Any, /) -> tuple[Any, ...]: ...


@dataclass(frozen=True, slots=True)
class Choice:
    """An IntEnum byte; ``label`` names it in a decoding error (the manual's name, "Mode Sel")."""

    name: str
    enum: type[IntEnum]
    label: str

    def check(self, value: Any, model: HollowModel) -> Any:
        return to_enum(self.name, value, self.enum)

    def decode(self, raw: float, data: bytes) -> Any:
        return decode_enum(self.label, int(raw), self.enum, data)


class Packed(Message):
    """A payload packed by the C core: ``PACKER`` (a :class:`Packers` attribute), ``SIZE`` bytes,
    ``FIELDS`` in the packer's order, and a ``model`` attribute giving the scales.

    ``WHAT`` names the payload in length errors. :meth:`refuse` lets a layout reject bytes that are
    another frame (a setpoint that is the special-command pattern).
    """

    __slots__ = ()
    PACKER: ClassVar[str]
    SIZE: ClassVar[int]
    WHAT: ClassVar[str]
    FIELDS: ClassVar[tuple[PackedField, ...]]
    _VALUES: ClassVar[_Getter]  # the field values in FIELDS order
    model: HollowModel

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "FIELDS" in cls.__dict__:
            cls._VALUES = attrgetter(*(spec.name for spec in cls.FIELDS))

    def __post_init__(self) -> None:
        model = self.model
        check_model(model)
        for spec in self.FIELDS:
            value = getattr(self, spec.name)
            checked = spec.check(value, model)
            if checked is not value:
                object.__setattr__(self, spec.name, checked)

    def encode(self) -> bytes:
        packed: bytes = getattr(packers(self.model), self.PACKER).pack(self._VALUES(self))
        return packed

    @classmethod
    def refuse(cls, data: bytes) -> None:
        """Raise ProtocolError if ``data`` (of the right size) is another frame; by default nothing."""

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode ``SIZE`` payload bytes with ``model``'s scales.

        Raises:
            ProtocolError: wrong length, another frame (:meth:`refuse`), or a value the class refuses.
        """
        require_size(data, cls.SIZE, what=cls.WHAT)
        cls.refuse(data)
        raws = getattr(packers(model), cls.PACKER).unpack(data)
        values = {spec.name: spec.decode(raw, data) for spec, raw in zip(cls.FIELDS, raws, strict=True)}
        return build(cls, data, model=model, **values)


class OnLinks:
    """The links of :func:`~servobus.protocols.hollow.bound.bind` a command travels on (``"can"``,
    ``"canfd"``, ``"rs485"``, ``"modbus"``); empty for a frame sent outside the bound codec."""

    __slots__ = ()
    LINKS: ClassVar[tuple[str, ...]] = ()

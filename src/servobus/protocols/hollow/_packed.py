"""Hollow payloads declared once (private): :class:`Packed`, a public bit layout
(:mod:`servobus.protocols.bits`, what a plug-in family declares its packed frames with) that the C core packs.

The hollow frames are bit-packed (16/12/12/12/12 setpoints, 40-bit FD positions) and their scales
depend on the motor model, so they are not the byte-aligned layouts of :mod:`servobus.protocols._layout`:
a :class:`Packed` class declares its fields at their bits, each with its scale (a function of the
model where the manual leaves the scale per motor), and names the C-core packer that packs the same
fields in the same order (:class:`~servobus.protocols.hollow.model.Packers`). The declaration gives
the validation and the decoders; the C core keeps the packing fast, and is tested against it.
"""

from __future__ import annotations

from operator import attrgetter
from typing import Any, ClassVar, Protocol, Self

from servobus.protocols.bits import BitField, BitLayout
from servobus.protocols.hollow._checks import require_size
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel, packers

__all__ = [
    "OnLinks",
    "Packed",
    "check_model",
    "fd_position_limits_deg",
    "fd_velocity_limits_rpm",
]


class _Getter(Protocol):
    """A getter of field values (an ``attrgetter``): a callable object, not a method."""

    def __call__(self, message: Any, /) -> tuple[Any, ...]: ...


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


class Packed(BitLayout):
    """A hollow payload: a :class:`~servobus.protocols.bits.BitLayout` (``SIZE``, ``FIELDS`` at
    their bits, scales from the ``model`` attribute) that the C core packs: ``PACKER`` names its
    packer in :class:`~servobus.protocols.hollow.model.Packers`, whose fields are ``FIELDS`` in
    order. The declaration is the reference the packer is tested against (tests/protocols/test_bits.py).

    ``WHAT`` names the payload in length errors. :meth:`refuse` lets a layout reject bytes that are
    another frame (a setpoint that is the special-command pattern).
    """

    __slots__ = ()
    PACKER: ClassVar[str]
    FIELDS: ClassVar[tuple[BitField, ...]]
    _VALUES: ClassVar[_Getter]  # the field values in FIELDS order
    model: HollowModel

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "FIELDS" in cls.__dict__:
            cls._VALUES = attrgetter(*(spec.name for spec in cls.FIELDS))

    def __post_init__(self) -> None:
        check_model(self.model)
        BitLayout.__post_init__(self)

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
        return super().decode(data, model=model)


class OnLinks:
    """The links of :func:`~servobus.protocols.hollow.bound.bind` a command travels on (``"can"``,
    ``"canfd"``, ``"rs485"``, ``"modbus"``); empty for a frame sent outside the bound codec."""

    __slots__ = ()
    LINKS: ClassVar[tuple[str, ...]] = ()

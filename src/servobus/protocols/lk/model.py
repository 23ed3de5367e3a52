"""The parameters an LK payload depends on: protocol revision, motor type, encoder width.

Spec §9 lists what changes between the revisions (reply identifier, 0x9A/0x9D/0x94/0xA2/0xA5/0xA6
layouts, the 0x40/0x42/0x44 addressing, the commands that exist). Spec §8.2 lists what changes
between motor types: the meaning and scale of the status-2 int16 at DATA[2..3] (torque current iq in
A for MF/MG, a unitless output power for MS, an unstated scale for MH) and of the 0x9D phase currents.
Spec §2 gives the encoder widths. :class:`LkModel` bundles the three so the codec entry points take
one ``model=`` argument; messages whose bytes depend on one of them carry it as a field, so their
``encode()`` needs nothing else.

Resolutions applied here (each also in the package docstring):

* MG torque current is 66/4096 A per count on both revisions. [003] V2.35 writes "-32A~32A" for MG
  in 0xA1 and "-33A~33A" elsewhere; spec §8.2 reads both as roundings of [001]'s 66/4096 A/LSB, and
  one motor has one iq scale in every command and reply.
* MH: neither manual states its A/LSB (spec A23), so MH iq values stay raw counts (``iq_counts``).
* MS has no phase-current sensing ([001] §3, §4): its status-2 DATA[2..3] is the output power
  (unitless, spec A24) on both revisions, kept as ``power_counts``.
* 18-bit encoders are named only by [003]'s closing note ("12bit to 18bit"); the encoder fields are
  uint16, so an 18-bit drive cannot send all its bits. We accept 0..65535 and, for angles, assume it
  sends the top 16 bits (65536 counts per turn) — inferred, unverified.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from types import MappingProxyType

from servobus.protocols._fields import ScaledField, check_choice

__all__ = [
    "DEFAULT_MODEL",
    "ENCODER_BITS",
    "IQ_AMPS_PER_COUNT",
    "LkModel",
    "MotorType",
    "Revision",
    "check_encoder_bits",
    "check_member",
    "encoder_counts_per_turn",
    "encoder_max_count",
    "iq_field",
]


class Revision(enum.Enum):
    """Protocol revision: V2.36 is LK-TECH's manual [001], V2.35 the RMD-S/RMD-F reseller manual [003]."""

    V2_36 = "v2.36"
    V2_35 = "v2.35"


class MotorType(enum.Enum):
    """LK motor family: MS (no current sensing, reports power), MF, MH, MG (report torque current iq)."""

    MS = "MS"
    MF = "MF"
    MH = "MH"
    MG = "MG"


# Spec §8.2. MF and MG only: MH's scale is not stated (A23), MS has no iq.
IQ_AMPS_PER_COUNT: Mapping[MotorType, float] = MappingProxyType(
    {MotorType.MF: 33 / 4096, MotorType.MG: 66 / 4096}
)

ENCODER_BITS = (14, 15, 16, 18)


def check_member(name: str, value: object, enum_cls: type[enum.Enum]) -> None:
    """Raise ValueError unless ``value`` is a member of ``enum_cls`` (a bare int or str is not)."""
    if not isinstance(value, enum_cls):
        names = ", ".join(f"{enum_cls.__name__}.{m.name}" for m in enum_cls)
        raise ValueError(f"{name}={value!r} is not one of {names}")


def check_encoder_bits(encoder_bits: int) -> None:
    """Raise ValueError unless ``encoder_bits`` is one of 14, 15, 16, 18."""
    if isinstance(encoder_bits, bool) or not isinstance(encoder_bits, int):
        raise ValueError(f"encoder_bits={encoder_bits!r} is not an integer")
    check_choice("encoder_bits", encoder_bits, ENCODER_BITS)


def encoder_max_count(encoder_bits: int) -> int:
    """The largest count an encoder field (uint16 on the wire) holds for this encoder width."""
    return (1 << min(encoder_bits, 16)) - 1


def encoder_counts_per_turn(encoder_bits: int) -> int:
    """Counts per mechanical turn as they appear on the wire (18-bit: 65536, inferred, see module doc)."""
    return 1 << min(encoder_bits, 16)


@cache
def iq_field(name: str, motor_type: MotorType, min_counts: int, max_counts: int) -> ScaledField | None:
    """The int16 torque-current field in A for ``motor_type``, limited to [min_counts, max_counts].

    Returns None for MS and MH, whose int16 has no stated ampere scale.
    """
    amps = IQ_AMPS_PER_COUNT.get(motor_type)
    if amps is None:
        return None
    counts_per_amp = 1 / amps
    # Limits are computed as decoding computes a value (count / counts_per_unit), so a decoded
    # extreme count compares equal to the limit instead of one ulp beyond it.
    return ScaledField(
        name,
        size=2,
        signed=True,
        counts_per_unit=counts_per_amp,
        lo=min_counts / counts_per_amp,
        hi=max_counts / counts_per_amp,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class LkModel:
    """What an LK payload's layout and units depend on.

    Defaults: V2.36 (the manufacturer's current manual), MG (its iq scale, 66/4096 A, is also the one
    [003] uses for every motor), 14-bit encoder (the only width both manuals give for 0x90 and the
    only one [003] knows). A drive with a wider encoder must say so: encoder counts above the
    declared width are rejected, so a wrong width shows at the first reply instead of as wrong angles.

    Attributes:
        revision: protocol revision (reply identifier, layouts, available commands).
        motor_type: MS, MF, MH or MG (meaning and scale of iq/power and phase currents).
        encoder_bits: 14, 15, 16 or 18.

    Raises:
        ValueError: a field is not one of its allowed values.
    """

    revision: Revision = Revision.V2_36
    motor_type: MotorType = MotorType.MG
    encoder_bits: int = 14

    def __post_init__(self) -> None:
        check_member("revision", self.revision, Revision)
        check_member("motor_type", self.motor_type, MotorType)
        check_encoder_bits(self.encoder_bits)


DEFAULT_MODEL = LkModel()

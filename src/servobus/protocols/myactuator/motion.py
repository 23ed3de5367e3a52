"""Motion (MIT) mode on CAN: command on 0x400 + ID, reply on 0x500 + ID (myactuator-v4.md §5).

The bit packing is the C core's (``servobus.core.Packer`` with ``MIT_COMMAND``, and ``MIT_REPLY`` in an
8-byte slot); this module supplies the ranges, which differ by revision (§5.5, §9 item 24):

=======  ============  ==========================  ==========================================
field    bits          V4.3 ([002])                V4.4 ([000], defaults)
=======  ============  ==========================  ==========================================
p        16            ±12.5 rad                   ±12.566 rad (change log; its example: ±12.5)
v        12            ±45 rad/s                   ±45 rad/s
kp       12            0..500                      0..500 (English text says 0..1000)
kd       12            0..5                        0..50 (change log and example)
t        12            ±24 N·m                     ±Motor Max Torque (model-specific)
=======  ============  ==========================  ==========================================

V4.4's torque range is the motor model's maximum torque, shown by the vendor's host software; no manual
lists it, so :meth:`MotionScales.for_revision` keeps V4.3's ±24 N·m unless ``max_torque_nm`` is given.
Any range can be overridden by building a :class:`MotionScales`.

Mapping (C core, §5.4): ``[min, max]`` onto ``[0, 2**bits - 1]``, round half away from zero. The reply's
p, v, t use the command's ranges. A command or reply carries its scales, so ``encode()`` needs nothing
else; packers are built once per scales value and cached.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import ClassVar, Self

from servobus.core import MIT_COMMAND, MIT_REPLY, FieldScale, Packer
from servobus.errors import ProtocolError
from servobus.protocols._fields import check_range
from servobus.protocols._message import Command, Reply, require_length
from servobus.protocols.myactuator._layout import PAYLOAD_SIZE, MyActuatorMessage, construct
from servobus.protocols.myactuator.ids import MOTOR_IDS
from servobus.protocols.myactuator.revision import Revision

__all__ = ["MOTION_SCALES", "MotionCommand", "MotionReply", "MotionScales"]


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionScales:
    """The physical ranges of the motion-mode fields (symmetric for p, v, t; from 0 for kp, kd).

    Raises:
        ValueError: a limit that is not a positive finite number.
    """

    p_max_rad: float
    v_max_rad_s: float
    kp_max: float
    kd_max: float
    t_max_nm: float

    def __post_init__(self) -> None:
        for name in ("p_max_rad", "v_max_rad_s", "kp_max", "kd_max", "t_max_nm"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < float("inf"):
                raise ValueError(f"MotionScales.{name}={value!r} must be a positive finite number")

    @classmethod
    def for_revision(cls, revision: Revision, *, max_torque_nm: float | None = None) -> MotionScales:
        """The manual's ranges for ``revision``; ``max_torque_nm`` sets V4.4's ±Motor Max Torque.

        Raises:
            ValueError: ``max_torque_nm`` given for V4.3 (whose range is fixed at ±24 N·m), or not positive.
        """
        base = MOTION_SCALES[revision]
        if max_torque_nm is None:
            return base
        if revision is Revision.V4_3:
            raise ValueError("V4.3 fixes the motion torque range at ±24 N·m; max_torque_nm is V4.4's")
        return cls(
            p_max_rad=base.p_max_rad,
            v_max_rad_s=base.v_max_rad_s,
            kp_max=base.kp_max,
            kd_max=base.kd_max,
            t_max_nm=max_torque_nm,
        )

    def command_scales(self) -> tuple[FieldScale, ...]:
        """FieldScales of MIT_COMMAND (p_des, v_des, kp, kd, t_ff), in layout order."""
        return _command_scales(self)

    def reply_scales(self) -> tuple[FieldScale, ...]:
        """FieldScales of MIT_REPLY (motor id, p, v, t), in layout order."""
        return _reply_scales(self)

    def resolution(self, name: str) -> float:
        """One code of field ``name`` (``position_rad``, ``kd``, ``torque_nm``…) in its unit.

        Raises:
            KeyError: no motion field has that name.
        """
        for scale in (*self.command_scales(), *self.reply_scales()[1:]):
            if scale.name == name:
                return scale.span / scale.codes
        raise KeyError(name)


# Every command and reply checks its values against these: built once per scales value.
@functools.cache
def _command_scales(scales: MotionScales) -> tuple[FieldScale, ...]:
    return (
        FieldScale.linear("position_rad", -scales.p_max_rad, scales.p_max_rad, 16),
        FieldScale.linear("velocity_rad_s", -scales.v_max_rad_s, scales.v_max_rad_s, 12),
        FieldScale.linear("kp", 0.0, scales.kp_max, 12),
        FieldScale.linear("kd", 0.0, scales.kd_max, 12),
        FieldScale.linear("torque_ff_nm", -scales.t_max_nm, scales.t_max_nm, 12),
    )


@functools.cache
def _reply_scales(scales: MotionScales) -> tuple[FieldScale, ...]:
    p, v, _, _, t = _command_scales(scales)
    return (
        FieldScale.integer("motor_id", MOTOR_IDS.start, MOTOR_IDS.stop - 1),
        FieldScale.linear("position_rad", p.lo, p.hi, 16),
        FieldScale.linear("velocity_rad_s", v.lo, v.hi, 12),
        FieldScale.linear("torque_nm", t.lo, t.hi, 12),
    )


MOTION_SCALES: dict[Revision, MotionScales] = {
    Revision.V4_3: MotionScales(p_max_rad=12.5, v_max_rad_s=45.0, kp_max=500.0, kd_max=5.0, t_max_nm=24.0),
    Revision.V4_4: MotionScales(p_max_rad=12.566, v_max_rad_s=45.0, kp_max=500.0, kd_max=50.0, t_max_nm=24.0),
}


@functools.cache
def command_packer(scales: MotionScales) -> Packer:
    """The MIT_COMMAND packer of ``scales`` (built once per scales value)."""
    return Packer(MIT_COMMAND, scales.command_scales())


@functools.cache
def reply_packer(scales: MotionScales) -> Packer:
    """The MIT_REPLY packer of ``scales`` in an 8-byte slot (DATA[6..7] NULL)."""
    return Packer(MIT_REPLY, scales.reply_scales(), stride=PAYLOAD_SIZE)


def _clamped(values: tuple[float, ...], packer: Packer) -> tuple[float, ...]:
    # code * span / codes + origin can land one ulp outside [lo, hi] at the top code (e.g. ±12.566):
    # clamp, so a frame this codec encoded always decodes.
    return tuple(min(max(x, s.lo), s.hi) for x, s in zip(values, packer.scales, strict=True))


def _check(names_values: tuple[tuple[str, float], ...], scales: tuple[FieldScale, ...]) -> None:
    for (name, value), scale in zip(names_values, scales, strict=True):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{name}={value!r} is not a number")
        check_range(name, value, scale.lo, scale.hi)


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionReply(MyActuatorMessage, Reply):
    """Motion (MIT) mode reply on 0x500 + ID (§5.3): DATA[0] motor id, then position, velocity and
    torque packed with the command's ranges. DATA[6..7] are NULL (ignored on decode)."""

    CODE: ClassVar[int | None] = None
    TITLE: ClassVar[str] = "motion mode reply"
    motor_id: int
    position_rad: float
    velocity_rad_s: float
    torque_nm: float
    scales: MotionScales = field(default=MOTION_SCALES[Revision.V4_4])

    def __post_init__(self) -> None:
        if isinstance(self.motor_id, bool) or not isinstance(self.motor_id, int):
            raise ValueError(f"motor_id={self.motor_id!r} is not an integer")
        _check(self._named(), self.scales.reply_scales())

    def _named(self) -> tuple[tuple[str, float], ...]:
        return (
            ("motor_id", self.motor_id),
            ("position_rad", self.position_rad),
            ("velocity_rad_s", self.velocity_rad_s),
            ("torque_nm", self.torque_nm),
        )

    def encode(self) -> bytes:
        return reply_packer(self.scales).pack([v for _, v in self._named()])

    @classmethod
    def decode(cls, data: bytes, scales: MotionScales | None = None) -> Self:
        """Decode 8 bytes with ``scales`` (default V4.4's).

        Raises:
            ProtocolError: not 8 bytes, or DATA[0] not a motor id 1..32.
        """
        scales = scales or MOTION_SCALES[Revision.V4_4]
        require_length(data, PAYLOAD_SIZE, what="motion reply", command=None)
        if data[0] not in MOTOR_IDS:
            raise ProtocolError(f"motion reply: DATA[0]={data[0]} is not a motor id 1..32", raw=data)
        packer = reply_packer(scales)
        motor_id, p, v, t = _clamped(packer.unpack(data), packer)
        values = {
            "motor_id": int(motor_id),
            "position_rad": p,
            "velocity_rad_s": v,
            "torque_nm": t,
            "scales": scales,
        }
        return construct(cls, data, values)


#: what kp = 0 leaves unused (Command.inactive)
_POSITION = frozenset({"position_rad"})


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionCommand(MyActuatorMessage, Command[MotionReply]):
    """Motion (MIT) mode setpoint, sent on 0x400 + ID (§5.1):
    ``IqRef = [kp·(p_des - p) + kd·(v_des - v) + t_ff] / KT``, all on the output side.

    Its ``scales`` fix the ranges (default: V4.4's, see the module docstring); values outside raise
    ValueError naming the field and its limits.
    """

    CODE: ClassVar[int | None] = None  # no command byte: DATA[0] is p_des's high byte
    TITLE: ClassVar[str] = "motion mode command"
    position_rad: float
    velocity_rad_s: float
    kp: float
    kd: float
    torque_ff_nm: float
    scales: MotionScales = field(default=MOTION_SCALES[Revision.V4_4])

    def inactive(self) -> frozenset[str]:
        """With kp = 0 the position is not acted on (a speed or torque set-point): see Command."""
        return _POSITION if self.kp == 0 else frozenset()

    def __post_init__(self) -> None:
        _check(self._named(), self.scales.command_scales())

    def _named(self) -> tuple[tuple[str, float], ...]:
        return (
            ("position_rad", self.position_rad),
            ("velocity_rad_s", self.velocity_rad_s),
            ("kp", self.kp),
            ("kd", self.kd),
            ("torque_ff_nm", self.torque_ff_nm),
        )

    def encode(self) -> bytes:
        return command_packer(self.scales).pack([v for _, v in self._named()])

    @classmethod
    def decode(cls, data: bytes, scales: MotionScales | None = None) -> Self:
        """Decode 8 bytes with ``scales`` (default V4.4's).

        Raises:
            ProtocolError: not 8 bytes.
        """
        scales = scales or MOTION_SCALES[Revision.V4_4]
        require_length(data, PAYLOAD_SIZE, what="motion command", command=None)
        packer = command_packer(scales)
        p, v, kp, kd, t = _clamped(packer.unpack(data), packer)
        values = {
            "position_rad": p,
            "velocity_rad_s": v,
            "kp": kp,
            "kd": kd,
            "torque_ff_nm": t,
            "scales": scales,
        }
        return construct(cls, data, values)

"""The Damiao DM-J MIT-mode commands and their feedback, each declared once as bit fields.

Every frame is 8 bytes, declared on :class:`~servobus.protocols.bits.BitLayout`: a field is a run
of bits at an offset (bit 0 is the most significant bit of DATA[0]) and a width. A :func:`Linear`
field maps its range onto every code, ``code = (x - lo) * (2**width - 1) / (hi - lo)`` rounded (the
MIT map), and its range may come from the motor's model (``_velocity(m) = (-m.v_max, m.v_max)``):
the message carries its ``model`` and refuses to be made with a value outside the range of that
model, naming field, limits and model. A command told by a fixed payload (FF x 7 and a code byte)
declares constant bits (:class:`Const`) and nothing else.

The five commands to motor ID (CAN id ID) and the read on 0x7FF; the feedback comes on ID + 0x10:

================  =========================  ====================================================
command           payload                    the motor
================  =========================  ====================================================
MitControl        p 16 | v 12 | kp 12 |      runs torque = kp (p - pos) + kd (v - vel) + t; answers
                  kd 12 | t 12               with its feedback
Enable            FF FF FF FF FF FF FF FC    drives the MIT law; answers with its feedback
Disable           FF FF FF FF FF FF FF FD    output off (the safe stop); answers with its feedback
SaveZero          FF FF FF FF FF FF FF FE    the position now is zero (kept in flash); no answer
ClearError        FF FF FF FF FF FF FF FB    clears a latched error; no answer
RefreshState      ID 00 CC 00 00 00 00 00    (on 0x7FF) changes nothing; answers with its feedback
================  =========================  ====================================================
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import ClassVar, TypeVar

from servobus.authoring import BitLayout, Choice, Code, Command, Const, Linear, Reply, le
from servobus_dm.models import DEFAULT_MODEL, KD_RANGE, KP_RANGE, DmModel

__all__ = [
    "ClearError",
    "Disable",
    "DmCommand",
    "DmState",
    "Enable",
    "Feedback",
    "MitControl",
    "RefreshState",
    "Revision",
    "SaveZero",
    "SpecialCommand",
]

R = TypeVar("R", bound=Reply | None, covariant=True)


class Revision(enum.Enum):
    """The protocol revisions (one: the DM-J firmware's MIT mode)."""

    V1 = "1"


class DmState(enum.IntEnum):
    """The feedback's 4-bit ERR code: the motor's state, or the one error it latched."""

    DISABLED = 0x0
    ENABLED = 0x1
    OVER_VOLTAGE = 0x8
    UNDER_VOLTAGE = 0x9
    OVER_CURRENT = 0xA
    MOS_OVER_TEMPERATURE = 0xB
    COIL_OVER_TEMPERATURE = 0xC
    COMMUNICATION_LOST = 0xD
    OVERLOAD = 0xE


def _position(m: DmModel) -> tuple[float, float]:
    return (-m.p_max, m.p_max)


def _velocity(m: DmModel) -> tuple[float, float]:
    return (-m.v_max, m.v_max)


def _torque(m: DmModel) -> tuple[float, float]:
    return (-m.t_max, m.t_max)


class DmCommand(BitLayout, Command[R]):
    """A DM-J request: 8 bytes of bit fields, generic in the reply it gets."""

    __slots__ = ()
    SIZE: ClassVar[int] = 8


# ---- the feedback ----


@dataclass(frozen=True, slots=True, kw_only=True)
class Feedback(BitLayout, Reply):
    """The motor's state (on ID + 0x10), its answer to every command that gets one.

    ``state`` is the ERR code (:class:`DmState`: disabled, enabled or the error latched; the
    Bus keeps an error as the motor's ``MotorFault``, its ``code`` the member),
    ``motor_id`` the low nibble of the motor's id, ``temperature_c`` the driver's MOS temperature
    and ``rotor_temperature_c`` the coil's (whole °C). Position, velocity and torque are scaled by
    the ``model``'s ranges, as in :class:`MitControl`.
    """

    SIZE: ClassVar[int] = 8
    FAULT_CODE: ClassVar[str | None] = "state"  # one code, not flags: the Bus's MotorFault.code
    NO_FAULT_CODES: ClassVar[frozenset[int]] = frozenset({DmState.DISABLED, DmState.ENABLED})
    FIELDS = (
        Choice("state", (0, 4), DmState, label="ERR"),
        Code("motor_id", (4, 4)),
        Linear("position_rad", (8, 16), _position),
        Linear("velocity_rad_s", (24, 12), _velocity),
        Linear("torque_nm", (36, 12), _torque),
        Code("temperature_c", (48, 8)),
        Code("rotor_temperature_c", (56, 8)),
    )
    state: DmState
    motor_id: int
    position_rad: float
    velocity_rad_s: float
    torque_nm: float
    temperature_c: int
    rotor_temperature_c: int
    model: DmModel = DEFAULT_MODEL


# ---- commands ----


@dataclass(frozen=True, slots=True, kw_only=True)
class MitControl(DmCommand[Feedback]):
    """The MIT set-point: torque = kp·(position_rad - pos) + kd·(velocity_rad_s - vel) + torque_nm.

    Position in ±P_MAX rad, velocity in ±V_MAX rad/s, torque in ±T_MAX N·m (the ``model``'s), kp in
    0..500 N·m/rad, kd in 0..5 N·m·s/rad. Only an enabled motor acts on it.
    """

    FIELDS = (
        Linear("position_rad", (0, 16), _position),
        Linear("velocity_rad_s", (16, 12), _velocity),
        Linear("kp", (28, 12), KP_RANGE),
        Linear("kd", (40, 12), KD_RANGE),
        Linear("torque_nm", (52, 12), _torque),
    )
    position_rad: float
    velocity_rad_s: float = 0.0
    kp: float = 0.0
    kd: float = 0.0
    torque_nm: float = 0.0
    model: DmModel = DEFAULT_MODEL

    def inactive(self) -> frozenset[str]:
        """With kp = 0 the motor does not act on the position (host-side limits leave it alone)."""
        return frozenset({"position_rad"}) if self.kp == 0 else frozenset()


class SpecialCommand(DmCommand[R]):
    """A command told by its whole payload: FF x 7 and a code byte."""

    __slots__ = ()


_FF7 = Const((0, 56), (1 << 56) - 1)


@dataclass(frozen=True, slots=True)
class Enable(SpecialCommand[Feedback]):
    """FF x 7 FC: the motor drives the MIT law (of the set-points that follow)."""

    FIELDS = (_FF7, Const((56, 8), 0xFC))


@dataclass(frozen=True, slots=True)
class Disable(SpecialCommand[Feedback]):
    """FF x 7 FD: output off, the shaft coasts (the Bus's safe stop)."""

    FIELDS = (_FF7, Const((56, 8), 0xFD))


@dataclass(frozen=True, slots=True)
class SaveZero(SpecialCommand[None]):
    """FF x 7 FE: the position now becomes zero, kept in flash (send it while disabled)."""

    FIELDS = (_FF7, Const((56, 8), 0xFE))
    SLOW: ClassVar[bool] = True
    NO_REPLY: ClassVar[str | None] = "the motor does not answer a zero"


@dataclass(frozen=True, slots=True)
class ClearError(SpecialCommand[None]):
    """FF x 7 FB: clear the error the motor latched (it comes back disabled)."""

    FIELDS = (_FF7, Const((56, 8), 0xFB))
    NO_REPLY: ClassVar[str | None] = "the motor does not answer a clear"


@dataclass(frozen=True, slots=True, kw_only=True)
class RefreshState(DmCommand[Feedback]):
    """On 0x7FF, DATA[0..1] the motor's id (little-endian), DATA[2] 0xCC: read the state; changes nothing.

    ``motor_id`` is the address, filled in by the bound codec (it is not part of what is asked:
    two refreshes of different motors compare equal).
    """

    FIELDS = (Code("motor_id", le(0, 2)), Const((16, 8), 0xCC), Const((24, 40), 0))
    READ: ClassVar[bool] = True
    motor_id: int = field(default=0, compare=False)

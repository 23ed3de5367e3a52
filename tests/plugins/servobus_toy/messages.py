"""The toy protocol's commands and replies, each declared once.

Every payload is 8 bytes: DATA[0] the command (or reply) byte, little-endian fields at fixed offsets,
the other bytes zero. A command class states its byte, its fields with their units and ranges, the
reply it gets (the type argument of its base) and what kind of command it is (``READ``, ``SLOW``,
``ECHO``, ``NO_REPLY``); the codec, the bound codec and the simulated device read those declarations
and keep no list of their own.

Five commands: a read (:class:`ReadState`), a set-point with a unit and a range (:class:`SetSpeed`),
the stop the Bus sends on leaving (:class:`Stop`), a flash write answered by an echo
(:class:`WriteSpeedLimit`) and a command without a reply (:class:`Restart`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import ClassVar, TypeVar

from servobus.protocols import Command, Reply
from servobus.protocols.authoring import FlagsField, Layout, ScaledField

__all__ = [
    "MAX_SPEED_DPS",
    "ReadState",
    "Restart",
    "Revision",
    "SetSpeed",
    "SpeedLimitEcho",
    "StateReply",
    "Stop",
    "ToyCommand",
    "ToyFaults",
    "ToyReply",
    "WriteSpeedLimit",
]

R = TypeVar("R", bound=Reply | None, covariant=True)

#: The fastest speed a set-point or a limit may ask for (the toy drive's rating).
MAX_SPEED_DPS = 1000.0


class Revision(enum.Enum):
    """The protocol revisions (one so far; a Family lists them, newest first)."""

    V1 = "1"


class ToyFaults(enum.IntFlag):
    """The fault flags a :class:`StateReply` carries (DATA[7])."""

    NONE = 0
    OVER_TEMPERATURE = 0x01
    STALL = 0x02


class ToyCommand(Layout, Command[R]):
    """A toy request: the 8-byte layout, generic in the reply it gets."""

    __slots__ = ()


class ToyReply(Layout, Reply):
    """A toy reply: the 8-byte layout."""

    __slots__ = ()


# ---- replies ----


@dataclass(frozen=True, slots=True, kw_only=True)
class StateReply(ToyReply):
    """0x81: where the output shaft is, how fast it turns, and the drive's faults."""

    CODE: ClassVar[int] = 0x81
    FAULTS: ClassVar[str] = "faults"
    FIELDS = (
        (1, ScaledField("position_deg", 4, counts_per_unit=100)),
        (5, ScaledField("speed_dps", 2, counts_per_unit=10)),
        (7, FlagsField("faults", 1, ToyFaults)),
    )
    position_deg: float
    speed_dps: float
    faults: ToyFaults = ToyFaults.NONE


_LIMIT = ScaledField("limit_dps", 2, signed=False, counts_per_unit=10, lo=0.0, hi=MAX_SPEED_DPS)


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedLimitEcho(ToyReply):
    """0x30: the echo of :class:`WriteSpeedLimit`, its bytes unchanged."""

    CODE: ClassVar[int] = 0x30
    FIELDS = ((1, _LIMIT),)
    limit_dps: float


# ---- commands ----


@dataclass(frozen=True, slots=True)
class ReadState(ToyCommand[StateReply]):
    """0x10: read the state; changes nothing."""

    CODE: ClassVar[int] = 0x10
    READ: ClassVar[bool] = True


@dataclass(frozen=True, slots=True, kw_only=True)
class SetSpeed(ToyCommand[StateReply]):
    """0x20: turn at ``speed_dps`` (-1000..1000 dps, 0.01 dps steps), within the speed limit."""

    CODE: ClassVar[int] = 0x20
    FIELDS = ((1, ScaledField("speed_dps", 4, counts_per_unit=100, lo=-MAX_SPEED_DPS, hi=MAX_SPEED_DPS)),)
    speed_dps: float


@dataclass(frozen=True, slots=True)
class Stop(ToyCommand[StateReply]):
    """0x21: brake to a halt and hold the position reached (the Bus's safe command)."""

    CODE: ClassVar[int] = 0x21


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteSpeedLimit(ToyCommand[SpeedLimitEcho]):
    """0x30: the highest speed any set-point runs at (0..1000 dps, 0.1 dps steps), kept in flash."""

    CODE: ClassVar[int] = 0x30
    SLOW: ClassVar[bool] = True  # a flash write: the echo comes late
    ECHO: ClassVar[bool] = True
    FIELDS = ((1, _LIMIT),)
    limit_dps: float


@dataclass(frozen=True, slots=True)
class Restart(ToyCommand[None]):
    """0x7F: restart the drive: output off, latched faults cleared (the speed limit is kept in flash)."""

    CODE: ClassVar[int] = 0x7F
    NO_REPLY: ClassVar[str | None] = "the device restarts"

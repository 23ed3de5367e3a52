"""What a protocol family declares to the rest of servobus (design.md: "a family is a plug-in").

Each ``servobus.protocols.<family>`` package exposes one :class:`Family` as ``FAMILY``. Upper layers
(scheduler, Bus, simulator, CLI log decoder) reach a family's codec only through it, so adding a
family touches one folder and one registry line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

from servobus.protocols._bound import BoundCodec, Broadcast
from servobus.protocols._message import Command, Reply

__all__ = ["Family"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Family:
    """A protocol family's codec surface.

    Attributes:
        name: registry name (``"myactuator"``, ``"lk"``, ``"hollow"``).
        description: one line for ``servobus`` CLI listings.
        revisions: the protocol revisions the codec speaks, newest first.
        default_revision: the revision used when none is given.
        decode_request: ``(can_id, data, *, revision=..., **params) -> Command``.
        decode_reply: ``(can_id, data, *, revision=..., **params) -> Reply``.
        links: the links the family speaks (``"can"``, ``"rs485"``, ...), default first.
        bind: ``(motor_id, *, revision=None, model=None, link="can", **options) -> BoundCodec``: one
            motor's codec on Frames, the only thing the Bus and the CLI use (protocols/_bound.py).
        broadcast: ``(command, motors) -> Broadcast``: one frame for several bound motors and the
            keys of the replies it collects; ValueError where the family has no such frame.
    """

    name: str
    description: str
    revisions: tuple[Enum, ...]
    default_revision: Enum
    decode_request: Callable[..., Command]
    decode_reply: Callable[..., Reply]
    links: tuple[str, ...]
    bind: Callable[..., BoundCodec]
    broadcast: Callable[..., Broadcast]

    def __post_init__(self) -> None:
        if self.default_revision not in self.revisions:
            raise ValueError(f"{self.name}: default revision {self.default_revision!r} not in revisions")

    def revision(self, name: str | Enum) -> Any:
        """The revision named ``name`` ("V4_3", "v4.3", or the enum member itself).

        Raises:
            ValueError: no revision of this family has that name.
        """
        if isinstance(name, Enum):
            if name in self.revisions:
                return name
        else:
            wanted = name.upper().replace(".", "_")
            for revision in self.revisions:
                if revision.name == wanted:
                    return revision
        known = ", ".join(r.name for r in self.revisions)
        raise ValueError(f"{self.name} has no revision {name!r} (known: {known})")

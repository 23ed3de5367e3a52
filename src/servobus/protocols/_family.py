"""What a protocol family declares to the rest of servobus (design.md: "a family is a plug-in").

Each ``servobus.protocols.<family>`` package exposes one :class:`Family` as ``FAMILY``. Upper layers
(scheduler, Bus, simulator, CLI log decoder) reach a family's codec only through it, so adding a
family touches one folder and one registry line.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import re
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Generic

if sys.version_info >= (3, 13):
    from typing import TypeVar
else:
    from typing_extensions import TypeVar

from servobus.protocols._bound import BoundCodec, Broadcast, Framing
from servobus.protocols._message import Command, Reply

__all__ = ["Family", "SerialLine", "command_classes", "method_name"]

M = TypeVar("M", default=Any)  # the typed Motor class (servobus.Motor for a family without one)


@dataclass(frozen=True, slots=True, kw_only=True)
class SerialLine:
    """One way a family's frames travel on a serial line (RS485): its framing and line settings.

    Attributes:
        name: the framing's name (``"myactuator-rs485"``), unique over all families.
        framing: makes the framing (imported only when a serial line is opened).
        bauds: the rates the manual allows, the default first.
        parity: ``"N"``, ``"E"`` or ``"O"``.
        aliases: other names a user may give for it (``SerialTransport(mode=...)``).
    """

    name: str
    framing: Callable[[], Framing]
    bauds: tuple[int, ...]
    parity: str = "N"
    aliases: tuple[str, ...] = ()


_PARTS = ("sim", "cli", "dbc")


def _exists(module: str) -> bool:
    """True if ``module`` can be imported (found, not imported)."""
    return importlib.util.find_spec(module) is not None


def _lazy(module: str, attribute: str) -> Callable[[], Any]:
    """A function that imports ``module`` when called and returns its ``attribute``."""
    return lambda: getattr(importlib.import_module(module), attribute)


def method_name(cls: type) -> str:
    """A command class's motor method name: ``ReadStatus2`` -> ``read_status2``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", cls.__name__).lower()


def command_classes(namespace: Iterable[object]) -> tuple[type[Command], ...]:
    """The concrete command classes among ``namespace`` (a family package's names): the dataclasses
    deriving from :class:`Command`, each once, in order. A family passes ``globals().values()``."""
    out: dict[type[Command], None] = {}
    for obj in namespace:
        if isinstance(obj, type) and issubclass(obj, Command) and dataclasses.is_dataclass(obj):
            if (obj.REPLY is None) != (obj.NO_REPLY is not None):
                raise TypeError(
                    f"{obj.__name__}: a command declares a reply type or, with Command[None], why none "
                    f"comes (NO_REPLY), not both or neither (REPLY={obj.REPLY!r}, NO_REPLY={obj.NO_REPLY!r})"
                )
            out[obj] = None
    return tuple(out)


@dataclass(frozen=True, slots=True, kw_only=True)
class Family(Generic[M]):
    """A protocol family: everything family-specific that the other layers use, in one plug-in.

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
        commands: every command class (the typed motor methods, the CLI, the simulator and the DBC
            are derived from their declarations).
        motor_ids: the motor ids the manuals allow.
        serial: the serial framings the family's motors (or converters) speak; empty: CAN only.
        motor: the typed :class:`~servobus.Motor` subclass with a method per command (made when
            asked: it imports the Bus).
        parts: ``"module:attribute"`` of the family's larger plug-in parts, imported only when
            asked for with :meth:`part`: ``"sim"`` (simulated devices), ``"cli"`` (the command
            line's operations and settings), ``"dbc"`` (the DBC description).
        package: the family's package, where what is not given is found by name: the typed motor
            in ``<package>._motor`` (class ``Motor``) and the parts in ``<package>.sim``,
            ``.cli`` and ``.dbc`` (objects ``SIM``, ``CLI``, ``DBC``), those modules that exist.
            (``dataclasses.replace`` keeps it: a copy without a part gives ``package=None``.)
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
    commands: tuple[type[Command], ...] = ()
    motor_ids: range = range(0, 256)
    serial: tuple[SerialLine, ...] = ()
    motor: Callable[[], type[M]] | None = None
    parts: dict[str, str] = field(default_factory=dict)
    package: str | None = None

    def __post_init__(self) -> None:
        if self.default_revision not in self.revisions:
            raise ValueError(f"{self.name}: default revision {self.default_revision!r} not in revisions")
        package = self.package
        if package is None:
            return
        if self.motor is None and _exists(f"{package}._motor"):
            object.__setattr__(self, "motor", _lazy(f"{package}._motor", "Motor"))
        found = {p: f"{package}.{p}:{p.upper()}" for p in _PARTS if _exists(f"{package}.{p}")}
        object.__setattr__(self, "parts", {**found, **self.parts})  # given ones win; the caller's dict kept

    def methods(self) -> dict[str, type[Command]]:
        """The command classes by method name, ``ReadStatus2`` -> ``read_status2``: what a
        :class:`~servobus.Motor` of this family offers as ``await motor.read_status2()``."""
        methods: dict[str, type[Command]] = {}
        for cls in self.commands:
            name = method_name(cls)
            if name in methods:
                raise ValueError(f"{self.name}: {methods[name].__name__} and {cls.__name__} are {name}()")
            methods[name] = cls
        return methods

    def part(self, name: str) -> Any:
        """The family's plug-in part ``name`` (``"sim"``, ``"cli"``, ``"dbc"``), imported now.

        Raises:
            LookupError: the family has no such part (the message names the family).
        """
        target = self.parts.get(name)
        if target is None:
            raise LookupError(f"the {self.name} family has no {name} part")
        module, _, attribute = target.partition(":")
        return getattr(importlib.import_module(module), attribute)

    def revision(self, name: str | Enum) -> Any:
        """The revision named ``name`` ("V4_3", "v4.3", or the enum member itself).

        Raises:
            ValueError: no revision of this family has that name.
        """
        return find_revision(self.name, self.revisions, name)


def find_revision(family: str, revisions: tuple[Enum, ...], name: str | Enum) -> Any:
    """The revision of ``revisions`` named ``name`` ("V4_3", "v4.3", or the enum member itself): what
    :meth:`Family.revision` answers, for a family's ``bind``, which runs before its Family exists.

    Raises:
        ValueError: no revision of ``family`` has that name.
    """
    if isinstance(name, Enum):
        if name in revisions:
            return name
    else:
        wanted = name.upper().replace(".", "_")
        for revision in revisions:
            if revision.name == wanted:
                return revision
    known = ", ".join(r.name for r in revisions)
    raise ValueError(f"{family} has no revision {name!r} (known: {known})")

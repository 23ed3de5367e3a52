"""Protocol families: sans-IO codecs between typed commands/replies and payload bytes.

Every family lives in its own package with the same files (``ids.py``, ``commands.py``,
``replies.py``, ``codec.py``) and exposes a :class:`Family` as ``FAMILY``. The registry below maps
names to ``"module:attribute"`` strings and imports a family only when it is asked for, so using
one family never pays for the others.

Third-party families register under the ``servobus.families`` entry-point group; one that fails to
load is skipped with a warning rather than breaking the built-in ones.

The contracts a family's parts implement live here too, where both sides import them, so a family
never imports what uses it: :mod:`servobus.protocols.cli` (its ``cli`` part, for the command line),
:mod:`servobus.protocols.dbc` with :mod:`servobus.protocols.dbc_layouts` (its ``dbc`` part, for the
DBC exporter in ``servobus.tools``) and :class:`servobus.protocols._calls.TypedCalls` (the base of its
generated typed calls, which the Bus composes with its Motor).

Layer: the protocols layer imports only the base (errors, Frame, the C core; TypedCalls names the
Bus's Motor for a type checker only, under ``TYPE_CHECKING``); a family's package
(its codec and its parts, its simulator aside) imports only the base and this layer.
"""

from __future__ import annotations

from servobus import _plugins
from servobus.protocols._bound import BoundCodec, Broadcast, FrameKind, Framing, check_bus
from servobus.protocols._family import Family, SerialLine
from servobus.protocols._message import Command, Message, Reply

__all__ = [
    "DEFAULT_FAMILY",
    "FAMILIES",
    "BoundCodec",
    "Broadcast",
    "Command",
    "Family",
    "FrameKind",
    "Framing",
    "Message",
    "Reply",
    "SerialLine",
    "available_families",
    "check_bus",
    "get_family",
]

FAMILIES: dict[str, str] = {
    "myactuator": "servobus.protocols.myactuator:FAMILY",
    "lk": "servobus.protocols.lk:FAMILY",
    "hollow": "servobus.protocols.hollow:FAMILY",
}

ENTRY_POINT_GROUP = "servobus.families"

#: The family a command line uses when none is named (the registry's first).
DEFAULT_FAMILY = next(iter(FAMILIES))


def available_families() -> dict[str, str]:
    """Built-in families plus those registered by installed plug-ins (built-ins win on a clash)."""
    return _plugins.available(ENTRY_POINT_GROUP, FAMILIES)


def get_family(name: str) -> Family:
    """Import and return the family registered as ``name``.

    Raises:
        ValueError: no family has that name, or a plug-in's target is not a Family.
    """
    family = _plugins.load(ENTRY_POINT_GROUP, FAMILIES, name, "protocol family")
    if not isinstance(family, Family):
        raise ValueError(f"{available_families()[name]} is {type(family).__name__}, not a servobus Family")
    return family

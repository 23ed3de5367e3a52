"""Protocol families: sans-IO codecs between typed commands/replies and payload bytes.

Every family lives in its own package with the same files (``ids.py``, ``commands.py``,
``replies.py``, ``codec.py``) and exposes a :class:`Family` as ``FAMILY``. The registry below maps
names to ``"module:attribute"`` strings and imports a family only when it is asked for, so using
one family never pays for the others.

Third-party families register under the ``servobus.families`` entry-point group; one that fails to
load is skipped with a warning rather than breaking the built-in ones.
"""

from __future__ import annotations

import importlib
import warnings
from importlib.metadata import entry_points

from servobus.protocols._family import Family
from servobus.protocols._message import Command, Message, Reply

__all__ = ["FAMILIES", "Command", "Family", "Message", "Reply", "available_families", "get_family"]

FAMILIES: dict[str, str] = {
    "myactuator": "servobus.protocols.myactuator:FAMILY",
    "lk": "servobus.protocols.lk:FAMILY",
    "hollow": "servobus.protocols.hollow:FAMILY",
}

ENTRY_POINT_GROUP = "servobus.families"


def available_families() -> dict[str, str]:
    """Built-in families plus those registered by installed plug-ins (built-ins win on a clash)."""
    found = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    return {**found, **FAMILIES}


def get_family(name: str) -> Family:
    """Import and return the family registered as ``name``.

    Raises:
        ValueError: no family has that name, or a plug-in's target is not a Family.
    """
    families = available_families()
    try:
        target = families[name]
    except KeyError:
        raise ValueError(f"unknown protocol family {name!r} (known: {', '.join(sorted(families))})") from None
    module_name, _, attribute = target.partition(":")
    try:
        family = getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as exc:
        if name in FAMILIES:
            raise
        warnings.warn(f"protocol family plug-in {name!r} ({target}) failed to load: {exc}", stacklevel=2)
        raise ValueError(f"protocol family {name!r} failed to load") from exc
    if not isinstance(family, Family):
        raise ValueError(f"{target} is {type(family).__name__}, not a servobus Family")
    return family

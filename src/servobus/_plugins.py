"""Named plug-ins: built-ins as ``"module:attribute"`` strings, more from an entry-point group.

Shared by the protocol families (``servobus.families``) and the transports
(``servobus.transports``). Nothing is imported until it is asked for, so using one plug-in never
pays for the others; a third-party plug-in that fails to load warns instead of breaking the rest.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Mapping
from importlib.metadata import entry_points
from types import ModuleType

__all__ = ["available", "load"]

#: (group, name) -> (its module, the loaded object): a Bus asks for a motor's family per motor and
#: per broadcast, and finding a plug-in scans every installed distribution's metadata (milliseconds).
#: Kept while its module is the one imported (a module removed from sys.modules is looked up again).
_LOADED: dict[tuple[str, str], tuple[ModuleType, str]] = {}


def available(group: str, builtins: Mapping[str, str]) -> dict[str, str]:
    """Built-ins plus those registered under ``group`` by installed packages (built-ins win)."""
    found = {ep.name: ep.value for ep in entry_points(group=group)}
    return {**found, **builtins}


def load(group: str, builtins: Mapping[str, str], name: str, what: str) -> object:
    """Import and return the object registered as ``name``.

    Raises:
        ValueError: nothing has that name, or a third-party plug-in failed to import (with a
            warning naming it); a failing built-in raises its own ImportError.
    """
    loaded = _LOADED.get((group, name))
    if loaded is not None and sys.modules.get(loaded[0].__name__) is loaded[0]:
        return getattr(loaded[0], loaded[1])  # read again: a rebound attribute is never stale
    # Built-ins win, so their names need no scan of the installed packages' metadata.
    known = builtins if name in builtins else available(group, builtins)
    try:
        target = known[name]
    except KeyError:
        raise ValueError(f"unknown {what} {name!r} (known: {', '.join(sorted(known))})") from None
    module_name, _, attribute = target.partition(":")
    try:
        module = importlib.import_module(module_name)
        target_object = getattr(module, attribute)
    except (ImportError, AttributeError) as exc:
        if name in builtins:
            raise
        warnings.warn(f"{what} plug-in {name!r} ({target}) failed to load: {exc}", stacklevel=3)
        raise ValueError(f"{what} {name!r} failed to load") from exc
    _LOADED[(group, name)] = (module, attribute)
    return target_object

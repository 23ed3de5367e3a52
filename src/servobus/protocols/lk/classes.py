"""LK's command classes, in their modules' order, and the request class of each command byte per
revision: the tables the codec and the identifiers (``ids.request_keys``) both read, kept here,
below both, so neither imports the other.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from servobus.protocols._family import command_classes
from servobus.protocols.lk import commands as cmd
from servobus.protocols.lk import commands_control as ctl
from servobus.protocols.lk import params_v235 as p235
from servobus.protocols.lk import params_v236 as p236
from servobus.protocols.lk._base import LkCommand
from servobus.protocols.lk.model import Revision

__all__ = ["COMMAND_CLASSES", "REQUESTS"]

# Every command class of the family's modules, in their order (the classes state everything else).
COMMAND_CLASSES: tuple[type[LkCommand], ...] = tuple(
    cls
    for cls in command_classes(value for module in (cmd, ctl, p236, p235) for value in vars(module).values())
    if issubclass(cls, LkCommand)
)


def _request_table(revision: Revision) -> dict[int, type[LkCommand]]:
    table: dict[int, type[LkCommand]] = {}
    for cls in COMMAND_CLASSES:
        if revision in cls.REVISIONS and cls.CODE is not None:
            if cls.CODE in table:  # pragma: no cover - a table error, caught at import
                raise AssertionError(f"0x{cls.CODE:02X}: {table[cls.CODE].__name__} and {cls.__name__}")
            table[cls.CODE] = cls
    return table


REQUESTS: Mapping[Revision, Mapping[int, type[LkCommand]]] = MappingProxyType(
    {revision: MappingProxyType(_request_table(revision)) for revision in Revision}
)

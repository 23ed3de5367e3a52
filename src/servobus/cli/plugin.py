"""The command line's side of the CLI contract: the names a family's ``cli`` part is made of.

The contract itself (:class:`CliFamily`, :class:`Op`, :class:`Setting`, :class:`Query`, the
builders and parsers) lives in :mod:`servobus.protocols.cli`, in the protocols layer, so a family
implements it without importing the command line; the CLI's modules (``_families``, ``config``,
``scan``, ``_motors``, ...) use it through this module, which re-exports it unchanged (the path the
docs showed, ``servobus.cli.plugin.CliFamily``, stays).
"""

from __future__ import annotations

from servobus.protocols.cli import (
    DEFAULT_OPS,
    OPERATIONS,
    STATUS_SOURCES,
    Build,
    CliFamily,
    Make,
    Op,
    Query,
    Setting,
    Values,
    build,
    derived_status,
    fault_names,
    move,
    once,
    parse_bool,
    parse_float,
    parse_float_or_none,
    parse_int,
    parse_int_or_none,
    safe,
    setpoint,
    setting_of,
    sharing_rounds,
)

__all__ = [
    "DEFAULT_OPS",
    "OPERATIONS",
    "STATUS_SOURCES",
    "Build",
    "CliFamily",
    "Make",
    "Op",
    "Query",
    "Setting",
    "Values",
    "build",
    "derived_status",
    "fault_names",
    "move",
    "once",
    "parse_bool",
    "parse_float",
    "parse_float_or_none",
    "parse_int",
    "parse_int_or_none",
    "safe",
    "setpoint",
    "setting_of",
    "sharing_rounds",
]

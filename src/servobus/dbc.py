"""Deprecated: the DBC exporter moved (issue 38). Import the contract a family implements from
:mod:`servobus.protocols.dbc` (``DbcFamily``, ``DbcOption``, ``DbcQuery``, ``Described`` and the
layouts it builds with) and the exporter from :mod:`servobus.tools.dbc` (``plan``, ``database``,
``dbc_text``, ``build_database``). This module re-exports the old names and warns at import.
"""

from __future__ import annotations

import warnings

from servobus.protocols.dbc import (
    CONFIG_FIELDS,
    DIRECTIONS,
    MUX,
    DbcFamily,
    DbcOption,
    DbcQuery,
    Described,
    EnumByte,
    FlagsByte,
    Keyed,
    Layout,
    MessageSpec,
    Mux,
    ResultByte,
    SignalSpec,
    dbc_name,
    dbc_part,
    derived,
    enum_choices,
    fields_layout,
    keyed_layouts,
    le_signal,
    muxed,
    packed_signals,
    reply_keys,
    request_keys,
    signal_spec,
)
from servobus.protocols.dbc_layouts import UNITS, ByteOrder, message_fields
from servobus.tools.dbc import (
    Placed,
    Plan,
    build_database,
    database,
    dbc_text,
    option_owners,
    plan,
    signal_table,
)

__all__ = [
    "CONFIG_FIELDS",
    "DIRECTIONS",
    "MUX",
    "UNITS",
    "ByteOrder",
    "DbcFamily",
    "DbcOption",
    "DbcQuery",
    "Described",
    "EnumByte",
    "FlagsByte",
    "Keyed",
    "Layout",
    "MessageSpec",
    "Mux",
    "Placed",
    "Plan",
    "ResultByte",
    "SignalSpec",
    "build_database",
    "database",
    "dbc_name",
    "dbc_part",
    "dbc_text",
    "derived",
    "enum_choices",
    "fields_layout",
    "keyed_layouts",
    "le_signal",
    "message_fields",
    "muxed",
    "option_owners",
    "packed_signals",
    "plan",
    "reply_keys",
    "request_keys",
    "signal_spec",
    "signal_table",
]

warnings.warn(
    "servobus.dbc is deprecated: import the DBC contract from servobus.protocols.dbc and the exporter "
    "from servobus.tools.dbc",
    DeprecationWarning,
    stacklevel=2,
)

"""The DBC exporter: a family's CAN frames as a DBC (cantools: ``servobus[dbc]``).

A DBC signal is a bit range with a byte order, a sign, ``value = raw * factor + offset``, a range and a
unit. The exporter never names a family: it asks the :class:`~servobus.protocols.Family` (built-in or
registered by entry point) and derives every signal from what the codec already states.
The family's part (:mod:`servobus.protocols.dbc`, the contract) describes its messages; this
module plans the DBC of some motors (:func:`plan`), names and places its signals
(:func:`signal_table`) and builds the cantools database (:func:`database`, :func:`dbc_text`).

Messages are multiplexed on DATA[0] (the signal ``code``) where the family keys its frames by it;
parameter frames whose value layout depends on a parameter byte are multiplexed again on that byte
(extended multiplexing, ``SG_MUL_VAL_``). A multiplexer value's name is unique (``Status2Reply_A0``):
cantools reads a decoded name back by the name.

**Signal names are servobus' field names** (what ``decode`` and ``servobus.tools.logs`` call them), with two
rules the DBC format forces, and :func:`signal_table` applies:

* a DBC name is an identifier: an item of a tuple value or a field of a field is spelled with ``_``
  (:func:`dbc_name`: ``currents_a[0]`` -> ``currents_a_0``, ``value.kp`` -> ``value_kp``,
  ``command.speed_dps`` -> ``command_speed_dps``); a field split in bit runs is one signal per run
  (``position_deg_b0``, ``position_deg_b16``, see above).
* a DBC name is unique in its message, and one signal has one multiplexer, bit range, conversion,
  choices, range and comment. A field described alike under several values of one multiplexer is one
  signal, shared by them (``angle_deg`` of the 0x9C status reply and of the control replies). Where
  layouts under one identifier describe a field differently (an int16 1° ``angle_deg`` in those
  replies, an int32 0.01° one in 0x92's; 0xA9's ``max_torque_pct``, whose raw 0 is not 0xA2's "no
  limit") or under different multiplexers (LK's ``value`` of 0xC1's parameters and of 0x42's
  settings), only one signal can have the name: the one with the fewest multiplexer levels above it,
  then the one the most multiplexer values carry (the first of a tie), keeps it; each other gets the
  multiplexer values of its first layout as a suffix (``angle_deg_92``, ``value_C1_1E``: 0xC1's value
  of parameter 0x1E). Neither extended multiplexing nor a message per multiplexer value avoids it: a
  DBC has one message per identifier, and a signal's multiplexer values select its children under
  every value of the multiplexer above it (cantools builds one subtree per value of the multiplexer
  itself), so a byte that is a multiplexer in one layout (0xC1's ``param``) and a plain value in
  another (0xC0's) must be two signals.

The multiplexer on DATA[0], ``code``, is not a field: its value names the layout (the message class).
A servobus field a multiplexer value stands for (the ``command`` byte of a reply layout several
DATA[0] values share, a parameter's name) has no signal of its own: the multiplexer value selecting the
layout gives it (the layout's ``implies``).

What a DBC cannot say is left out, and :func:`plan` names it with the reason (text fields, layouts
decoded by rules of their own, two layouts under one identifier and DATA[0], what the family's part
adds).

Layer: tools; imports the protocols' contract and the C core, cantools only when a database is built.
"""

from __future__ import annotations

import dataclasses
import enum
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from servobus.protocols import Family, available_families, get_family
from servobus.protocols.dbc import DIRECTIONS, DbcQuery, dbc_part
from servobus.protocols.dbc_layouts import Layout, MessageSpec, Mux, SignalSpec

__all__ = [
    "Placed",
    "Plan",
    "build_database",
    "database",
    "dbc_text",
    "option_owners",
    "owners_of",
    "plan",
    "signal_table",
]


@dataclass(frozen=True, slots=True)
class Plan:
    """Everything a DBC of one family holds, and what it leaves out (each with the reason)."""

    family: str
    revision: enum.Enum
    messages: tuple[MessageSpec, ...]
    left_out: tuple[str, ...]
    nodes: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Placed:
    """A signal of a built message: its spec, the multiplexer it hangs on and the values selecting it;
    for a multiplexer, the layouts its values select."""

    name: str
    spec: SignalSpec
    mux_signal: str | None
    mux_ids: tuple[int, ...]
    layouts: tuple[Layout, ...] | None = None


# ---- plans and databases ------------------------------------------------------------------------


def option_owners(option: str) -> list[str]:
    """The families (built-in and plug-in) whose DBC takes ``option``; a family whose part does not
    load is skipped (an error message is being built)."""
    owners = []
    for name in available_families():
        try:
            part = dbc_part(get_family(name))
        except (ImportError, LookupError, TypeError, ValueError):
            continue
        if part.option(option) is not None:
            owners.append(name)
    return owners


def owners_of(option: str) -> str:
    """:func:`option_owners` as words: ``"dm, lk and hollow"`` ("" for none)."""
    owners = option_owners(option)
    return " and ".join([", ".join(owners[:-1]), owners[-1]] if len(owners) > 1 else owners)


def plan(
    family: str | Family,
    ids: Iterable[int],
    revision: str | enum.Enum | None = None,
    *,
    direction: str | None = None,
    **options: Any,
) -> Plan:
    """What the DBC of ``family``'s motors ``ids`` holds, and what it leaves out.

    Args:
        family: a registered family's name (``myactuator``, ``lk``, ``hollow``, a plug-in's), or the
            Family.
        ids: the motors' ids.
        revision: the protocol revision (default: the family's choice).
        direction: ``request`` or ``reply`` for only those messages (default both).
        options: the family's DBC options (its ``DbcFamily.options``); None is "not given". The
            built-in ones: ``model`` (LK: an ``LkModel`` or a motor type MS, MF, MH, MG; hollow: a
            ``HollowModel`` or a name of ``hollow.MODELS``), ``encoder_bits`` (LK), ``can_mode`` and
            ``host_id`` (hollow), ``max_torque_nm`` (MyActuator V4.4's motion torque range).

    Raises:
        ValueError: an unknown family, revision, direction or option, an option of another family, a
            bad option value, or a motor id the family does not accept.
    """
    if isinstance(family, str):
        known = available_families()
        if family not in known:
            raise ValueError(f"no family {family!r} (known: {', '.join(known)})")
        family = get_family(family)
    if direction is not None and direction not in DIRECTIONS:
        raise ValueError(f"direction={direction!r} is not one of {', '.join(DIRECTIONS)}")
    part = dbc_part(family)
    given = {name: value for name, value in options.items() if value is not None}
    for name in given:
        if part.option(name) is None:
            owners = owners_of(name) or "no family"
            raise ValueError(f"{name} is an option of {owners}, not of {family.name}")
    query = DbcQuery(
        family=family,
        ids=tuple(dict.fromkeys(ids)),
        revision=family.revision(revision) if revision is not None else None,
        options=given,
        direction=direction,
    )
    described = part.describe(query)
    messages = [m for m in described.messages if direction is None or m.kind == direction]
    nodes = ("host", *(f"motor_{i}" for i in query.ids))
    return Plan(family.name, described.revision, tuple(messages), tuple(described.left_out), nodes)


def signal_table(message: MessageSpec) -> dict[str, Placed]:
    """Every DBC signal of ``message`` by name.

    A signal with one shape (spec) under one multiplexer is one DBC signal, shared by the multiplexer
    values that carry it; a multiplexer is shared by the values whose nested layouts are the same. A
    name is the field's (``speed_dps``, ``currents_a_0``: :func:`dbc_name`). Where several signals have
    one field name (described differently, or under different multiplexers), the one with the fewest
    multiplexer levels above it, then the most multiplexer values, keeps the name (``angle_deg``: int16
    1° in the status replies); each other gets the multiplexer values of its first layout as a suffix
    (``angle_deg_92``: int32 0.01° under 0x92; ``value_C1_1E``: 0xC1's value of parameter 0x1E).
    """
    groups: list[_Group] = []
    by_spec: dict[tuple[int | None, SignalSpec], int] = {}
    muxes: dict[int | None, list[int]] = {}

    def visit(layout: Layout, parent: int | None, path: tuple[int, ...]) -> None:
        for spec in layout.signals:
            k = by_spec.get((parent, spec))
            if k is None:
                k = by_spec[(parent, spec)] = len(groups)
                groups.append(_Group(spec, path, parent))
            if layout.code is not None:
                groups[k].ids.append(layout.code)
        mux = layout.mux
        if mux is None:
            return
        siblings = muxes.setdefault(parent, [])
        k = next((i for i in siblings if groups[i].mux is mux or groups[i].mux == mux), None)
        new = k is None
        if k is None:
            k = len(groups)
            groups.append(_Group(mux.signal, path, parent, mux))
            siblings.append(k)
        if layout.code is not None:
            groups[k].ids.append(layout.code)
        if new:
            for sub in mux.layouts:
                assert sub.code is not None
                visit(sub, k, (*path, sub.code))

    visit(message.root, None, ())
    # The field's own name goes to one signal per name (see _rank; the first of a tie); any other shape
    # of that field is suffixed.
    owner: dict[str, int] = {}
    for k, group in enumerate(groups):
        base = group.spec.base_name
        best = owner.get(base)
        if best is None or _rank(group) > _rank(groups[best]):
            owner[base] = k
    names: list[str] = [""] * len(groups)
    taken = set(owner)
    for base, k in owner.items():
        names[k] = base
    for k, group in enumerate(groups):
        if names[k]:
            continue
        name = group.spec.base_name + "".join(f"_{c:02X}" for c in group.path)
        unique, n = name, 2
        while unique in taken:
            unique, n = f"{name}_{n}", n + 1
        names[k] = unique
        taken.add(unique)
    return {
        name: Placed(
            name,
            group.spec,
            None if group.parent is None else names[group.parent],
            tuple(group.ids),
            None if group.mux is None else group.mux.layouts,
        )
        for name, group in zip(names, groups, strict=True)
    }


def _rank(group: _Group) -> tuple[int, int]:
    """Which of the signals sharing a field name keeps it: the fewest multiplexer levels above it (a
    root signal first), then the most multiplexer values selecting it."""
    return (-len(group.path), len(group.ids))


@dataclass(slots=True)
class _Group:
    """One DBC signal while :func:`signal_table` collects them: its spec, the multiplexer values of its
    first layout, the group it hangs on, the values selecting it (and the multiplexer it is)."""

    spec: SignalSpec
    path: tuple[int, ...]
    parent: int | None
    mux: Mux | None = None
    ids: list[int] = dataclasses.field(default_factory=list)


def database(p: Plan) -> Any:
    """The cantools Database of a :class:`Plan`.

    Raises:
        ImportError: cantools is not installed (``pip install 'servobus[dbc]'``).
    """
    from cantools.database.can import Database, Message, Node

    messages = [
        Message(
            m.frame_id,
            m.name,
            m.length,
            [_signal(placed) for placed in signal_table(m).values()],
            comment=m.comment or None,
            senders=list(m.senders),
            is_extended_frame=m.extended,
            is_fd=m.fd,
        )
        for m in p.messages
    ]
    specifics = _fd_specifics() if any(m.fd for m in p.messages) else None
    return Database(messages=messages, nodes=[Node(n) for n in p.nodes], dbc_specifics=specifics)


def _fd_specifics() -> Any:
    """DBC attributes that make cantools write (and read back) CAN FD messages: BusType "CAN FD"."""
    from cantools.database.can.formats.dbc import DbcSpecifics
    from cantools.database.can.formats.dbc.dbc_attribute import DbcAttribute
    from cantools.database.can.formats.dbc.dbc_attribute_definition import DbcAttributeDefinition

    bus_type = DbcAttributeDefinition("BusType", default_value="", type_name="STRING")
    return DbcSpecifics(
        attributes=OrderedDict(BusType=DbcAttribute("CAN FD", bus_type)),
        attribute_definitions=OrderedDict(BusType=bus_type),
    )


def _signal(placed: Placed) -> Any:
    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion
    from cantools.database.namedsignalvalue import NamedSignalValue

    spec = placed.spec
    choices: OrderedDict[int, str | NamedSignalValue] | None = None
    if placed.layouts is not None:
        choices = OrderedDict(
            (layout.code, layout.name) for layout in placed.layouts if layout.code is not None
        )
    elif spec.choices:
        choices = OrderedDict(spec.choices)
    conversion = BaseConversion.factory(
        scale=spec.scale, offset=spec.offset, choices=choices, is_float=spec.is_float
    )
    return Signal(
        placed.name,
        spec.start,
        spec.length,
        byte_order=spec.byte_order,
        is_signed=spec.signed,
        conversion=conversion,
        minimum=spec.minimum,
        maximum=spec.maximum,
        unit=spec.unit or None,
        comment=spec.comment or None,
        is_multiplexer=placed.layouts is not None,
        multiplexer_ids=list(placed.mux_ids) if placed.mux_signal is not None else None,
        multiplexer_signal=placed.mux_signal,
    )


def build_database(
    family: str, ids: Iterable[int], revision: str | enum.Enum | None = None, **options: Any
) -> tuple[Any, list[str]]:
    """A cantools Database of ``family``'s frames for the motors ``ids``, and what it leaves out.

    ``options`` are :func:`plan`'s.

    Raises:
        ValueError: as :func:`plan`.
        ImportError: cantools is not installed (``pip install 'servobus[dbc]'``).
    """
    p = plan(family, ids, revision, **options)
    return database(p), list(p.left_out)


def dbc_text(db: Any) -> str:
    """The database as DBC text."""
    text: str = db.as_dbc_string()
    return text

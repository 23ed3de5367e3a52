"""The DBC contract: what a family tells the DBC exporter (its ``dbc`` part), and the blocks it builds
its answer from.

**From the family** (what declarations cannot say): which identifiers carry which frames per motor,
which byte multiplexes them, comments, bit-packed layouts, options (a motor model, a CAN mode). A family
states it in its ``dbc`` part (``Family.part("dbc")``, a :class:`DbcFamily`), whose ``describe`` builds
the messages with the helpers here. A family without a ``dbc`` part gets :func:`derived`: per motor,
the identifiers its bound codec lists (``request_ids``, ``reply_ids``), the commands of the revision
multiplexed on DATA[0] by their ``CODE``, their replies (``reply_types()``) likewise.

This module is the contract both sides import: a family's ``dbc.py`` imports only from here; the
exporter (:mod:`servobus.tools.dbc`: plans, signal names, the cantools database) asks
:func:`dbc_part` of a family and calls its ``describe``. The building blocks (signals, layouts,
multiplexers, the layouts derived from declarations) are :mod:`servobus.protocols.dbc_layouts`'s,
re-exported here so a family names one module.

Layer: protocols (the family contract); sans-IO, imports nothing above the protocols layer.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from servobus.protocols._bound import EXTENDED
from servobus.protocols._family import Family
from servobus.protocols.dbc_layouts import (
    CONFIG_FIELDS,
    DIRECTIONS,
    MUX,
    EnumByte,
    FlagsByte,
    Keyed,
    Layout,
    MessageSpec,
    Mux,
    ResultByte,
    SignalSpec,
    dbc_name,
    enum_choices,
    fields_layout,
    in_revision,
    keyed_layouts,
    le_signal,
    message_fields,
    muxed,
    reply_keys,
    request_keys,
    signal_spec,
)
from servobus.protocols.dbc_packed import bit_signals, packed_signals

__all__ = [
    "CONFIG_FIELDS",
    "DIRECTIONS",
    "MUX",
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
    "ResultByte",
    "SignalSpec",
    "bit_signals",
    "dbc_name",
    "dbc_part",
    "derived",
    "enum_choices",
    "fields_layout",
    "in_revision",
    "keyed_layouts",
    "le_signal",
    "message_fields",
    "muxed",
    "packed_signals",
    "reply_keys",
    "request_keys",
    "signal_spec",
]

_PLURAL = {"request": "requests", "reply": "replies"}

# ---- what a family tells the exporter -----------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcOption:
    """An option of a family's DBC: ``plan(family, ids, name=value)``, on the command line ``--option
    name=value`` (or a flag of its own, ``--model``).

    Attributes:
        name: the keyword (``can_mode``), an identifier.
        help: one line for the user: what it sets and its default.
        parse: the value from command-line text (``int``; default: the text itself).
    """

    name: str
    help: str
    parse: Callable[[str], Any] = str


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcQuery:
    """What a DBC is asked for, as a family's :attr:`DbcFamily.describe` gets it.

    Attributes:
        family: the family.
        ids: the motors' ids (each once, in the order given).
        revision: the revision asked for (a member of ``family.revisions``), or None: the family's
            choice (its default, or what an option implies).
        options: the family's options that were given, by name (never None values).
        direction: ``"request"`` or ``"reply"`` when only those messages are wanted (the exporter
            drops the others; a family may use it to choose what shares an identifier), or None.
    """

    family: Family
    ids: tuple[int, ...]
    revision: enum.Enum | None
    options: Mapping[str, Any]
    direction: str | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Described:
    """A family's answer: the revision described, every message (both directions), what is left out."""

    revision: enum.Enum
    messages: tuple[MessageSpec, ...]
    left_out: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcFamily:
    """A family's DBC part (``Family.parts["dbc"]``, ``protocols/<family>/dbc.py`` ``DBC``): what its
    classes' declarations do not say.

    Attributes:
        summary: what its DBC holds, in a few lines (``servobus dbc --help`` shows it).
        options: the options its ``describe`` takes (validated by name before it is called).
        describe: the messages of a :class:`DbcQuery`: identifiers per motor, layouts (from the
            declarations with :func:`fields_layout` and :func:`muxed`, bit-packed ones with
            :func:`packed_signals`), comments. Raises ValueError naming a bad id or option value.
            Default :func:`derived`.
    """

    summary: str = ""
    options: tuple[DbcOption, ...] = ()
    describe: Callable[[DbcQuery], Described] = dataclasses.field(default_factory=lambda: derived)

    def option(self, name: str) -> DbcOption | None:
        """The option called ``name``, or None."""
        return next((o for o in self.options if o.name == name), None)


def dbc_part(family: Family) -> DbcFamily:
    """The family's DBC part, or the default (:func:`derived`, no options) if it has none.

    Raises:
        TypeError: the family's ``dbc`` part is not a :class:`DbcFamily`.
    """
    if "dbc" not in family.parts:
        return DbcFamily()
    part = family.part("dbc")
    if not isinstance(part, DbcFamily):
        raise TypeError(f"the {family.name} family's dbc part is {type(part).__name__}, not a DbcFamily")
    return part


def derived(query: DbcQuery) -> Described:
    """The DBC of a family from its declarations alone (a family without a ``dbc`` part).

    Per motor, the bound codec's identifiers (``Family.bind(motor_id, revision=...)``): a request
    message on each of its ``request_ids``, the family's commands of the revision (``REVISIONS``, if
    declared) multiplexed on DATA[0] by ``CODE``; a reply message on each of its ``reply_ids``, the
    commands' ``reply_types()`` likewise. A direction of one class whose ``CODE`` is None is that
    class's layout, unmultiplexed. An identifier several motors share (one reply id for all) is one
    message; an identifier in both lists carries the replies unless ``direction="request"``. A message
    is as long as its longest ``SIZE`` (CAN FD beyond 8 bytes); an identifier in ``EXTENDED`` is
    29-bit.

    Raises:
        ValueError: a motor id outside ``family.motor_ids``, or one its ``bind`` refuses.
    """
    family = query.family
    rev = query.revision if query.revision is not None else family.default_revision
    left_out: list[str] = []
    commands = [c for c in family.commands if in_revision(c, rev)]
    replies = list(dict.fromkeys(r for c in commands for r in c.reply_types() if in_revision(r, rev)))
    roots = {
        "request": _derived_root(commands, request_keys(commands, rev), "request", left_out),
        "reply": _derived_root(replies, reply_keys(commands, rev), "reply", left_out),
    }
    sizes = {
        "request": max((getattr(c, "SIZE", 8) for c in commands), default=8),
        "reply": max((getattr(r, "SIZE", 8) for r in replies), default=8),
    }
    carried: dict[tuple[str, int], list[int]] = {}
    shared_any = False
    for motor_id in query.ids:
        if motor_id not in family.motor_ids:
            first, last = family.motor_ids[0], family.motor_ids[-1]
            raise ValueError(f"motor_id={motor_id} is outside {family.name}'s ids {first}..{last}")
        codec = family.bind(motor_id, revision=rev)
        shared = codec.request_ids & codec.reply_ids
        shared_any = shared_any or bool(shared)
        for kind, idents in (("request", codec.request_ids), ("reply", codec.reply_ids)):
            for ident in sorted(idents):
                # An identifier both ways carries the replies, unless the requests are asked for.
                if ident in shared and (kind == "request") != (query.direction == "request"):
                    continue
                carried.setdefault((kind, ident), []).append(motor_id)
    if shared_any and query.direction != "request":
        left_out.append(
            "requests on the identifiers replies come on: a DBC has one message per identifier, so those "
            "describe the replies; direction 'request' gives the requests' DBC"
        )
    names = {
        key: f"{family.name}_{key[0]}" + (f"_{m[0]}" if len(m) == 1 else "") for key, m in carried.items()
    }
    messages = []
    for (kind, ident), motors in carried.items():
        root = roots[kind]
        if root is None:
            continue
        frame_id = ident & ~EXTENDED
        name = names[(kind, ident)]
        if list(names.values()).count(name) > 1:  # a motor with several identifiers one way
            name += f"_{frame_id:X}"
        senders = ("host",) if kind == "request" else tuple(f"motor_{m}" for m in motors)
        whose = f"motor {motors[0]}" if len(motors) == 1 else "motors " + ", ".join(map(str, motors))
        multiplexed = ", multiplexed on DATA[0]" if root.mux is not None else ""
        messages.append(
            MessageSpec(
                frame_id,
                name,
                sizes[kind],
                kind,
                root,
                senders,
                f"{family.name} {rev.name} {_PLURAL[kind]} of {whose}{multiplexed}",
                extended=bool(ident & EXTENDED),
                fd=sizes[kind] > 8,
                motor_id=motors[0] if len(motors) == 1 else None,
            )
        )
    return Described(revision=rev, messages=tuple(messages), left_out=tuple(left_out))


def _derived_root(
    classes: Sequence[type], keys: list[Keyed], what: str, left_out: list[str]
) -> Layout | None:
    """One direction's layout tree: ``keys`` multiplexed on DATA[0]; a lone class without a ``CODE``,
    as it is; None (and why, in ``left_out``) when nothing is describable."""
    if len(classes) == 1 and getattr(classes[0], "CODE", None) is None:
        layout = fields_layout(classes[0], None, what, left_out)
        return None if layout is None else dataclasses.replace(layout, name="")
    keyed = {key.cls for key in keys}
    for cls in classes:
        if cls not in keyed and getattr(cls, "CODE", None) is None:
            left_out.append(f"{what} {cls.__name__}: no CODE (DATA[0]) to be told apart by")
    layouts = keyed_layouts(keys, what, left_out)
    return muxed(layouts) if layouts else None

"""The CLI contract: what a protocol family gives the command line (its ``cli`` part), and the pieces
it is built from.

This module is where both sides meet: a family's ``cli.py`` imports only from here; the command
line (``servobus.cli``, which re-exports these names in :mod:`servobus.cli.plugin`) asks a family's
part and sends what it builds. It is the protocols layer's (sans-IO, imports nothing above it).

The CLI never names a family. For ``--family NAME`` it asks ``get_family(NAME).part("cli")``, which
a family points at a :class:`CliFamily` (``Family.parts["cli"] = "mypkg.cli:CLI"``); the module is
imported only then, so the CLI loads no family it does not use. A family without a ``cli`` part (a
third-party family that does not import servobus's CLI) still gets every command that needs no
table: ``decode``, ``record``, ``status``/``monitor``/``scan`` (reads derived from its commands'
declarations, :func:`derived_status`), ``stop`` and ``off`` (its bound codec's
``safe_command("stop"|"shutdown")``); every other command is refused in one line, exit 2.

The contract, as the CLI uses it:

``CliFamily.ops``
    CLI command name -> :class:`Op`: what the command sends. The names the CLI offers are
    ``move``, ``speed``, ``torque``, ``mit``, ``stop``, ``off``, ``brake``, ``zero``, ``set-id``,
    ``clear-errors``, ``reset``. Each builder takes the motor's bound codec (``revision``,
    ``model``, ``link``) and the command line's values, keyed in the units their options carry
    (:func:`build` gives them to the command's fields of the same names):

    ========  ==================================================================================
    move      ``angle_deg``, ``max_speed_dps`` (None: no limit), ``relative`` (bool),
              ``max_current_a`` (None: the motor's full scale)
    speed     ``speed_dps``, ``max_current_a``
    torque    ``current_a``
    mit       ``position_rad``, ``velocity_rad_s``, ``kp``, ``kd``, ``torque_ff_nm``
    brake     ``lock`` (bool: lock, or release)
    set-id    ``new_id``
    others    nothing
    ========  ==================================================================================

    A builder raises ValueError for a value or a combination the family refuses (naming the field
    and its limit, or what to drop); the CLI reports it as bad usage (exit 2) before anything is
    sent. ``stop`` and ``off`` need no entry: :func:`safe` of the bound codec is the default.
``CliFamily.why_not``
    CLI command name -> why the family has no such command (said with the exit-2 refusal); a
    command named here is refused even where there is a default (``off`` without a shutdown).
``CliFamily.status``
    The reads ``status``, ``monitor`` and ``scan`` send, in order (classes or other callables that
    make a command with no arguments; the first is scan's probe). None: derived from the family's
    commands (:func:`derived_status`); empty: the family has no read-only request
    (``why_not["status"]`` says why). The columns shown come from the replies' field names
    (:data:`STATUS_SOURCES`) and their ``Reply.FAULTS`` field.
``CliFamily.settings``
    What ``servobus config`` reads and writes: :class:`Setting` s, built with :func:`setting_of`
    from the read and write command classes where they say it all.
``CliFamily.identify`` / ``CliFamily.describe``
    What ``scan`` asks a motor that answered its probe (:class:`Query`): ``identify`` on the probe's
    binding (it may name the motor's revision), then ``describe`` on a binding in that revision.
``CliFamily.scan_ids``
    The ids ``scan`` probes without ``--ids`` (None: 1-32, those of them the family's ``motor_ids``
    allow). Whatever the ids, ``scan`` probes them in rounds of motors that can share one bus
    (:func:`sharing_rounds`: the bound codecs' request and reply ids, as
    :func:`~servobus.protocols.check_bus` checks them): a family whose reply id of motor N is
    another motor's request id (Damiao: feedback N + 0x10) needs no rule of its own.
``CliFamily.supports`` / ``CliFamily.operations``
    What a command, or the demo, may ask a family's part: whether it offers a CLI command, and
    which it offers (the ``demo`` moves motors with ``move``, else ``mit``).

Everything here is sans-IO: a family's part builds commands and reads replies; the CLI sends them.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Union

from servobus.protocols._bound import BoundCodec, check_bus
from servobus.protocols._family import Family
from servobus.protocols._message import Command, Reply

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

Values = Mapping[str, Any]
"""The command line's values, keyed by name with the unit (``speed_dps``); see the module's table."""
Build = Callable[[BoundCodec, Values], Sequence[Command]]
"""(the motor's bound codec, the values) -> the commands, in order."""
Make = Callable[[BoundCodec, Values], Command]
"""(the motor's bound codec, the values) -> one command."""


@dataclass(frozen=True, slots=True)
class Op:
    """What one CLI command sends to one motor.

    Attributes:
        first: the commands sent once, in order (the reply to the last one is shown).
        repeat: for set-points, the commands sent again at the command's rate, in order (None:
            one-shot); their replies together are the motor's status. Only commands that may be
            repeated: an absolute set-point, a read; never an increment.
        rom: it writes the motor's ROM or changes its id: ask first (``--yes`` skips).
        note: said after it succeeded (what else the user must do).
        current_limit: its set-point carries a current limit (``--max-current-a``; without it, the
            motor's full scale); a command without one refuses the option.
        speed_limit: a ``move`` whose set-point carries its speed limit (``max_speed_dps``; None:
            the family's own "no limit"); a move without one (an MIT law: its gains set the pace)
            refuses ``--max-speed-dps``, and the demo gives it none.
    """

    first: Build
    repeat: Build | None = None
    rom: bool = False
    note: str = ""
    current_limit: bool = False
    speed_limit: bool = False


def build(cls: type[Command], **renamed: str) -> Make:
    """A builder of ``cls`` from the command line's values: each field takes the value of the same
    name (units in both names: ``build(SpeedControl)`` takes ``speed_dps``), or of the name
    ``renamed`` gives it (``build(IncrementalPositionSpeed, increment_deg="angle_deg")``); a field the
    command line has no value for keeps its default.

    Raises:
        TypeError: ``renamed`` names a field ``cls`` does not have.
    """
    fields = [(f.name, renamed.get(f.name, f.name)) for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    unknown = set(renamed) - {name for name, _ in fields}
    if unknown:
        raise TypeError(f"{cls.__name__} has no field {', '.join(sorted(unknown))}")

    def make(codec: BoundCodec, v: Values) -> Command:
        return cls(**{name: v[key] for name, key in fields if key in v})

    return make


def once(make: Make, **options: Any) -> Op:
    """A one-shot sending one command (``options``: :class:`Op`'s ``rom``, ``note``)."""
    return Op(first=lambda codec, v: (make(codec, v),), **options)


def setpoint(make: Make, *, current_limit: bool = False) -> Op:
    """A set-point resent as it is at the command's rate (an absolute target, a speed, a current)."""
    return Op(
        first=lambda codec, v: (make(codec, v),),
        repeat=lambda codec, v: (make(codec, v),),
        current_limit=current_limit,
    )


def safe(kind: str) -> Op:
    """The bound codec's safe command ``kind`` (``"stop"``, ``"shutdown"``): the family contract's,
    so every family has ``stop`` and ``off`` without a table."""
    return once(lambda codec, v: codec.safe_command(kind))


def move(
    absolute: Make,
    relative: Make,
    *,
    angle: Callable[[], Command],
    reads: Sequence[Callable[[], Command]] = (),
    angle_in_reply: bool = True,
) -> Op:
    """``move``: an absolute move resends its target; a relative one reads the angle, sends the
    increment once, then only reads (the reply to ``first[0]`` is the angle it started from).

    Args:
        angle: the read of the multi-turn angle (degrees: the position set-points' scale).
        reads: what a relative move reads besides the angle while it runs (speed, current).
        angle_in_reply: the absolute set-point's reply carries the angle; False: the angle read is
            resent with it.
    """

    def first(codec: BoundCodec, v: Values) -> Sequence[Command]:
        if v["relative"]:
            return (angle(), relative(codec, v))
        return (absolute(codec, v),)

    def repeat(codec: BoundCodec, v: Values) -> Sequence[Command]:
        if v["relative"]:
            return (angle(), *(read() for read in reads))
        return (absolute(codec, v), *(() if angle_in_reply else (angle(),)))

    return Op(first=first, repeat=repeat, speed_limit=True)


# ---- scan ----


@dataclass(frozen=True, slots=True)
class Query:
    """What ``scan`` asks a motor that answered its probe, and what the replies say.

    Attributes:
        reads: (the motor's bound codec) -> the reads to send, in order.
        columns: (the bound codec, the replies in the same order) -> scan's columns: any of
            ``revision`` (a revision name of the family), ``model``, ``firmware``, ``state``.
    """

    reads: Callable[[BoundCodec], Sequence[Command]]
    columns: Callable[[BoundCodec, Sequence[Reply | None]], Mapping[str, Any]]


def sharing_rounds(codecs: Sequence[BoundCodec]) -> list[list[BoundCodec]]:
    """``codecs`` in rounds of motors that can share one bus: each motor, in order, joins the first
    round it can share a bus with (:func:`~servobus.protocols.check_bus`), or starts a new one.

    What ``scan`` probes at once: a family whose motors' ids never collide gets one round; Damiao's
    (command id N, feedback id N + 0x10: motor 1's feedback is motor 17's command id) gets two for
    ids 1-32, 1-16 then 17-32.
    """
    rounds: list[list[BoundCodec]] = []
    for codec in codecs:
        for members in rounds:
            if _shares(members, codec):
                members.append(codec)
                break
        else:
            rounds.append([codec])
    return rounds


def _shares(members: Sequence[BoundCodec], codec: BoundCodec) -> bool:
    """Whether ``codec`` can join ``members`` on a bus (check_bus is pairwise: the new pairs only)."""
    try:
        for member in members:
            check_bus([member, codec])
    except ValueError:
        return False
    return True


# ---- config ----


@dataclass(frozen=True, slots=True)
class Setting:
    """One setting of one family, for ``servobus config``.

    Attributes:
        key: its name on the command line (units in it where it has one).
        help: what it is, in a line.
        parse: the command line's text -> the value the write takes (ValueError for bad text).
        read: the command that reads it (None: the motor cannot report it).
        field: the reply's field that holds the value read.
        write: (value, to_rom) -> the command that writes it (None: read-only).
        rom: True: every write reaches ROM; False: RAM only; None: RAM, or ROM with ``--rom``.
    """

    key: str
    help: str
    parse: Callable[[str], Any]
    read: Callable[[], Command] | None = None
    field: str = "value"
    write: Callable[[Any, bool], Command] | None = None
    rom: bool | None = False

    def value_of(self, reply: Reply | None) -> Any:
        """The value in the reply to :attr:`read`."""
        return getattr(reply, self.field, None)


def parse_float(text: str) -> float:
    """``text`` as a float (ValueError otherwise): a setting's parser."""
    return float(text)


def parse_float_or_none(text: str) -> float | None:
    """A number, or ``none``/``off``."""
    return None if text.lower() in ("none", "off") else float(text)


def parse_int(text: str) -> int:
    """A whole number: decimal, ``0x``/``0o``/``0b``, or a float that is one (``1e3``, ``200.0``: the
    range check then names the limits, where int() would say "invalid literal")."""
    try:
        return int(text, 0)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        raise ValueError("not a number") from None
    if not number.is_integer():
        raise ValueError("not a whole number")
    return int(number)


def parse_int_or_none(text: str) -> int | None:
    """A whole number, or ``none``/``off``."""
    return None if text.lower() in ("none", "off") else parse_int(text)


def parse_bool(text: str) -> bool:
    """``on``/``off`` (and 1/0, true/false, yes/no)."""
    lowered = text.lower()
    if lowered in ("on", "1", "true", "yes"):
        return True
    if lowered in ("off", "0", "false", "no"):
        return False
    raise ValueError(f"{text!r} is not on or off")


#: a write field's type -> the parser of its text
_PARSERS: dict[Any, Callable[[str], Any]] = {
    float: parse_float,
    int: parse_int,
    bool: parse_bool,
    float | None: parse_float_or_none,
    int | None: parse_int_or_none,
}


def _value_field(cls: type[Command], key: Mapping[str, Any]) -> tuple[str, Any]:
    """The one field of write command ``cls`` that the user gives, besides the ``key`` fields (a
    field with a default, like a shared class's code byte, is not one), and its type."""
    hints = typing.get_type_hints(cls)
    given = [
        f
        for f in dataclasses.fields(cls)  # type: ignore[arg-type]
        if f.init
        and f.name not in key
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if len(given) != 1:
        names = ", ".join(f.name for f in given) or "none"
        raise TypeError(
            f"{cls.__name__}: a setting's write takes one value field besides {set(key)} ({names})"
        )
    return given[0].name, hints[given[0].name]


def setting_of(
    key: str,
    help: str,
    *,
    write: type[Command],
    read: type[Command] | None = None,
    rom_write: type[Command] | None = None,
    keys: Mapping[str, Any] | None = None,
    parse: Callable[[str], Any] | None = None,
    rom: bool = False,
) -> Setting:
    """A setting said by its commands: ``read(**keys)`` reads it, ``write(**keys, <value>=...)``
    writes it; the write's one other field names the value, which is the read's reply's field of
    the same name, and its type gives the parser (``float``, ``int``, ``bool``, optional ones take
    ``none``/``off``) unless ``parse`` is given.

    Args:
        rom_write: the command that writes it to ROM where ``write`` writes RAM (``--rom`` picks it).
        rom: ``write`` reaches ROM (asks first); ignored with ``rom_write``.

    Raises:
        TypeError: the write command has not exactly one value field, or no parser for its type.
    """
    fixed = dict(keys or {})
    name, kind = _value_field(write, fixed)
    if parse is None:
        parse = _PARSERS.get(_optional(kind))
        if parse is None:
            raise TypeError(f"{write.__name__}.{name}: no parser for {kind!r}: give parse=")

    def write_value(value: Any, to_rom: bool) -> Command:
        cls = rom_write if to_rom and rom_write is not None else write
        return cls(**fixed, **{name: value})

    return Setting(
        key=key,
        help=help,
        parse=parse,
        read=None if read is None else functools.partial(read, **fixed),
        field=name,
        write=write_value,
        rom=None if rom_write is not None else rom,
    )


def _optional(kind: Any) -> Any:
    """``X | None`` in one spelling (typing.Optional and the ``|`` union compare unequal)."""
    if typing.get_origin(kind) in (Union, types.UnionType):
        args = typing.get_args(kind)
        if len(args) == 2 and type(None) in args:
            (inner,) = (a for a in args if a is not type(None))
            return inner | None
    return kind


# ---- status ----

_DEG_PER_RAD = 180.0 / math.pi
STATUS_SOURCES: dict[str, tuple[tuple[str, float], ...]] = {
    "angle_deg": (("angle_deg", 1.0), ("position_deg", 1.0), ("position_rad", _DEG_PER_RAD)),
    "speed_dps": (("speed_dps", 1.0), ("speed_rad_s", _DEG_PER_RAD), ("velocity_rad_s", _DEG_PER_RAD)),
    "current_a": (("current_a", 1.0),),
    "torque_nm": (("torque_nm", 1.0),),
    "temperature_c": (("temperature_c", 1.0),),
    "voltage_v": (("voltage_v", 1.0),),
}
"""The status columns and the reply fields they are read from, ``(field, factor)`` in order of
preference: a family's replies show in ``status``/``monitor``/``move`` by naming their fields so."""
_STATUS_FIELDS = frozenset(name for sources in STATUS_SOURCES.values() for name, _ in sources)


def derived_status(family: Family) -> tuple[type[Command], ...]:
    """The status reads of a family that names none: its commands declared ``READ`` that take no
    arguments and whose reply (``REPLY``) carries a status field (:data:`STATUS_SOURCES`) or the
    motor's fault flags, in the family's order."""
    return tuple(cls for cls in family.commands if cls.READ and _no_arguments(cls) and _shows_status(cls))


def _no_arguments(cls: type[Command]) -> bool:
    return dataclasses.is_dataclass(cls) and all(
        not f.init or f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
        for f in dataclasses.fields(cls)
    )


def _shows_status(cls: type[Command]) -> bool:
    for reply in cls.reply_types():
        if not dataclasses.is_dataclass(reply):
            continue
        if reply.FAULTS is not None or _STATUS_FIELDS & {f.name for f in dataclasses.fields(reply)}:
            return True
    return False


def fault_names(reply: Reply | None) -> list[str] | None:
    """The faults ``reply`` reports, by name: its flags (``Reply.FAULTS``), or its fault code
    (``Reply.FAULT_CODE``; a code in ``NO_FAULT_CODES`` is a state, no fault: ``[]``); None for a
    reply with neither field (the ``errors`` column of ``status`` and ``scan``)."""
    faults = getattr(reply, "FAULTS", None)
    if faults is not None:
        flags = getattr(reply, faults)
        if not isinstance(flags, enum.Flag):  # (flags declared as a plain int)
            return [f"0x{int(flags):X}"] if flags else []
        return [m.name for m in type(flags) if m.value and m in flags and m.name]
    code_field = getattr(reply, "FAULT_CODE", None)
    if code_field is not None:
        code = getattr(reply, code_field)
        if code in getattr(reply, "NO_FAULT_CODES", ()):
            return []
        return [code.name if isinstance(code, enum.Enum) else f"code {int(code)}"]
    return None


# ---- the part ----


def _no_ops() -> Mapping[str, Op]:
    return {}


@dataclass(frozen=True, slots=True, kw_only=True)
class CliFamily:
    """A family's ``cli`` part: its operations, settings, status reads and scan queries (see the
    module's docstring for how the CLI uses each).

    Attributes:
        ops: CLI command name -> what it sends (``stop`` and ``off`` default to the bound codec's
            safe commands).
        why_not: CLI command name -> why the family has none.
        status: the status reads (None: derived from the commands' declarations; empty: none).
        settings: ``servobus config``'s settings, keys unique.
        identify: scan's first query, on the probe's binding (None: nothing more to ask).
        describe: scan's second query, on a binding in the revision ``identify`` named.
        scan_ids: the ids ``scan`` probes without ``--ids`` (None: 1-32, those of them the family's
            ``motor_ids`` allow); probed in rounds of motors that can share a bus
            (:func:`sharing_rounds`), so ids whose request and reply ids collide need no rule here.
    """

    ops: Mapping[str, Op] = field(default_factory=_no_ops)
    why_not: Mapping[str, str] = field(default_factory=dict)
    status: Sequence[Callable[[], Command]] | None = None
    settings: Sequence[Setting] = ()
    identify: Query | None = None
    describe: Query | None = None
    scan_ids: Sequence[int] | None = None

    def __post_init__(self) -> None:
        keys = [s.key for s in self.settings]
        if len(set(keys)) != len(keys):
            raise ValueError(f"settings keys repeat: {sorted(k for k in keys if keys.count(k) > 1)}")
        both = set(self.ops) & set(self.why_not)
        if both:
            raise ValueError(f"commands both offered and refused: {sorted(both)}")

    def op(self, command: str) -> Op | None:
        """The entry of CLI command ``command`` (None: the family has none)."""
        found = self.ops.get(command)
        if found is None and command not in self.why_not:
            return DEFAULT_OPS.get(command)
        return found

    def supports(self, command: str, family: Family | None = None) -> bool:
        """Whether the family offers CLI command ``command`` (one of :data:`OPERATIONS`): an entry in
        :attr:`ops` (or a default: ``stop``, ``off``), not refused in :attr:`why_not`. For
        ``status``: reads given in :attr:`status`, or, where it is None, derived from ``family``'s
        commands (assumed there without ``family``)."""
        if command == "status":
            if "status" in self.why_not:
                return False
            if self.status is None:
                return family is None or bool(derived_status(family))
            return bool(self.status)
        return self.op(command) is not None

    def operations(self, family: Family | None = None) -> tuple[str, ...]:
        """The CLI commands the family offers, in :data:`OPERATIONS`' order (see :meth:`supports`)."""
        return tuple(c for c in OPERATIONS if self.supports(c, family))

    def status_reads(self, family: Family) -> Sequence[Callable[[], Command]]:
        """:attr:`status`, or the reads derived from ``family``'s commands where it is None."""
        return derived_status(family) if self.status is None else self.status


OPERATIONS = (
    "status",
    "move",
    "speed",
    "torque",
    "mit",
    "stop",
    "off",
    "brake",
    "zero",
    "set-id",
    "clear-errors",
    "reset",
)
"""The CLI commands a family's part offers (``ops``, ``status``) or refuses (``why_not``)."""

DEFAULT_OPS: Mapping[str, Op] = {"stop": safe("stop"), "off": safe("shutdown")}
"""The CLI commands every family has without a table: its bound codec's safe commands."""

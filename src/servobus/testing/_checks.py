"""The contract's checks as plain functions of a :class:`~servobus.protocols.Family` (each raises
AssertionError naming the family and the class, or returns what it checked)."""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from hypothesis import HealthCheck, Phase, find, given, settings
from hypothesis import strategies as st
from hypothesis.errors import NoSuchExample, Unsatisfiable

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Command, Family, FrameKind, Message, Reply, check_bus
from servobus.protocols.authoring import EXTENDED
from servobus.testing._strategies import Strategies, message_classes, strategies_of

__all__ = [
    "FLAGS",
    "NO_OPTIONS",
    "BindOptions",
    "bindings",
    "check_bound_codecs",
    "check_bus_of",
    "check_cli_part",
    "check_command_round_trips",
    "check_dbc_part",
    "check_declarations",
    "check_reply_round_trips",
    "check_safe_commands",
    "check_sim_answers",
    "unbuilt",
]

#: the bool class attributes every command declares (``Command``'s docstring)
FLAGS = ("READ", "SLOW", "ECHO", "STREAMABLE", "NOTED", "NEVER_ECHOED")
#: ``bind``'s keyword arguments, one mapping per binding to check (a motor model, a bound codec's options)
BindOptions = Sequence[Mapping[str, Any]]
#: bind with the family's defaults only
NO_OPTIONS: BindOptions = ({},)
#: the kinds of safe command a bound codec may give (``BoundCodec.safe_command``)
SAFE_KINDS = ("stop", "shutdown", "brake")


def _is_frozen_slotted_dataclass(cls: type) -> bool:
    params = getattr(cls, "__dataclass_params__", None)
    return params is not None and params.frozen and "__slots__" in cls.__dict__


def check_declarations(family: Family[Any]) -> None:
    """Every command declares its reply (``Command[R]``) or why none comes (``NO_REPLY``), not both;
    its reply classes are Replies; commands and replies are frozen slotted dataclasses; the
    command kinds (``READ``, ``SLOW``, ...) are bools; one method name per command."""
    assert family.commands, f"{family.name} declares no commands"
    for cls in family.commands:
        name = f"{family.name}: {cls.__name__}"
        assert cls.REPLY is not Reply, f"{name} does not declare its reply type (Command[R])"
        assert (cls.REPLY is None) == (cls.NO_REPLY is not None), f"{name}: REPLY or NO_REPLY, one of them"
        assert all(isinstance(r, type) and issubclass(r, Reply) for r in cls.reply_types()), name
        for flag in FLAGS:
            assert isinstance(getattr(cls, flag), bool), f"{name}.{flag} is not a bool"
    for message in message_classes(family):
        assert _is_frozen_slotted_dataclass(message), (
            f"{family.name}: {message.__name__} is no frozen slotted dataclass"
        )
    family.methods()  # ValueError: two commands with one method name


def _bound(
    family: Family[Any], options: BindOptions = NO_OPTIONS, motor_id: int | None = None
) -> list[tuple[BoundCodec, dict[str, Any]]]:
    """(codec, the options it was bound with) for every options, link and revision the family binds."""
    ids = family.motor_ids
    chosen = motor_id if motor_id is not None else ids[1] if len(ids) > 1 else ids[0]
    out = []
    for opts in options:
        for link in family.links:
            for revision in family.revisions:
                try:
                    out.append((family.bind(chosen, revision=revision, link=link, **opts), dict(opts)))
                except ValueError:
                    continue
    return out


def bindings(
    family: Family[Any], motor_id: int | None = None, options: BindOptions = NO_OPTIONS
) -> Iterator[BoundCodec]:
    """One motor's bound codec on every link and revision the family binds, with each of
    ``options`` (``bind``'s keyword arguments, a motor model: none by default); a combination the
    family refuses with ValueError is skipped. ``motor_id`` defaults to the family's second id
    (its first may be special)."""
    for codec, _ in _bound(family, options, motor_id):
        yield codec


def _can_bindings(family: Family[Any], options: BindOptions) -> list[tuple[BoundCodec, dict[str, Any]]]:
    return [(codec, opts) for codec, opts in _bound(family, options) if codec.framing is None]


def _sent_on_can(
    family: Family[Any], strategies: Strategies | None, options: BindOptions
) -> set[type[Command]]:
    """The command classes whose simplest command encodes on a CAN binding."""
    codecs = [codec for codec, _ in _can_bindings(family, options)]
    out: set[type[Command]] = set()
    for cls, command in _examples(family, strategies).items():
        for codec in codecs:
            try:
                codec.encode(command)
            except ValueError:
                continue
            out.add(cls)
            break
    return out


def unbuilt(family: Family[Any], strategies: Strategies | None = None) -> list[str]:
    """The names of the family's message classes with no strategy (neither given nor derived)."""
    built = strategies_of(family, strategies)
    return [cls.__name__ for cls in message_classes(family) if cls not in built]


def _run(check: Callable[[Message], None], strategy: st.SearchStrategy[Any], max_examples: int) -> None:
    @settings(
        max_examples=max_examples,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
    )
    @given(strategy)
    def each(message: Message) -> None:
        check(message)

    each()


def _reply_frames(codec: BoundCodec, data: bytes) -> Iterator[Frame]:
    """``data`` as it would arrive on each of the codec's reply identifiers."""
    serial = codec.framing is not None
    for ident in sorted(codec.reply_ids):
        yield Frame(
            arbitration_id=ident & ~EXTENDED,
            data=data,
            is_extended_id=bool(ident & EXTENDED),
            is_fd=len(data) > 8 and not serial,
            is_serial=serial,
            is_rx=True,
        )


def _request_options(
    family: Family[Any], codec: BoundCodec, frame: Frame, opts: Mapping[str, Any]
) -> dict[str, Any]:
    """``decode_request``'s keyword arguments for ``frame``, as servobus' log decoder gives them
    (the revision; the codec's model and the frame's flags where the decoder takes them), and the
    binding's own options it takes."""
    params = inspect.signature(family.decode_request).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    options: dict[str, Any] = {"revision": codec.revision}
    derived = {"model": codec.model, "is_extended_id": frame.is_extended_id, "is_fd": frame.is_fd}
    options.update((name, value) for name, value in derived.items() if name in params)
    options.update((name, value) for name, value in opts.items() if name in params or takes_any)
    return options


def check_command_round_trips(
    family: Family[Any],
    strategies: Strategies | None = None,
    *,
    max_examples: int = 20,
    bind_options: BindOptions = NO_OPTIONS,
) -> list[str]:
    """Each command class with a strategy that is sent on CAN: every drawn command encodes on a CAN
    binding that takes it, and the family's request decoder (``Family.decode_request``, which takes
    a CAN identifier; given the revision, the codec's model, the frame's ``is_extended_id`` and
    ``is_fd`` where it names them, and the binding's options) gives back an equal command there.
    Returns the classes checked."""
    codecs = _can_bindings(family, bind_options)
    built = strategies_of(family, strategies)
    on_can = _sent_on_can(family, strategies, bind_options)
    checked = []
    for cls in family.commands:
        if cls not in built or cls not in on_can:
            continue

        def round_trip(command: Message) -> None:
            tried = []
            for codec, opts in codecs:
                try:
                    frame = codec.encode(command)  # type: ignore[arg-type]
                except ValueError:  # not on this link or revision
                    continue
                try:
                    decoded = family.decode_request(
                        frame.arbitration_id, frame.data, **_request_options(family, codec, frame, opts)
                    )
                except ProtocolError as exc:
                    tried.append(f"{codec!r}: {exc}")
                    continue
                if decoded == command:
                    return
                tried.append(f"{codec!r}: decoded as {decoded!r}")
            assert tried, f"{family.name}: no binding encodes {command!r}"
            raise AssertionError(f"{family.name}: {command!r} does not decode back: {'; '.join(tried)}")

        _run(round_trip, built[cls], max_examples)
        checked.append(cls.__name__)
    return checked


def check_reply_round_trips(
    family: Family[Any],
    strategies: Strategies | None = None,
    *,
    max_examples: int = 20,
    bind_options: BindOptions = NO_OPTIONS,
) -> list[str]:
    """Each reply class with a strategy that answers a command sent on CAN: every drawn reply's
    bytes, arriving on a motor's reply identifier, are the motor's (``classify`` is not NOT_OURS)
    and decode to an equal reply on some CAN binding. Returns the classes checked."""
    codecs = [codec for codec, _ in _can_bindings(family, bind_options)]
    built = strategies_of(family, strategies)
    sent = _sent_on_can(family, strategies, bind_options)
    replies = list(dict.fromkeys(r for cls in sent for r in cls.reply_types()))
    checked = []
    for cls in replies:
        if cls not in built:
            continue

        def round_trip(reply: Message) -> None:
            data = reply.encode()
            tried = []
            for codec in codecs:
                for frame in _reply_frames(codec, data):
                    if codec.classify(frame)[0] is FrameKind.NOT_OURS:
                        continue
                    try:
                        decoded = codec.decode(frame)
                    except ProtocolError as exc:
                        tried.append(f"{codec!r}: {exc}")
                        continue
                    if decoded == reply:
                        return
                    tried.append(f"{codec!r}: decoded as {decoded!r}")
            raise AssertionError(
                f"{family.name}: {reply!r} does not decode back: {'; '.join(tried) or 'no codec takes it'}"
            )

        _run(round_trip, built[cls], max_examples)
        checked.append(cls.__name__)
    return checked


#: the simplest example, without hypothesis's explain phase (it cost 90 % of the time and says nothing
#: here: every example is "interesting")
_SIMPLEST = settings(database=None, deadline=None, phases=[Phase.generate, Phase.shrink])


def _examples(family: Family[Any], strategies: Strategies | None) -> dict[type[Command], Command]:
    """One command of each class that has a strategy (its simplest: what hypothesis shrinks to)."""
    out: dict[type[Command], Command] = {}
    for cls, strategy in strategies_of(family, strategies).items():
        if not issubclass(cls, Command):
            continue
        try:
            out[cls] = find(strategy, lambda _: True, settings=_SIMPLEST)
        except (NoSuchExample, Unsatisfiable):  # a strategy that yields nothing: see unbuilt()
            continue
    return out


def check_bound_codecs(
    family: Family[Any], strategies: Strategies | None = None, *, bind_options: BindOptions = NO_OPTIONS
) -> int:
    """Every binding (link, revision) follows the declarations for every command it takes: it
    encodes on one of the motor's own or the family's shared identifiers, ``retry_safe`` is ``READ``,
    a reply key exactly when a reply is declared, a positive ``timeout_s``. Returns the (binding,
    command) pairs checked."""
    checked = 0
    examples = _examples(family, strategies)
    for codec in bindings(family, options=bind_options):
        for cls, command in examples.items():
            try:
                frame = codec.encode(command)
                key = codec.reply_key(command)
            except ValueError:  # not on this link or revision (or a broadcast): the codec says so
                continue
            where = f"{family.name} {codec!r}: {cls.__name__}"
            ident = frame.arbitration_id | (EXTENDED if frame.is_extended_id else 0)
            assert ident in codec.request_ids | codec.shared_ids, (
                f"{where} is sent on {frame.arbitration_id:#x}"
            )
            assert codec.retry_safe(command) is cls.READ, f"{where}: retry_safe is not READ"
            assert (key is None) == (cls.REPLY is None), f"{where}: a reply key iff a reply is declared"
            assert codec.timeout_s(command) > 0, f"{where}: timeout_s"
            checked += 1
    assert checked, f"{family.name}: no command could be checked on any binding"
    return checked


def check_safe_commands(family: Family[Any], *, bind_options: BindOptions = NO_OPTIONS) -> None:
    """Every binding gives a safe command of one of its kinds (``stop``, ``shutdown``, ``brake``), a
    command of the family that encodes; an unknown kind is a ValueError."""
    for codec in bindings(family, options=bind_options):
        found = []
        for kind in SAFE_KINDS:
            try:
                command = codec.safe_command(kind)
            except ValueError:
                continue
            assert type(command) in family.commands, f"{family.name} {codec!r}: {kind} is {command!r}"
            codec.encode(command)
            found.append(kind)
        assert found, f"{family.name} {codec!r} has no safe command"
        try:
            codec.safe_command("no such kind")
        except ValueError:
            pass
        else:
            raise AssertionError(f"{family.name} {codec!r}: an unknown safe-command kind is accepted")


def check_bus_of(family: Family[Any], count: int = 3, *, bind_options: BindOptions = NO_OPTIONS) -> None:
    """``count`` motors of the family (its first ids but 0) share a bus on every link, with each
    of ``bind_options``."""
    ids = [i for i in family.motor_ids if i != 0][:count]
    for opts in bind_options:
        for link in family.links:
            codecs = []
            for motor_id in ids:
                try:
                    codecs.append(family.bind(motor_id, link=link, **opts))
                except ValueError:
                    break
            check_bus(codecs)


def check_sim_answers(family: Family[Any], strategies: Strategies | None = None) -> int:
    """The family's ``sim`` part (if any): a fresh simulated motor answers every command that
    expects a reply with a frame its bound codec classifies as that command's reply and decodes
    to one of the declared reply types. Returns the commands checked (0: no sim part)."""
    if "sim" not in family.parts:
        return 0
    from servobus.sim.family import SimFamily, SimOptions

    sim = family.part("sim")
    assert isinstance(sim, SimFamily), f"{family.name}: the sim part is {type(sim).__name__}"
    examples = _examples(family, strategies)
    checked = 0
    for codec in bindings(family):  # the family's defaults: the simulated motors' model
        if codec.link != "can" or codec.framing is not None:
            continue
        for cls, command in examples.items():
            try:
                frame = codec.encode(command)
                key = codec.reply_key(command)
            except ValueError:
                continue
            if key is None:
                continue
            (device,) = sim.devices([codec.motor_id], codec.revision, SimOptions()).can_devices
            sent = dataclasses.replace(frame, is_rx=False)
            answers = [dataclasses.replace(e.frame, is_rx=True) for e in device.receive(sent, 0.0)]
            mine = [a for a in answers if codec.classify(a) == (FrameKind.REPLY, key)]
            where = f"{family.name} {codec!r}: the simulated motor's answer to {command!r}"
            assert mine, f"{where}: none with the reply key ({answers})"
            reply = codec.decode(mine[0])
            assert isinstance(reply, cls.reply_types()), f"{where} is {reply!r}"
            checked += 1
    return checked


def check_cli_part(family: Family[Any]) -> bool:
    """The family's ``cli`` part (if any) is a :class:`servobus.protocols.cli.CliFamily` that offers
    or refuses (with a reason) each CLI operation, and whose status reads build commands of the
    family. Returns whether there is a part."""
    if "cli" not in family.parts:
        return False
    from servobus.protocols.cli import OPERATIONS, CliFamily

    part = family.part("cli")
    assert isinstance(part, CliFamily), f"{family.name}: the cli part is {type(part).__name__}"
    for operation in OPERATIONS:
        if operation == "status":
            continue
        assert part.op(operation) is not None or part.why_not.get(operation), (family.name, operation)
    for make in part.status_reads(family):
        assert type(make()) in family.commands, f"{family.name}: status read {make!r}"
    return True


def check_dbc_part(family: Family[Any], ids: tuple[int, ...] | None = None) -> str:
    """The family's ``dbc`` part (if any) is a :class:`servobus.protocols.dbc.DbcFamily`, and the
    family's DBC (its part's, or the one derived from its declarations) builds for a few motors and
    cantools loads it back with the same frames. Returns the DBC text (needs cantools)."""
    import cantools

    from servobus.protocols.dbc import DbcFamily
    from servobus.tools.dbc import database, dbc_text, plan

    if "dbc" in family.parts:
        part = family.part("dbc")
        assert isinstance(part, DbcFamily), f"{family.name}: the dbc part is {type(part).__name__}"
    chosen = ids if ids is not None else tuple(i for i in family.motor_ids if i != 0)[:2]
    p = plan(family, chosen)
    assert p.messages, f"{family.name}: the DBC has no messages"
    text = dbc_text(database(p))
    loaded = cantools.database.load_string(text, database_format="dbc")
    assert isinstance(loaded, cantools.database.can.Database)
    assert sorted(m.frame_id for m in loaded.messages) == sorted(m.frame_id for m in p.messages)
    return text

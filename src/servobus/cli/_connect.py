"""The connection options every bus command takes, in python-can's terms, and the Bus they open.

``--sim N`` runs against N simulated motors in-process (real time), with the first N ids of
``--ids`` (:data:`SIM_RULE`, the one rule every command follows); ``--interface/--channel``
(``-i``/``-c``) opens a CAN adapter through python-can (its configuration file and ``CAN_*``
environment variables are the defaults), or with ``-i servobus-slcan`` an SLCAN adapter through
servobus's own transport; ``--port`` opens an RS485 line. ``--family``,
``--revision`` and ``--ids`` say which motors are there; ``--timeout-ms`` how long each request
waits for its reply (default: the library's).
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import click

from servobus.bus import Bus, Motor
from servobus.cli._help import CONNECTION, GroupedOption
from servobus.cli._output import FloatRange, refused
from servobus.cli._remote import remote_from, remote_options
from servobus.limits import LimitBook
from servobus.limits import load as load_limits
from servobus.protocols import DEFAULT_FAMILY, FAMILIES, available_families, get_family

if TYPE_CHECKING:
    from servobus.sim.family import SimFamily

__all__ = [
    "SIM_RULE",
    "Connection",
    "FamilyChoice",
    "connection_options",
    "family_option",
    "note_exit",
    "open_bus",
    "parse_ids",
    "remote_connection_options",
    "revision_option",
    "sim_devices",
    "sim_part",
    "timeout_option",
]

#: ``--interface`` value for servobus's own SLCAN transport (no python-can; no 2 s wait on open)
NATIVE_SLCAN = "servobus-slcan"
F = TypeVar("F", bound=Callable[..., Any])


#: more ids than any family has (hollow: 0-100; MyActuator, LK: 1-32); a longer list is a typo
MAX_IDS = 256


def parse_ids(text: str) -> tuple[int, ...]:
    """``"1-3,7"`` -> ``(1, 2, 3, 7)``.

    Raises:
        ValueError: not a list of ids and ranges, an empty range, or more than :data:`MAX_IDS` ids
            (refused before the list is built: ``1-1000000000`` would take gigabytes).
    """
    ids: list[int] = []
    for part in text.split(","):
        first, sep, last = part.strip().partition("-")
        try:
            lo = int(first)
            hi = int(last) if sep else lo
        except ValueError:
            raise ValueError(f"--ids {text!r}: expected ids and ranges like 1-4,7") from None
        if hi < lo:
            raise ValueError(f"--ids {text!r}: the range {part.strip()} is empty")
        if len(ids) + (hi - lo + 1) > MAX_IDS:
            raise ValueError(f"--ids {text!r}: more than {MAX_IDS} ids")
        ids.extend(range(lo, hi + 1))
    return tuple(dict.fromkeys(ids))


@dataclass(frozen=True, slots=True)
class Connection:
    """Where the motors are (from the command line)."""

    family: str = DEFAULT_FAMILY
    revision: str | None = None
    ids: tuple[int, ...] = ()
    sim: int | None = None
    interface: str | None = None
    channel: str | None = None
    bitrate: int | None = None
    fd: bool = False
    data_bitrate: int | None = None
    port: str | None = None
    baud: int | None = None
    #: each request's reply timeout (``--timeout-ms``); None: the library's
    timeout_s: float | None = None
    #: the motors' host-side limits (``--limits FILE``); None: none
    limits: LimitBook | None = None

    @property
    def link(self) -> str:
        """The family's link name: ``"rs485"`` on a serial port, ``"canfd"``/``"can"`` otherwise."""
        if self.port is not None:
            return "rs485"
        return "canfd" if self.fd and "canfd" in get_family(self.family).links else "can"

    @property
    def motor_ids(self) -> tuple[int, ...]:
        """The ids to address: ``--ids``, or 1..N with ``--sim N``, or 1 alone."""
        if self.ids:
            return self.ids
        return tuple(range(1, (self.sim or 1) + 1))

    @property
    def sim_ids(self) -> tuple[int, ...]:
        """The simulated motors' ids with ``--sim N`` (:data:`SIM_RULE`): the first N of
        :attr:`motor_ids` (empty without ``--sim``)."""
        return self.motor_ids[: self.sim or 0]

    def bind_options(self) -> dict[str, Any]:
        options: dict[str, Any] = {"link": self.link}
        if self.revision is not None:
            options["revision"] = self.revision
        return options

    def sim_transport(self, ids: tuple[int, ...], name: str = "sim") -> Any:
        """The in-process simulated bus of this connection's family with motors ``ids`` (not yet
        open), their drives within ``limits`` too (as ``servobus sim --limits``)."""
        from servobus.transports.sim import SimTransport

        where = (self.family, ids, self.revision)
        # fd only when given: the plain three-argument call is the one test doubles stand in for
        devices = sim_devices(*where, fd=True) if self.fd else sim_devices(*where)
        if self.limits is not None:
            from servobus.sim.limits import bound

            bound(devices, self.limits)
        return SimTransport(devices=devices, name=name)

    def transport(self) -> Any:
        """The transport (not yet open) this connection names.

        Raises:
            click.UsageError: no bus named, or contradictory flags.
        """
        if self.sim is not None:
            return self.sim_transport(self.sim_ids)
        if self.port is not None:
            from servobus.transports.rs485 import SerialTransport

            framing = get_family(self.family).bind(self.motor_ids[0], **self.bind_options()).framing
            return SerialTransport(self.port, framing=framing, baud=self.baud)
        if self.interface == NATIVE_SLCAN:
            from servobus.transports.slcan import SlcanTransport

            if not self.channel:
                raise click.UsageError(f"-i {NATIVE_SLCAN} needs the adapter's serial port: -c /dev/ttyACM0")
            return SlcanTransport(
                self.channel, bitrate=self.bitrate, data_bitrate=self.data_bitrate, fd=self.fd
            )
        from servobus.transports.can import CanTransport

        return CanTransport(
            self.interface,
            self.channel,
            bitrate=self.bitrate,
            fd=self.fd,
            data_bitrate=self.data_bitrate,
        )


def sim_part(family: str) -> SimFamily:
    """The simulator part of ``family`` (``FAMILY.part("sim")``).

    Raises:
        ValueError: the family has none, or it is not a :class:`~servobus.sim.family.SimFamily`.
    """
    from servobus.sim.family import SimFamily

    try:
        sim = get_family(family).part("sim")
    except LookupError as exc:
        raise ValueError(f"--sim: {exc}") from None
    if not isinstance(sim, SimFamily):
        raise ValueError(f"--sim: the {family} family's sim part is {type(sim).__name__}, not a SimFamily")
    return sim


def sim_devices(
    family: str, ids: tuple[int, ...], revision: str | None = None, *, fd: bool = False
) -> list[Any]:
    """Simulated motors of ``family`` with ``ids``, in ``revision`` (the family's own parser reads it),
    on CAN FD with ``fd``: what the family's simulator part builds for the in-process bus.

    Raises:
        ValueError: a revision the family does not have, or options its simulator refuses.
    """
    from servobus.sim.family import SimOptions

    protocol = get_family(family)
    rev = protocol.revision(revision) if revision else protocol.default_revision
    setup = sim_part(family).devices(ids, rev, SimOptions(fd=fd))
    return list(setup.can_devices)


def _check(conn: Connection) -> Connection:
    """``conn``, or a click.UsageError naming the mistake and what to give (exit 2, one line)."""
    named = [
        flag
        for flag, on in (
            ("--sim", conn.sim is not None),
            ("--port", conn.port is not None),
            ("--interface/--channel", bool(conn.interface or conn.channel)),
        )
        if on
    ]
    if len(named) > 1:
        raise click.UsageError(f"{' and '.join(named)} name different buses: give one")
    if conn.baud is not None and conn.port is None:
        raise click.UsageError("--baud is for a serial --port")
    if (conn.fd or conn.data_bitrate) and conn.port is not None:
        raise click.UsageError("--fd and --data-bitrate are for CAN, not a serial --port")
    if conn.bitrate is not None and conn.port is not None:
        raise click.UsageError("--bitrate is for CAN; a serial --port takes --baud")
    if conn.data_bitrate is not None and not conn.fd:
        raise click.UsageError("--data-bitrate is the CAN FD data phase's bit rate: give --fd too")
    if conn.sim is not None and not 1 <= conn.sim <= 32:
        raise click.UsageError(f"--sim {conn.sim}: between 1 and 32 motors")
    if conn.sim is not None and conn.ids and len(conn.ids) < conn.sim:
        raise click.UsageError(
            f"--sim {conn.sim} simulates the first {conn.sim} ids of --ids, which names "
            f"{len(conn.ids)}: give {conn.sim} ids or more, or --sim {len(conn.ids)}"
        )
    if conn.sim is not None:  # what the family's simulator serves: its one-line refusals
        from servobus.sim.family import SimOptions

        try:
            sim_part(conn.family).check(SimOptions(fd=conn.fd))
        except ValueError as exc:
            raise click.UsageError(str(exc)) from None
    if conn.interface == NATIVE_SLCAN:
        if not conn.channel:
            raise click.UsageError(f"-i {NATIVE_SLCAN} needs the adapter's serial port: -c /dev/ttyACM0")
    elif conn.sim is None and conn.port is None:
        _check_python_can(conn)
    family = get_family(conn.family)
    with refused():  # the ids and revision the family has, before any command builds on them
        for motor_id in conn.motor_ids:
            family.bind(motor_id, **conn.bind_options())
    return conn


#: -c examples for the interfaces a newcomer meets first
_CHANNELS = {"slcan": "/dev/ttyACM0", "socketcan": "can0", "virtual": "test", "pcan": "PCAN_USBBUS1"}
_NO_BUS = (
    "give --sim N, --interface/--channel (python-can), or a serial --port "
    "(or configure python-can: ~/.canrc or CAN_INTERFACE)"
)


def _check_python_can(conn: Connection) -> None:
    """The python-can interface and channel ``conn`` names (with python-can's configuration: its
    files and ``CAN_*`` variables) exist: a UsageError, not python-can's traceback, when they do not."""
    import can

    given = {"interface": conn.interface, "channel": conn.channel}
    try:
        config = can.util.load_config(config={k: v for k, v in given.items() if v is not None})
    except can.CanInterfaceNotImplementedError:  # python-can's answer to a missing interface too
        config = None
    except ValueError as exc:  # a value python-can's configuration refused (a bit timing)
        raise click.UsageError(f"python-can's configuration: {exc}") from None
    interface = conn.interface if config is None else config.get("interface")
    if config is None and conn.interface is None:
        configured = (
            can.util.load_environment_config().get("interface")
            or can.util.load_file_config().get("interface")
            or can.util.load_file_config().get("bustype")
        )
        if configured:  # not on the command line: python-can's own configuration names it
            raise click.UsageError(
                f"python-can's configuration (CAN_INTERFACE or ~/.canrc) names interface "
                f"{configured!r}, which python-can does not have: give -i"
            )
        if conn.channel:
            raise click.UsageError(
                f"-c {conn.channel} needs -i: the python-can interface (slcan for a serial adapter, "
                f"socketcan, pcan, ...) or {NATIVE_SLCAN}"
            )
        raise click.UsageError(f"no bus: {_NO_BUS}")
    if config is None:
        known = ", ".join(sorted(can.interfaces.VALID_INTERFACES))
        raise click.UsageError(
            f"-i {interface}: python-can has no such interface; one of {known}, or {NATIVE_SLCAN}"
        )
    if config.get("channel") is None and _needs_channel(str(interface)):
        example = _CHANNELS.get(str(interface), "CHANNEL")
        raise click.UsageError(f"-i {interface} needs -c: the adapter's channel (-c {example})")


def _needs_channel(interface: str) -> bool:
    """Whether python-can's ``interface`` has no default channel (slcan: the serial port); False when
    its module does not import (python-can's own error says why, on opening)."""
    import importlib
    import inspect

    import can

    try:
        module, name = can.interfaces.BACKENDS[interface]
        bus_class = getattr(importlib.import_module(module), name)
        channel = inspect.signature(bus_class.__init__).parameters.get("channel")
    except Exception:
        return False
    return channel is not None and channel.default is inspect.Parameter.empty


class FamilyChoice(click.Choice[str]):
    """The registered families' names, read when a command line is checked (not when this module is
    imported), so a family a plug-in registers by entry point is offered too: the built-ins in
    registry order, then the plug-ins'."""

    def __init__(self) -> None:
        super().__init__((), case_sensitive=True)

    @property
    def choices(self) -> tuple[str, ...]:
        return (*FAMILIES, *(name for name in available_families() if name not in FAMILIES))

    @choices.setter
    def choices(self, value: object) -> None:
        """click.Choice sets its choices once; these are read each time instead."""


#: the one rule of ``--sim N`` and ``--ids``, for every command that takes both (``--sim``'s help)
SIM_RULE = (
    "N simulated motors in-process, with the first N ids of --ids (1..N without --ids); the command "
    "addresses every id of --ids: the others stay silent, as on a bus of N motors."
)
IDS_HELP = "Motor ids, e.g. 1-4,7 [default: 1, or 1..N with --sim N]."


def _family(**grouped: Any) -> Callable[[F], F]:
    return click.option(
        "--family",
        "-f",
        type=FamilyChoice(),
        default=DEFAULT_FAMILY,
        show_default=True,
        help="Protocol family of the motors.",
        **grouped,
    )


def _revision(**grouped: Any) -> Callable[[F], F]:
    return click.option(
        "--revision", help="Protocol revision (myactuator V4_3/V4_4; lk V2_35/V2_36).", **grouped
    )


class _FamilyOption(GroupedOption):
    """``--family`` among the connection options: ``FAMILY`` for its value and the families in its
    help, so the page's first column stays narrow."""

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        record = super().get_help_record(ctx)
        if record is None or not isinstance(self.type, FamilyChoice):
            return record
        names, text = record
        return names, text.replace("motors.", f"motors: {', '.join(self.type.choices)}.", 1)


#: ``--family``/``-f``: the command receives ``family``
family_option = _family()
#: ``--revision``: the command receives ``revision`` (None: the family's default)
revision_option = _revision()


#: the shortest ``--timeout-ms``: about the shortest request and reply there are on a 1 Mbit/s CAN bus
#: (47 bits each), the least time a reply can take; the longest: a reply later than this is not coming
#: (and the next request to the motor would wait as long again for a late one)
MIN_TIMEOUT_MS, MAX_TIMEOUT_MS = 0.1, 10_000.0


def _seconds(ctx: click.Context, param: click.Parameter, value: float | None) -> float | None:
    return None if value is None else value / 1000.0


def _timeout(**grouped: Any) -> Callable[[F], F]:
    return click.option(
        "--timeout-ms",
        "timeout_s",
        type=FloatRange(min=MIN_TIMEOUT_MS, max=MAX_TIMEOUT_MS),
        callback=_seconds,
        metavar="MS",
        help="How long each request waits for its reply, in ms [default: the library's, per command]. "
        "Raise it for a slow adapter.",
        **grouped,
    )


#: ``--timeout-ms``: the command receives ``timeout_s`` (seconds; None: the library's timeout)
timeout_option = _timeout()
#: the connection options' class and heading in --help (servobus.cli._help)
_GROUP: dict[str, Any] = {"cls": GroupedOption, "help_group": CONNECTION}


def _limits(ctx: click.Context, param: click.Parameter, value: str | None) -> LimitBook | None:
    if value is None:
        return None
    try:
        return load_limits(value)
    except (OSError, ValueError) as exc:
        raise click.BadParameter(str(exc)) from None


def _limits_opt(**grouped: Any) -> Callable[[F], F]:
    return click.option(
        "--limits",
        type=click.Path(dir_okay=False),
        callback=_limits,
        metavar="FILE",
        help="The motors' host-side limits (a TOML file: servobus.limits): every command is checked "
        "against them before it is sent, refused (exit 2) or clamped as the file says.",
        **grouped,
    )


def connection_options(func: F) -> F:
    """Add the connection options (and ``--timeout-ms``) to a click command; it receives
    ``conn: Connection``."""
    return _connection_options(func, remote=False)


def remote_connection_options(func: F) -> F:
    """:func:`connection_options`, and ``--remote NODE/BUS`` with its options
    (:mod:`servobus.cli._remote`): the command receives ``conn`` and ``remote`` (a
    :class:`~servobus.cli._remote.Remote`, or None for a local bus). With ``--remote``, ``conn``
    keeps only ``--family`` (as given), ``--ids`` and ``--timeout-ms``, unchecked: the bridge's motors
    are known once connected; a local bus option given with it is refused (exit 2)."""
    return _connection_options(func, remote=True)


#: the options that name a local bus (``Connection`` field -> flag), refused with ``--remote``
_LOCAL = {
    "sim": "--sim",
    "interface": "--interface",
    "channel": "--channel",
    "bitrate": "--bitrate",
    "fd": "--fd",
    "data_bitrate": "--data-bitrate",
    "port": "--port",
    "baud": "--baud",
    "revision": "--revision",
}


def _connection_options(func: F, *, remote: bool) -> F:
    @_family(cls=_FamilyOption, help_group=CONNECTION, metavar="FAMILY")
    @_revision(**_GROUP)
    @click.option("--ids", "ids_text", metavar="IDS", help=IDS_HELP, **_GROUP)
    @click.option("--sim", type=int, metavar="N", help=SIM_RULE, **_GROUP)
    @click.option(
        "--interface",
        "-i",
        help=f"python-can interface (socketcan, slcan, pcan, virtual, ...), or {NATIVE_SLCAN}: "
        "servobus's own SLCAN transport.",
        **_GROUP,
    )
    @click.option("--channel", "-c", help="python-can channel (can0, /dev/ttyACM0, ...).", **_GROUP)
    @click.option(
        "--bitrate",
        type=click.IntRange(min=1),
        help="CAN bit rate [default: the adapter's config].",
        **_GROUP,
    )
    @click.option("--fd", is_flag=True, help="CAN FD.", **_GROUP)
    @click.option("--data-bitrate", type=click.IntRange(min=1), help="CAN FD data-phase bit rate.", **_GROUP)
    @click.option("--port", help="Serial port of an RS485 line (/dev/ttyUSB0).", **_GROUP)
    @click.option(
        "--baud", type=click.IntRange(min=1), help="Serial baud rate [default: the family's].", **_GROUP
    )
    @_timeout(**_GROUP)
    @_limits_opt(**_GROUP)
    @(remote_options if remote else _unchanged)
    @functools.wraps(func)
    def wrapper(*args: Any, ids_text: str | None, **kwargs: Any) -> Any:
        names = (
            "family",
            "revision",
            "sim",
            "interface",
            "channel",
            "bitrate",
            "fd",
            "data_bitrate",
            "port",
            "baud",
            "timeout_s",
            "limits",
        )
        fields = {name: kwargs.pop(name) for name in names}
        try:
            ids = parse_ids(ids_text) if ids_text else ()
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--ids") from None
        if not remote:
            return func(*args, conn=_check(Connection(ids=ids, **fields)), **kwargs)
        target = remote_from(kwargs)
        if target is None:
            return func(*args, conn=_check(Connection(ids=ids, **fields)), remote=None, **kwargs)
        local = [flag for name, flag in _LOCAL.items() if fields[name] not in (None, False)]
        if local:
            raise click.UsageError(f"--remote and {', '.join(local)}: the bus is the bridge's, give one")
        conn = Connection(
            family=fields["family"], ids=ids, timeout_s=fields["timeout_s"], limits=fields["limits"]
        )
        return func(*args, conn=conn, remote=target, **kwargs)

    return wrapper  # type: ignore[return-value]


def _unchanged(func: F) -> F:
    return func


def note_exit(bus: Bus) -> None:
    """Remember which commanded motors ``bus`` sent its safe command when its block was left, and
    which of them answered it, for the line Ctrl-C prints (nothing for a Bus without one: it claims
    no stop)."""
    if bus.safe is None:
        return
    from servobus.cli import SAFE_EXITS

    sent = {id(motor) for motor in bus.safe_sent}
    acknowledged = {id(motor) for motor in bus.safe_acknowledged}
    by_family: dict[str, tuple[list[int], list[int], list[int]]] = {}
    for motor in bus.commanded:
        answered, unanswered, missed = by_family.setdefault(motor.codec.family, ([], [], []))
        if id(motor) in acknowledged:
            answered.append(motor.motor_id)
        else:
            (unanswered if id(motor) in sent else missed).append(motor.motor_id)
    for family, (answered, unanswered, missed) in by_family.items():
        ids = tuple(sorted(answered)), tuple(sorted(unanswered)), tuple(sorted(missed))
        SAFE_EXITS.append((bus.name, family, bus.safe, *ids))


@contextlib.asynccontextmanager
async def open_bus(
    conn: Connection, *, wrap: Callable[[Any], Any] | None = None, **bus_options: Any
) -> AsyncIterator[tuple[Bus, list[Motor]]]:
    """The Bus on ``conn``'s transport (given to ``wrap`` first, when given: a tap) with its motors
    bound; leaving it stops the commanded ones."""
    transport = conn.transport()
    bus_options.setdefault("limits", conn.limits)
    bus = Bus(transport if wrap is None else wrap(transport), **bus_options)
    try:
        async with bus:
            yield bus, [bus.motor(conn.family, i, **conn.bind_options()) for i in conn.motor_ids]
    finally:
        note_exit(bus)

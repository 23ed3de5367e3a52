"""``--remote NODE/BUS``: a command's motors on a bridge (``servobus bridge``, :mod:`servobus.remote`)
instead of a bus opened here.

The command connects with :func:`servobus.remote.connect` (``--endpoint``, ``--user``/``--password``
or ``SERVOBUS_REMOTE_USER``/``SERVOBUS_REMOTE_PASSWORD``, ``--read-only``), learns the bus's motors
from the bridge (their family, revision and link: ``--family`` only checks them, ``--ids`` picks
among them, all of them without it), binds each motor's codec here to build and check its commands
before any is sent, and then sends them through the bridge: a one-shot or a read as a request (its
reply comes back), a stream of set-points as the bridge's set-points (``RemoteBus.cycle``), which its
own tick loop sends until they go stale. The output is the local command's.

Leaving the connection (the end, Ctrl-C, SIGTERM) takes away this client's liveliness token: the
bridge sends its Bus's safe command to the motors this client commanded.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import click

from servobus.cli._help import REMOTE, GroupedOption
from servobus.cli._output import refused

if TYPE_CHECKING:
    from servobus.protocols import Command
    from servobus.remote import RemoteBus, RemoteMotor

__all__ = [
    "ENV_PASSWORD",
    "ENV_USER",
    "Remote",
    "RemoteCliMotor",
    "open_remote",
    "remote_extra",
    "remote_from",
    "remote_options",
]

F = TypeVar("F", bound=Callable[..., Any])

ENV_USER = "SERVOBUS_REMOTE_USER"
ENV_PASSWORD = "SERVOBUS_REMOTE_PASSWORD"

#: the options :func:`remote_options` adds (click's parameter names), taken out of the command's
_NAMES = ("remote", "endpoints", "user", "password", "read_only")


@dataclass(frozen=True, slots=True)
class Remote:
    """A bus on a bridge, as the command line named it.

    Attributes:
        node: the bridge's node name.
        bus: the bus's name on the bridge.
        endpoints: where the bridge listens (Zenoh endpoints).
        user: the Zenoh user name (None: no authentication).
        password: its password.
        read_only: connect without the right to command (reads and states only).
        family: the family ``--family`` named (None: not given, the bridge's motors as they are).
    """

    node: str
    bus: str
    endpoints: tuple[str, ...]
    user: str | None = None
    password: str | None = None
    read_only: bool = False
    family: str | None = None

    @property
    def target(self) -> str:
        """``NODE/BUS``."""
        return f"{self.node}/{self.bus}"

    def commanding(self, name: str) -> None:
        """Refuse ``--read-only`` for command ``name``, which commands the motors (exit 2, nothing sent).

        Raises:
            click.UsageError: this connection was asked read-only.
        """
        if self.read_only:
            raise click.UsageError(f"--read-only: {name} commands the motors; drop --read-only")

    def connect(self, *, read_only: bool = False, valid_for_s: float = 0.1) -> RemoteBus:
        """The :class:`~servobus.remote.RemoteBus` to enter (``read_only`` as well as ``--read-only``:
        a command that only reads declares no commanding client)."""
        with remote_extra():
            from servobus.remote import connect

        return connect(
            self.target,
            endpoints=self.endpoints,
            user=self.user,
            password=self.password,
            read_only=read_only or self.read_only,
            valid_for_s=valid_for_s,
        )


def _default() -> str:
    """:data:`servobus.remote.security.DEFAULT_ENDPOINT`, known without importing Zenoh: the commands
    load without the ``[remote]`` extra (a test checks the two agree)."""
    return "tcp/127.0.0.1:7447"


@contextlib.contextmanager
def remote_extra() -> Iterator[None]:
    """Inside the block, :mod:`servobus.remote` failing to import (no ``eclipse-zenoh``) is one line
    naming the extra to install, exit 1.

    Raises:
        click.ClickException: the ImportError's message.
    """
    try:
        yield
    except ImportError as exc:
        raise click.ClickException(str(exc)) from exc


def _option(*names: str, **kwargs: Any) -> Callable[[F], F]:
    """A remote option: under its own heading in --help (:mod:`servobus.cli._help`)."""
    return click.option(*names, cls=GroupedOption, help_group=REMOTE, **kwargs)


def remote_options(func: F) -> F:
    """Add ``--remote``, ``--endpoint``, ``--user``, ``--password`` and ``--read-only`` to a click
    command (its wrapper takes them out with :func:`remote_from`)."""
    for option in reversed(
        (
            _option(
                "--remote",
                metavar="NODE/BUS",
                help="Talk to the motors of bus BUS on the bridge NODE (servobus bridge) instead of a "
                "local bus.",
            ),
            _option(
                "--endpoint",
                "endpoints",
                multiple=True,
                metavar="ENDPOINT",
                help="Where the bridge listens, a Zenoh endpoint; repeat for several "
                f"[default: {_default()}].",
            ),
            _option(
                "--user", envvar=ENV_USER, show_envvar=True, help="User name, when the bridge asks for one."
            ),
            _option(
                "--password",
                envvar=ENV_PASSWORD,
                show_envvar=True,
                help="Its password (from the environment, it stays out of the process list).",
            ),
            _option(
                "--read-only",
                is_flag=True,
                help="Connect without the right to command: reads and states only.",
            ),
        )
    ):
        func = option(func)
    return func


def remote_from(kwargs: dict[str, Any]) -> Remote | None:
    """Take the options of :func:`remote_options` out of a command's ``kwargs``: the bus they name,
    or None without ``--remote``.

    Raises:
        click.UsageError: ``--endpoint``, ``--user``, ``--password`` or ``--read-only`` without
            ``--remote`` on the command line, a target that is not ``NODE/BUS``, or a user without a
            password (exit 2).
    """
    target, endpoints, user, password, read_only = (kwargs.pop(name) for name in _NAMES)
    ctx = click.get_current_context()
    if target is None:
        given = [
            f"--{name.replace('_', '-').removesuffix('s')}"
            for name in _NAMES[1:]
            if ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
        ]
        if given:
            raise click.UsageError(f"{', '.join(given)}: for a bus on a bridge, with --remote NODE/BUS")
        return None
    with remote_extra():
        from servobus.remote.keys import check_name

    node, slash, bus = target.partition("/")
    try:
        if not slash:
            raise ValueError(f"{target!r} is not NODE/BUS")
        check_name("node", node)
        check_name("bus", bus)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--remote") from None
    if (user is None) != (password is None):
        raise click.UsageError(
            f"--user and --password go together (or {ENV_USER} and {ENV_PASSWORD}): give both"
        )
    family = ctx.params.get("family") if _given(ctx, "family") else None
    return Remote(node, bus, tuple(endpoints) or (_default(),), user, password, read_only, family)


def _given(ctx: click.Context, name: str) -> bool:
    return ctx.get_parameter_source(name) not in (None, click.core.ParameterSource.DEFAULT)


class RemoteCliMotor:
    """A motor on a bridge as the CLI's helpers use a :class:`~servobus.bus.Motor`: its id, its codec
    (bound here in the bridge's family, revision and link, to build and check commands), ``request``.
    """

    __slots__ = ("codec", "motor_id", "remote")

    def __init__(self, motor: RemoteMotor) -> None:
        self.remote = motor
        self.motor_id = motor.motor_id
        self.codec = motor.family.bind(motor.motor_id, revision=motor.revision, link=motor.link)

    async def request(self, command: Command[Any], *, timeout_s: float | None = None) -> Any:
        """The bridge runs ``command`` on its Bus: the reply, or the error raised there."""
        return await self.remote.request(command, timeout_s=timeout_s)


@contextlib.asynccontextmanager
async def open_remote(
    ids: tuple[int, ...], remote: Remote, *, read_only: bool = False, valid_for_s: float = 0.1
) -> AsyncIterator[tuple[RemoteBus, list[RemoteCliMotor]]]:
    """The bridge's bus and its motors ``ids`` (``--ids``; all of the bus's when empty).

    Raises:
        click.UsageError: an id the bus has not, or a motor not of ``--family`` (exit 2).
        RemoteError: no bridge reachable, no such node or bus (exit 1).
    """
    async with remote.connect(read_only=read_only, valid_for_s=valid_for_s) as bus:
        wanted = ids or tuple(sorted(bus.motors))
        with refused():
            found = [bus.motor(remote.family, i) if remote.family else bus.motor(i) for i in wanted]
        yield bus, [RemoteCliMotor(motor) for motor in found]

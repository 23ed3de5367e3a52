"""``servobus bridge``: local buses served to other computers over Zenoh (:class:`servobus.remote.Bridge`).

One real bus (the usual connection options: ``-i/-c``, ``--port``, with ``--family`` and ``--ids``) or
``--sim N --buses K``: N simulated motors in-process, spread over K simulated buses as the demo spreads
them (``sim1`` .. ``simK``, motors 1.. on each). The bridge listens on ``--listen`` (loopback by
default) and refuses to listen beyond this host without access control (``--users`` and/or mutual
TLS, with ``--commander``/``--reader`` names) unless ``--insecure``; the Zenoh configuration is
:func:`servobus.remote.security.bridge_config`'s, checked before any bus is opened.

It serves until Ctrl-C or SIGTERM, then leaves its Buses through their safe stop: the motors a
client still commanded get their stop, and the line on stderr says which. Clients reach it with
``servobus status --remote NODE/BUS`` (and the other ``--remote`` commands) or
:func:`servobus.remote.connect`.
"""

from __future__ import annotations

import contextlib
import re
import socket
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import anyio
import click

from servobus.bus import Bus, Motor
from servobus.cli._connect import Connection, connection_options, note_exit
from servobus.cli._motors import run, stop_scope
from servobus.cli._output import SETTINGS, FloatRange, examples, refused
from servobus.cli._remote import remote_extra

if TYPE_CHECKING:
    from servobus.remote.security import Access

__all__ = ["bridge", "default_node"]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"  # (servobus.remote.security's, without importing Zenoh: a test)

_File = click.Path(exists=True, dir_okay=False, path_type=Path)


def default_node() -> str:
    """This host's name as a node name (``keys.check_name``'s rules): its first label, every other
    character than letters, digits, ``_.-`` made ``-``, leading ``_.-`` dropped, at most 64."""
    host = socket.gethostname().split(".")[0]
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", host).lstrip("_.-")[:64]
    return name or "servobus"


def _bus_name(conn: Connection) -> str:
    """A real bus's name on the bridge: its channel's or port's last path part, made a valid name."""
    where = conn.port or conn.channel or conn.interface or "bus"
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", where.rstrip("/").rsplit("/", 1)[-1]).lstrip("_.-")[:64]
    return name or "bus"


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus bridge --sim 32 --buses 4 --node demo       # sim1..sim4, 8 motors each",
        "servobus bridge -i socketcan -c can0 --ids 1-6 --node arm",
        "servobus bridge -i socketcan -c can0 --node arm --listen tcp/0.0.0.0:7447 \\",
        "    --users users.txt --commander alice --reader bob",
        "servobus status --remote demo/sim1                    # in another terminal",
    ),
)
@connection_options
@click.option(
    "--buses",
    type=click.IntRange(1, 32),
    help="With --sim N: spread the N motors over this many simulated buses [default: 1].",
)
@click.option(
    "--bus-name",
    help="The bus's name on the bridge [default: sim1.. with --sim (this name plus 1..K), else the "
    "channel's or port's].",
)
@click.option("--node", help="This bridge's node name, NODE in NODE/BUS [default: the host name].")
@click.option(
    "--listen",
    multiple=True,
    metavar="ENDPOINT",
    help=f"A Zenoh endpoint to listen on; repeat for several [default: {DEFAULT_ENDPOINT}].",
)
@click.option("--users", type=_File, help="Zenoh usrpwd dictionary: one user:password a line.")
@click.option(
    "--commander", multiple=True, metavar="NAME", help="A user (or TLS common name) who may command."
)
@click.option(
    "--reader", multiple=True, metavar="NAME", help="A user (or TLS common name) who may only read."
)
@click.option("--tls-cert", type=_File, help="The bridge's certificate (PEM), for tls/ endpoints.")
@click.option("--tls-key", type=_File, help="Its private key (PEM).")
@click.option("--tls-ca", type=_File, help="The CA (PEM) that signs the clients' certificates (mutual TLS).")
@click.option("--zenoh-config", type=_File, help="A Zenoh JSON5 configuration to start from.")
@click.option(
    "--insecure",
    is_flag=True,
    help="Listen beyond this host without access control: anyone who reaches it may command the motors.",
)
@click.option(
    "--hz",
    type=FloatRange(min=1, max=10_000),
    help="The rate at which each bus sends its held set-points [default: the Bridge's, 1000].",
)
@click.option(
    "--state-hz",
    type=FloatRange(min=0.1, max=10_000),
    help="The most states published per motor per second [default: the Bridge's, 100].",
)
@click.option(
    "--stop-after-ms",
    type=FloatRange(min=0, max=60_000),
    help="How long a motor's set-point may be stale before it is stopped [default: the Bridge's, 50].",
)
@click.option("--allow-takeover", is_flag=True, help="A client may command a motor another client holds.")
def bridge(
    conn: Connection,
    buses: int | None,
    bus_name: str | None,
    node: str | None,
    listen: tuple[str, ...],
    users: Path | None,
    commander: tuple[str, ...],
    reader: tuple[str, ...],
    tls_cert: Path | None,
    tls_key: Path | None,
    tls_ca: Path | None,
    zenoh_config: Path | None,
    insecure: bool,
    hz: float | None,
    state_hz: float | None,
    stop_after_ms: float | None,
    allow_takeover: bool,
) -> None:
    """Serve local buses over Zenoh to other computers until Ctrl-C or SIGTERM.

    Loopback only by default; beyond this host only with --users and/or --tls-cert/--tls-key/--tls-ca
    (with --commander/--reader), or --insecure. On exit the buses send their safe stop.
    """
    with remote_extra():
        from servobus.remote.keys import check_name
        from servobus.remote.security import bridge_config

    node = node or default_node()
    try:
        check_name("node", node)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--node") from None
    endpoints = listen or (DEFAULT_ENDPOINT,)
    with refused():  # InsecureListen is a ValueError: one line, exit 2, nothing opened
        config = bridge_config(
            node,
            endpoints,
            _access(users, commander, reader, tls_cert, tls_key, tls_ca),
            insecure=insecure,
            config_file=zenoh_config,
        )
    layout = _layout(conn, buses, bus_name)
    for name, _ in layout:
        try:
            check_name("bus", name)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--bus-name") from None
    options: dict[str, Any] = {"allow_takeover": allow_takeover}
    if hz is not None:
        options["hz"] = hz
    if state_hz is not None:
        options["state_hz"] = state_hz
    if stop_after_ms is not None:
        options["stop_after_s"] = stop_after_ms / 1000.0
    signalled = run(_serve(conn, node, layout, endpoints, config, options))
    from servobus.cli import safe_exits, stopped_by

    by = f" by {stopped_by()}" if signalled else ""
    click.echo(f"servobus bridge: {node} stopped{by}{safe_exits()}", err=True)


def _access(
    users: Path | None,
    commanders: Sequence[str],
    readers: Sequence[str],
    tls_cert: Path | None,
    tls_key: Path | None,
    tls_ca: Path | None,
) -> Access | None:
    """The bridge's access control from the options (None without any of them).

    Raises:
        click.UsageError: what :class:`~servobus.remote.security.Access` refuses (exit 2).
    """
    if users is None and not (commanders or readers) and (tls_cert, tls_key, tls_ca) == (None, None, None):
        return None
    from servobus.remote.security import Access

    with refused():
        return Access(
            commanders=frozenset(commanders),
            readers=frozenset(readers),
            users_file=users,
            tls_cert=tls_cert,
            tls_key=tls_key,
            tls_ca=tls_ca,
        )


def _layout(conn: Connection, buses: int | None, bus_name: str | None) -> list[tuple[str, tuple[int, ...]]]:
    """Each bus's name and motor ids: ``--sim N --buses K`` spread as the demo does (motors 1.. on
    each), else the one bus with ``conn.motor_ids``.

    Raises:
        click.UsageError: ``--buses`` without ``--sim``, more buses than motors, or with ``--ids``.
    """
    if conn.sim is None:
        if buses is not None:
            raise click.UsageError("--buses is for simulated buses: give --sim N too")
        return [(bus_name or _bus_name(conn), conn.motor_ids)]
    count = buses or 1
    if count > conn.sim:
        raise click.BadParameter(
            f"{count} buses for {conn.sim} motors: at most one bus per motor", param_hint="--buses"
        )
    if count > 1 and conn.ids:
        raise click.UsageError("--ids with --buses: the simulated buses get motors 1.. each; drop --ids")
    if count == 1:
        return [(bus_name or "sim1", conn.motor_ids)]
    per_bus = [conn.sim // count + (1 if b < conn.sim % count else 0) for b in range(count)]
    return [(f"{bus_name or 'sim'}{b + 1}", tuple(range(1, n + 1))) for b, n in enumerate(per_bus)]


async def _serve(
    conn: Connection,
    node: str,
    layout: Sequence[tuple[str, tuple[int, ...]]],
    endpoints: Sequence[str],
    config: Any,
    options: dict[str, Any],
) -> bool:
    """Open the buses and serve them until a signal; whether one came."""
    from servobus.remote import Bridge

    async with contextlib.AsyncExitStack() as stack:
        opened: list[Bus] = []

        def noted() -> None:
            for bus in opened:
                note_exit(bus)

        stack.callback(noted)  # (first in, so it runs after every Bus was left)
        served: dict[str, tuple[Bus, list[Motor]]] = {}
        for name, ids in layout:
            # (--sim N: the first N ids simulated)
            transport = conn.transport() if conn.sim is None else conn.sim_transport(ids[: conn.sim], name)
            bus = await stack.enter_async_context(Bus(transport, name=name, limits=conn.limits))
            opened.append(bus)
            served[name] = (bus, [bus.motor(conn.family, i, **conn.bind_options()) for i in ids])
        with stop_scope() as stopping:
            async with Bridge(node, served, config=config, **options):
                listed = ", ".join(f"{node}/{name} ({len(ids)} motors)" for name, ids in layout)
                click.echo(f"serving {listed} on {', '.join(endpoints)}")
                await anyio.sleep_forever()
    return bool(stopping.cancelled_caught)

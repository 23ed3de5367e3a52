"""``servobus dashboard``: every motor of a bus live in a browser (:mod:`servobus.dashboard`).

On a local bus (``-i/-c``, ``--port``) the motors are read at ``--hz`` by a :class:`servobus.Loop`
(reads only: nothing is commanded unless the page's stop is pressed, with ``--allow-commands``); on
``--sim N`` the simulated motors follow the demo's sine so there is something to see (``--still``:
they are only read); on ``--remote NODE/BUS`` the page shows what the bridge publishes. The page is
served on 127.0.0.1 (``--listen``), beyond this host only with ``--users`` or ``--insecure``.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import anyio
import click

from servobus.cli._connect import Connection, open_bus, remote_connection_options
from servobus.cli._motors import BACKENDS, run, stop_scope
from servobus.cli._output import SETTINGS, FloatRange, examples, refused
from servobus.cli._page import dashboard_extra, parse_listen
from servobus.errors import ServobusError
from servobus.protocols import Command

if TYPE_CHECKING:
    import socket

    from servobus.bus import Bus, Motor
    from servobus.cli._remote import Remote
    from servobus.dashboard import Access, Dashboard, Watched
    from servobus.loop import LoopTick

__all__ = ["dashboard"]

_File = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus dashboard --sim 4                     # open the URL it prints",
        "servobus dashboard --sim 4 --allow-commands    # with stop and off buttons",
        "servobus dashboard -i socketcan -c can0 --ids 1-6 --hz 50",
        "servobus dashboard --remote arm/can0           # what a bridge publishes",
        "servobus dashboard -i socketcan -c can0 --listen 0.0.0.0:8765 --users users.txt --commander alice",
    ),
)
@remote_connection_options
@click.option(
    "--listen",
    default="127.0.0.1:8765",
    show_default=True,
    metavar="HOST:PORT",
    help="Where the page is served (port 0: any free port); beyond this host only with --users "
    "or --insecure.",
)
@click.option("--users", type=_File, help="user:password lines: the page asks for one (HTTP Basic).")
@click.option(
    "--commander", multiple=True, metavar="NAME", help="A user who may press stop (others only read)."
)
@click.option("--tls-cert", type=_File, help="Serve HTTPS with this certificate (PEM)...")
@click.option("--tls-key", type=_File, help="...and its private key (PEM).")
@click.option(
    "--insecure",
    is_flag=True,
    help="Listen beyond this host without --users: anyone who reaches it sees the motors.",
)
@click.option(
    "--allow-commands",
    is_flag=True,
    help="The page's stop and off buttons work (default: read-only; it can never command anything else).",
)
@click.option(
    "--hz",
    type=FloatRange(min=1, max=1000),
    default=100.0,
    show_default=True,
    help="How often the motors are read (and, with --sim, sent their set-point).",
)
@click.option(
    "--update-hz",
    type=FloatRange(min=0.5, max=100),
    default=30.0,
    show_default=True,
    help="The most updates per second the page gets.",
)
@click.option("--still", is_flag=True, help="With --sim: the simulated motors stay still (only read).")
@click.option(
    "--duration",
    type=FloatRange(min=0, min_open=True),
    help="Serve this many seconds [default: until Ctrl-C].",
)
@click.option(
    "--backend", type=click.Choice(BACKENDS), default="asyncio", show_default=True, help="The event loop."
)
def dashboard(
    conn: Connection,
    remote: Remote | None,
    listen: str,
    users: Path | None,
    commander: tuple[str, ...],
    tls_cert: Path | None,
    tls_key: Path | None,
    insecure: bool,
    allow_commands: bool,
    hz: float,
    update_hz: float,
    still: bool,
    duration: float | None,
    backend: str,
) -> None:
    """Serve a live web page of the motors: their state and faults, live plots of any field beside its
    set-point, the bus load and counters, a running loop's tick lateness and state age, and the raw
    frames decoded (like python-can's viewer).

    Its first line is the page's URL. Read-only by default: with --allow-commands the page gets stop
    and off buttons, and nothing else. Ctrl-C or SIGTERM ends it; motors it commanded get their stop.
    """
    with dashboard_extra():
        from servobus.dashboard import Access, listening_socket

    if (tls_cert is None) != (tls_key is None):
        raise click.UsageError("--tls-cert and --tls-key go together")
    if remote is not None and remote.read_only and allow_commands:
        raise click.UsageError(
            "--read-only and --allow-commands: the page's stop needs a commanding connection"
        )
    if commander and users is None:
        raise click.UsageError("--commander names a user of --users: give --users")
    host, port = parse_listen(listen)
    with refused():  # a bad users file, an unknown commander, InsecureListen: one line, exit 2
        access = Access.from_file(users, commander) if users is not None else None
        if access is not None and allow_commands is False and commander:
            raise ValueError("--commander: the page is read-only without --allow-commands")
        if access is not None and allow_commands and not commander:
            raise ValueError("--allow-commands with --users: name who may press stop (--commander NAME)")
        if tls_cert is not None and tls_key is not None:
            _check_tls(tls_cert, tls_key)
        sock = listening_socket(host, port, access=access, insecure=insecure)
    served = _Served(sock, access, tls_cert, tls_key, allow_commands, update_hz)
    with sock:
        if remote is not None:
            signalled = run(_remote(served, conn, remote, duration), backend=backend)
        else:
            moving = conn.sim is not None and not still
            signalled = run(_local(served, conn, hz, moving, duration), backend=backend)
    from servobus.cli import safe_exits, stopped_by

    by = f" by {stopped_by()}" if signalled else ""
    click.echo(f"servobus dashboard: stopped{by}{safe_exits()}", err=True)


def _check_tls(cert: Path, key: Path) -> None:
    """The certificate and key load (before anything is opened or printed).

    Raises:
        ValueError: they do not, with why.
    """
    import ssl

    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(cert, key)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(f"--tls-cert {cert} --tls-key {key}: {exc}") from None


class _Served:
    """The page's socket and serving options, and the Dashboard made from them."""

    def __init__(
        self,
        sock: socket.socket,
        access: Access | None,
        tls_cert: Path | None,
        tls_key: Path | None,
        allow_commands: bool,
        update_hz: float,
    ) -> None:
        from servobus.dashboard import Dashboard

        self.sock, self.access, self.tls = sock, access, (tls_cert, tls_key)
        self.stopped: set[int] = set()  # ids of the motors a page stopped (the sine leaves them be)
        self.dash: Dashboard = Dashboard(
            allow_commands=allow_commands, update_hz=update_hz, on_stop=self._held
        )

    def _held(self, motors: Sequence[Watched]) -> None:
        self.stopped.update(id(w.motor) for w in motors)

    def announce(self, what: str) -> None:
        from servobus.dashboard import url_of

        url = url_of(self.sock, tls=self.tls[0] is not None)
        mode = "stop and off allowed" if self.dash.allow_commands else "read-only"
        click.echo(f"servobus dashboard: {url} ({what}; {mode}; Ctrl-C stops)")

    def serving(self) -> contextlib.AbstractAsyncContextManager[str]:
        """The page served while inside (:func:`servobus.dashboard.serving`)."""
        from servobus.dashboard import serving

        cert, key = self.tls
        return serving(self.dash, self.sock, access=self.access, certfile=cert, keyfile=key)


async def _local(served: _Served, conn: Connection, hz: float, moving: bool, duration: float | None) -> bool:
    """Open the bus, serve its page and poll (or move) its motors until ``duration`` or a signal;
    whether a signal came."""
    from servobus.loop import Loop

    dash = served.dash
    reads = _reads(conn.family)
    async with open_bus(conn, wrap=dash.tap) as (bus, motors):
        dash.watch(bus, name=bus.name if conn.sim is None else "sim")
        loop = Loop(hz, timeout_s=conn.timeout_s)
        dash.watch_loop(loop)
        simulated = len(conn.sim_ids)  # (--ids may name more motors than --sim N: the others are silent)
        what = f"{len(motors)} {'simulated ' if simulated == len(motors) else ''}{conn.family} motor(s)"
        what += f", {simulated} simulated" if 0 < simulated < len(motors) else ""
        motion = _Motion(bus, motors, conn.family, served.stopped) if moving else None
        with stop_scope() as stopping:
            async with served.serving():
                served.announce(what + (", moving" if moving else ""))
                if motion is not None:
                    await motion.start(conn.timeout_s)
                async with loop:
                    start: float | None = None
                    async for tick in loop:
                        start = tick.deadline if start is None else start
                        if duration is not None and tick.deadline - start >= duration:
                            break
                        for motor in motors:
                            if motion is not None and id(motor) not in served.stopped:
                                motion.command(tick, motor, tick.deadline - start)
                            elif reads:
                                for read in reads:
                                    tick.command(motor, read)
    return bool(stopping.cancelled_caught)


def _reads(family: str) -> list[Command]:
    """The status reads each motor is sent (none where the family has no read-only request: hollow's
    state comes with each set-point's reply; the page then shows what it hears). A command holds no
    motor id: the same ones go to every motor."""
    from servobus.cli._families import cli_part
    from servobus.protocols import get_family

    found = get_family(family)
    return [read() for read in cli_part(found).status_reads(found)]


def _reads_of(motors: Sequence[Any]) -> list[tuple[Any, Command]]:
    """Each bridge motor's status reads (its family's; none for a family without)."""
    by_family: dict[str, list[Command]] = {}
    for motor in motors:
        if motor.codec.family not in by_family:
            by_family[motor.codec.family] = _reads(motor.codec.family)
    return [(motor, read) for motor in motors for read in by_family[motor.codec.family]]


class _Motion:
    """The demo's sine for the simulated motors (``servobus demo``'s), but for the motors a page stopped."""

    def __init__(self, bus: Bus, motors: list[Motor], family: str, stopped: set[int]) -> None:
        from servobus.cli.demo import _parts, _Sine

        self.bus, self.motors, self.stopped = bus, motors, stopped
        self.parts = _parts(family)
        self.sine = _Sine(motors, self.parts)
        self.index = {id(m): n for n, m in enumerate(motors)}

    async def start(self, timeout_s: float | None) -> None:
        from servobus.cli.demo import _start

        going = [m for m in self.motors if id(m) not in self.stopped]  # (a page may stop one already)
        if going:
            await _start([(self.bus, going)], self.sine, timeout_s)

    def command(self, tick: LoopTick, motor: Motor, t: float) -> None:
        angle = self.sine.target(self.index[id(motor)], t)
        command: Command = self.parts.setpoint(motor, angle)
        tick.command(motor, command)


async def _remote(served: _Served, conn: Connection, remote: Remote, duration: float | None) -> bool:
    """Connect to the bridge, serve its bus's page until ``duration`` or a signal; whether one came."""
    from servobus.cli._remote import open_remote

    dash = served.dash
    async with open_remote(conn.ids, remote, read_only=not dash.allow_commands) as (bus, motors):
        dash.watch(bus, name=remote.target)
        with stop_scope() as stopping:
            async with served.serving():
                served.announce(f"{len(motors)} motor(s) of {remote.target}")
                reads = _reads_of(motors)
                with anyio.move_on_after(math.inf if duration is None else duration):
                    while True:  # the bridge's figures and the motors' status, once a second
                        with contextlib.suppress(ServobusError):  # (a slow bridge: next second)
                            dash.board.set_metrics(remote.target, await bus.metrics())
                        for motor, read in reads:  # (between the states the bridge publishes)
                            with contextlib.suppress(ServobusError):
                                reply = await motor.request(read, timeout_s=conn.timeout_s)
                                dash.board.note(remote.target, motor.remote, reply)
                        await anyio.sleep(1.0)
    return bool(stopping.cancelled_caught)

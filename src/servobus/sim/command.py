"""The simulator's command line: one click command, run as ``servobus sim`` and ``python -m servobus.sim``.

Simulated motors on a pseudo-terminal, for any tool to talk to. The first line printed is the path
a host should open; it serves until interrupted (Ctrl-C, SIGTERM or SIGHUP)::

    servobus sim --family myactuator --motors 4 --slcan
    servobus sim --family myactuator --motors 4 --rs485 --baud 1000000
    servobus sim --family hollow --motors 4 --rs485          # converter, transparent, 1 Mbaud
    servobus sim --family hollow --motors 4 --rs485 --modbus # converter, Modbus RTU, 19200
    servobus sim --family lk --motors 8 --revision V2_35

Every argument is checked before anything is opened: a bad one, or flags that contradict each
other, print one line (``servobus.sim: error: ...``) to stderr and exit with status 2, under either
name (the command answers its own usage errors, so its caller's error format never applies).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import anyio
import anyio.abc
import click

from servobus.limits import LimitBook
from servobus.limits import load as load_limits
from servobus.protocols import available_families, get_family
from servobus.sim.attach import serve_rs485, serve_slcan
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.family import Setup, SimFamily, SimOptions
from servobus.sim.limits import bound
from servobus.sim.pty import PtyPort

__all__ = ["ERROR_PREFIX", "EXIT_USAGE", "Served", "main", "sim"]

ERROR_PREFIX = "servobus.sim: error: "
EXIT_USAGE = 2

EPILOG = """Examples:

\b
  servobus sim --family myactuator --motors 4 --slcan      # prints /dev/pts/N
  servobus status -i slcan -c /dev/pts/N --ids 1-4         # ... in another terminal
  servobus sim --family myactuator --motors 4 --rs485 --baud 1000000
  servobus sim --family lk --motors 8 --revision V2_35 --link /tmp/can0
  python -m servobus.sim --family hollow --motors 4 --rs485 --modbus
"""


@dataclass(frozen=True, slots=True)
class Served:
    """What the checked arguments describe: the family's simulator part, its options, the motors."""

    family: str
    sim: SimFamily
    options: SimOptions
    ids: range
    revision: Enum
    link: Path | None
    limits: LimitBook | None = None


if TYPE_CHECKING:
    _StrParam = click.ParamType[str]
else:  # (click's ParamType is generic from 8.4 on; the project supports 8.1)
    _StrParam = click.ParamType


class _FamilyName(_StrParam):
    """A family's name, among those installed when the command runs (plug-ins included)."""

    name = "family"

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        # (``ctx``: click 8.2 and later pass it)
        return "[" + "|".join(sorted(available_families())) + "]"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        names = sorted(available_families())
        if value not in names:
            self.fail(f"{value!r} is not one of {', '.join(map(repr, names))}", param, ctx)
        return str(value)


class _OneLineCommand(click.Command):
    """A click command that answers a usage error itself: one line on stderr, exit status 2."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as exc:
            _refuse(exc)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:
            _refuse(exc)


def _refuse(exc: click.UsageError) -> NoReturn:
    click.echo(ERROR_PREFIX + " ".join(exc.format_message().split()), err=True)
    raise click.exceptions.Exit(EXIT_USAGE)


@click.command(
    "sim",
    cls=_OneLineCommand,
    epilog=EPILOG,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
)
@click.option("--family", type=_FamilyName(), required=True, help="the motors' family")
@click.option("--motors", type=int, default=1, show_default=True, help="how many motors")
@click.option("--first-id", type=int, default=1, show_default=True, help="id of the first motor")
@click.option("--slcan", is_flag=True, help="a simulated SLCAN USB-CAN adapter (default)")
@click.option("--rs485", is_flag=True, help="the family's RS485 line (not with --slcan)")
@click.option("--baud", type=int, help="RS485 baud rate, where the line has several (default: the family's)")
@click.option("--revision", help="protocol revision, e.g. V2_35 (default: the family's newest)")
@click.option("--fd", is_flag=True, help="CAN FD motors, over SLCAN (where the family has them)")
@click.option("--modbus", is_flag=True, help="the RS485 line in Modbus RTU mode (where the family has it)")
@click.option("--link", help="also create this symlink to the pty (the path must not exist)")
@click.option(
    "--limits",
    "limits_file",
    type=click.Path(dir_okay=False),
    help="a limits file (servobus.limits): the motors' current, speed and acceleration stay within it",
)
def sim(
    family: str,
    motors: int,
    first_id: int,
    slcan: bool,
    rs485: bool,
    baud: int | None,
    revision: str | None,
    fd: bool,
    modbus: bool,
    link: str | None,
    limits_file: str | None,
) -> None:
    """Simulated motors on a pseudo-terminal (SLCAN adapter or RS485 line) for any tool to open.

    Prints the path to open on its first line, then serves until Ctrl-C, SIGTERM or SIGHUP (which
    also remove its --link, if it still points at this pty).
    """
    if slcan and rs485:
        raise click.UsageError("--rs485: not allowed with --slcan")
    options = SimOptions(rs485=rs485, fd=fd, modbus=modbus, baud=baud)
    served = check(family, options, first_id, motors, revision, link)
    if limits_file is not None:
        try:
            served = dataclasses.replace(served, limits=load_limits(limits_file))
        except (OSError, ValueError) as exc:
            raise click.UsageError(f"--limits {limits_file}: {exc}") from None
    setup = build(served)
    with contextlib.suppress(KeyboardInterrupt):  # (a Ctrl-C before the signals are taken)
        anyio.run(run, served, setup)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m servobus.sim``: the same command, its exit status returned."""
    args = list(sys.argv[1:] if argv is None else argv)
    code = sim.main(args=args, prog_name="python -m servobus.sim", standalone_mode=False)
    return code if isinstance(code, int) and not isinstance(code, bool) else 0


def check(
    family: str, options: SimOptions, first_id: int, motors: int, revision: str | None, link: str | None
) -> Served:
    """Refuse what cannot be served, before anything is opened.

    Raises:
        click.UsageError: a bad value or contradictory flags (the message names the argument).
    """
    plugin = get_family(family)
    try:
        part = plugin.part("sim")
    except LookupError as exc:
        raise click.UsageError(f"--family {family}: {exc}") from None
    if not isinstance(part, SimFamily):
        raise click.UsageError(f"--family {family}: its sim part is {type(part).__name__}, not a SimFamily")
    # the medium and its flags first, then the motors
    try:
        part.check(options)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    if motors < 1:
        raise click.UsageError(f"--motors {motors}: need at least 1 motor")
    allowed = part.motor_ids(options)
    ids = range(first_id, first_id + motors)
    last = ids.stop - 1
    if first_id not in allowed or last not in allowed:
        given = f"--first-id {first_id}"
        given += f" --motors {motors}: ids {first_id}..{last}, but" if motors > 1 else ":"
        note = part.motor_ids_note(options)
        raise click.UsageError(f"{given} {family} motor ids are {allowed.start}..{allowed.stop - 1}{note}")
    # the revision: the family's own parser, case-insensitive ("v2.35", "V2_35")
    if revision is None:
        chosen = plugin.default_revision
    else:
        try:
            chosen = plugin.revision(revision)
        except ValueError as exc:
            raise click.UsageError(f"--revision {revision}: {exc}") from None
    if link is not None:
        _check_link(link)
    return Served(family, part, options, ids, chosen, None if link is None else Path(link))


def _check_link(text: str) -> None:
    link = Path(text)
    if os.path.lexists(link):
        if link.is_symlink():
            what = f"a symlink to {os.readlink(link)}"
        elif link.is_dir():
            what = "a folder"
        else:
            what = "a file"
        raise click.UsageError(
            f"--link {text}: already exists ({what}); the simulator replaces nothing, choose a free path"
        )
    folder = link.parent
    if not folder.is_dir():
        problem = f"{folder} is not a folder" if os.path.lexists(folder) else f"no folder {folder}"
        raise click.UsageError(f"--link {text}: {problem}")


def build(served: Served) -> Setup:
    """The devices ``served`` describes; nothing is opened yet.

    Raises:
        click.UsageError: a device refused its settings (a check above missed a rule).
    """
    try:
        setup = served.sim.devices(served.ids, served.revision, served.options)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    if served.limits is not None:
        bound([*setup.can_devices, *setup.serial_devices], served.limits)
    return setup


def make_link(link: Path, target: str) -> None:
    """Create the symlink ``link`` -> ``target``; never replaces anything (the create is exclusive).

    Raises:
        click.UsageError: ``link`` appeared meanwhile, or the folder refused the symlink.
    """
    try:
        os.symlink(target, link)
    except FileExistsError:
        raise click.UsageError(f"--link {link}: already exists; the simulator replaces nothing") from None
    except OSError as exc:
        raise click.UsageError(f"--link {link}: cannot create it: {exc.strerror}") from None


def remove_link(link: Path, target: str) -> None:
    """Remove ``link`` only if it is still the symlink to ``target`` this process made."""
    with contextlib.suppress(OSError):  # gone or unreadable: someone else's now, leave it
        if os.readlink(link) == target:
            link.unlink()


async def serve(setup: Setup, port: PtyPort) -> None:
    """Serve ``setup``'s devices on ``port`` until cancelled."""
    if setup.serial_devices:
        await serve_rs485(setup.serial_devices, port, baud=setup.baud)
    else:
        await serve_slcan(CoreCanNetwork(setup.can_devices), port)


async def run(served: Served, setup: Setup) -> None:
    """Open the pty (and the link), print what a host should open, serve until stopped.

    SIGTERM and SIGHUP stop it as Ctrl-C does: the pty is closed and the link removed, if it still
    points at this pty. The signal handlers are in place before the path is printed, so a caller that
    stops the simulator as soon as it has read the path never leaves a link behind.

    Raises:
        click.UsageError: the link could not be created (it appeared after the checks, or the folder
            refused).
    """
    failed: list[click.UsageError] = []
    async with anyio.create_task_group() as group:
        # (the signals are taken before the path is printed; one cancels the group, serving ends)
        await group.start(_until_signalled, group.cancel_scope, name="servobus.sim signals")
        try:
            await _serve_on_a_pty(served, setup)
        except click.UsageError as exc:  # (out of the group as itself, not in an exception group)
            failed.append(exc)
        group.cancel_scope.cancel()
    if failed:
        raise failed[0]


async def _until_signalled(
    scope: anyio.CancelScope, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
) -> None:
    """Cancel ``scope`` on SIGTERM, SIGHUP or Ctrl-C (taken here, on asyncio and trio alike)."""
    with anyio.open_signal_receiver(signal.SIGTERM, signal.SIGHUP, signal.SIGINT) as signals:
        task_status.started()
        async for _ in signals:
            scope.cancel()  # (a second one while the pty closes changes nothing)


async def _serve_on_a_pty(served: Served, setup: Setup) -> None:
    link = served.link
    port = PtyPort()
    made_link = False
    try:
        if link is not None:
            make_link(link, port.path)
            made_link = True
        print(port.path if link is None else link, flush=True)
        kind = "RS485 line" if served.options.rs485 else "SLCAN adapter"
        print(
            f"{len(served.ids)} simulated {served.family} motor(s) behind a {kind}; Ctrl-C stops",
            file=sys.stderr,
        )
        await serve(setup, port)
    finally:
        port.close()
        if made_link and link is not None:
            remove_link(link, port.path)

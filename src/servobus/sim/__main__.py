"""``python -m servobus.sim``: simulated motors on a pseudo-terminal, for any tool to talk to.

Prints the device path a host should open on its first line of output, then serves until
interrupted (Ctrl-C, SIGTERM or SIGHUP)::

    python -m servobus.sim --family myactuator --motors 4 --slcan
    python -m servobus.sim --family myactuator --motors 4 --rs485 --baud 1000000
    python -m servobus.sim --family hollow --motors 4 --slcan
    python -m servobus.sim --family hollow --motors 4 --rs485          # converter, transparent, 1 Mbaud
    python -m servobus.sim --family hollow --motors 4 --rs485 --modbus # converter, Modbus RTU, 19200
    python -m servobus.sim --family lk --motors 8 --revision V2_35

``--slcan`` presents a USB-CAN adapter speaking SLCAN (python-can: ``interface="slcan"``);
``--rs485`` presents the family's RS485 line. ``--link PATH`` also creates a symlink to the pty at a
path that must not exist yet; it is removed on exit if it still points at this pty.

Every argument is checked before anything is opened: a bad one, or flags that contradict each
other, print one line (``servobus.sim: error: ...``) to stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import anyio
import anyio.abc

from servobus.protocols import available_families, get_family
from servobus.sim.attach import serve_rs485, serve_slcan
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.family import Setup, SimFamily, SimOptions
from servobus.sim.pty import PtyPort

ERROR_PREFIX = "servobus.sim: error: "
EXIT_USAGE = 2


class UsageError(Exception):
    """An argument the simulator refuses; the message is the one line the user sees."""


class _Parser(argparse.ArgumentParser):
    """argparse, but an error is one line on stderr (no usage block) and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{ERROR_PREFIX}{message}\n")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse and check ``argv``; on a bad argument print one line and exit 2 (``SystemExit(2)``).

    ``args.revision`` comes back as the family's revision enum member (the default filled in),
    ``args.sim`` as the family's simulator part and ``args.options`` as its :class:`SimOptions`.
    """
    parser = _Parser(prog="python -m servobus.sim", description=__doc__.split("\n\n")[0])
    parser.add_argument("--family", choices=sorted(available_families()), required=True)
    parser.add_argument("--motors", type=int, default=1, help="how many motors (default 1)")
    parser.add_argument("--first-id", type=int, default=1, help="id of the first motor (default 1)")
    medium = parser.add_mutually_exclusive_group()
    medium.add_argument("--slcan", action="store_true", help="a simulated SLCAN USB-CAN adapter (default)")
    medium.add_argument("--rs485", action="store_true", help="the family's RS485 line")
    parser.add_argument(
        "--baud", type=int, help="RS485 baud rate, where the line has several (default: the family's)"
    )
    parser.add_argument("--revision", help="protocol revision, e.g. V2_35 (default: the family's newest)")
    parser.add_argument(
        "--fd", action="store_true", help="CAN FD motors, over SLCAN (where the family has them)"
    )
    parser.add_argument(
        "--modbus", action="store_true", help="the RS485 line in Modbus RTU mode (where the family has it)"
    )
    parser.add_argument("--link", help="also create this symlink to the pty (the path must not exist)")
    args = parser.parse_args(argv)
    try:
        check_args(args)
    except UsageError as exc:
        parser.error(str(exc))
    return args


def check_args(args: argparse.Namespace) -> None:
    """Refuse what cannot be served, before anything is opened; fills in ``args.revision``,
    ``args.sim`` (the family's simulator part) and ``args.options``.

    Raises:
        UsageError: a bad value or contradictory flags (the message names the argument).
    """
    family = get_family(args.family)
    try:
        sim = family.part("sim")
    except LookupError as exc:
        raise UsageError(f"--family {args.family}: {exc}") from None
    if not isinstance(sim, SimFamily):
        raise UsageError(f"--family {args.family}: its sim part is {type(sim).__name__}, not a SimFamily")
    options = SimOptions(rs485=args.rs485, fd=args.fd, modbus=args.modbus, baud=args.baud)
    # the medium and its flags first, then the motors
    try:
        sim.check(options)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.motors < 1:
        raise UsageError(f"--motors {args.motors}: need at least 1 motor")
    ids = sim.motor_ids(options)
    last = args.first_id + args.motors - 1
    if args.first_id not in ids or last not in ids:
        given = f"--first-id {args.first_id}"
        if args.motors > 1:
            given += f" --motors {args.motors}: ids {args.first_id}..{last}, but"
        else:
            given += ":"
        note = sim.motor_ids_note(options)
        raise UsageError(f"{given} {args.family} motor ids are {ids.start}..{ids.stop - 1}{note}")
    # the revision: the family's own parser, case-insensitive ("v2.35", "V2_35")
    if args.revision is None:
        args.revision = family.default_revision
    else:
        try:
            args.revision = family.revision(args.revision)
        except ValueError as exc:
            raise UsageError(f"--revision {args.revision}: {exc}") from None
    if args.link is not None:
        _check_link(args.link)
    args.sim, args.options = sim, options


def _check_link(text: str) -> None:
    link = Path(text)
    if os.path.lexists(link):
        if link.is_symlink():
            what = f"a symlink to {os.readlink(link)}"
        elif link.is_dir():
            what = "a folder"
        else:
            what = "a file"
        raise UsageError(
            f"--link {text}: already exists ({what}); the simulator replaces nothing, choose a free path"
        )
    folder = link.parent
    if not folder.is_dir():
        problem = f"{folder} is not a folder" if os.path.lexists(folder) else f"no folder {folder}"
        raise UsageError(f"--link {text}: {problem}")


def build(args: argparse.Namespace) -> Setup:
    """The devices ``args`` (checked by :func:`parse_args`) describe; nothing is opened yet.

    Raises:
        UsageError: a device refused its settings (a check above missed a rule).
    """
    ids = range(args.first_id, args.first_id + args.motors)
    try:
        setup: Setup = args.sim.devices(ids, args.revision, args.options)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return setup


def make_link(link: Path, target: str) -> None:
    """Create the symlink ``link`` -> ``target``; never replaces anything (the create is exclusive).

    Raises:
        UsageError: ``link`` appeared meanwhile, or the folder refused the symlink.
    """
    try:
        os.symlink(target, link)
    except FileExistsError:
        raise UsageError(f"--link {link}: already exists; the simulator replaces nothing") from None
    except OSError as exc:
        raise UsageError(f"--link {link}: cannot create it: {exc.strerror}") from None


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


async def run(args: argparse.Namespace, setup: Setup) -> None:
    """Open the pty (and ``args.link``), print what a host should open, serve until stopped.

    SIGTERM and SIGHUP stop it as Ctrl-C does: the pty is closed and the link removed, if it still
    points at this pty. The signal handlers are in place before the path is printed, so a caller that
    stops the simulator as soon as it has read the path never leaves a link behind.

    Raises:
        UsageError: the link could not be created (it appeared after the checks, or the folder refused).
    """
    failed: list[UsageError] = []
    async with anyio.create_task_group() as group:
        # (the signals are taken before the path is printed; one cancels the group, serving ends)
        await group.start(_until_signalled, group.cancel_scope, name="servobus.sim signals")
        try:
            await _serve_on_a_pty(args, setup)
        except UsageError as exc:  # (out of the group as itself, not in an exception group)
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


async def _serve_on_a_pty(args: argparse.Namespace, setup: Setup) -> None:
    link = Path(args.link) if args.link is not None else None
    port = PtyPort()
    made_link = False
    try:
        if link is not None:
            make_link(link, port.path)
            made_link = True
        print(port.path if link is None else link, flush=True)
        kind = "RS485 line" if args.rs485 else "SLCAN adapter"
        print(
            f"{args.motors} simulated {args.family} motor(s) behind a {kind}; Ctrl-C stops", file=sys.stderr
        )
        await serve(setup, port)
    finally:
        port.close()
        if made_link and link is not None:
            remove_link(link, port.path)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        setup = build(args)
        with contextlib.suppress(KeyboardInterrupt):  # (a Ctrl-C before the signals are taken)
            anyio.run(run, args, setup)
    except UsageError as exc:
        print(f"{ERROR_PREFIX}{exc}", file=sys.stderr)
        return EXIT_USAGE
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``servobus sim``: the simulator's pty server, ``python -m servobus.sim`` under the ``servobus`` command.

The arguments go to :mod:`servobus.sim.__main__` as they are (its parser checks them, its server
runs), so the two never differ: the first line printed is the pseudo-terminal to open; a bad
argument is one line and exit 2; Ctrl-C, SIGTERM or SIGHUP stop it (and remove its ``--link``).
"""

from __future__ import annotations

import contextlib
import io

import click

__all__ = ["sim"]

EPILOG = """Examples:

\b
  servobus sim --family myactuator --motors 4 --slcan      # prints /dev/pts/N
  servobus status -i slcan -c /dev/pts/N --ids 1-4         # ... in another terminal
  servobus sim --family myactuator --motors 4 --rs485 --baud 1000000
  servobus sim --family lk --motors 8 --revision V2_35 --link /tmp/can0
"""


@click.command(
    context_settings={"ignore_unknown_options": True, "allow_extra_args": True, "help_option_names": []},
    epilog=EPILOG,
    add_help_option=False,
)
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
@click.pass_context
def sim(ctx: click.Context, args: tuple[str, ...]) -> None:
    """Simulated motors on a pseudo-terminal (SLCAN adapter or RS485 line) for any tool to open.

    Serves until Ctrl-C. The options are python -m servobus.sim's (below with --help).
    """
    from servobus.sim import __main__ as server

    if "-h" in args or "--help" in args:
        click.echo(ctx.get_help())
        click.echo("\nSimulator options (python -m servobus.sim):\n")
        click.echo(_server_help())
        return
    try:
        code = server.main(list(args))
    except SystemExit as exc:  # its parser refused an argument (one line printed, status 2)
        code = exc.code if isinstance(exc.code, int) else 2
    if code:
        raise click.exceptions.Exit(code)


def _server_help() -> str:
    from servobus.sim import __main__ as server

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        server.parse_args(["--help"])
    text = out.getvalue()
    return text[text.index("options:") :] if "options:" in text else text

"""The ``servobus`` command: a bench tool over the Bus (click + rich).

Every subcommand lives in its own module and is imported only when it runs (``servobus --help`` and
shell completion stay fast, and the optional extras, matplotlib and cantools, load only for ``plot``
and ``dbc``). Errors are one line on stderr, without a traceback unless ``--debug``:

==========  ==================================================================================
exit code   meaning
==========  ==================================================================================
0           done (also when stdout was closed early: ``servobus monitor --json | head``)
1           the job failed: a motor did not answer, the adapter was lost, a file did not parse
2           bad usage: an unknown option, a value out of range or beyond --limits, a missing or
            contradictory flag
130         interrupted (Ctrl-C); a command that drives motors (move, speed, torque, mit, demo)
            sends them its safe stop first, and the line says which motors it went to
143         terminated (SIGTERM: systemd, ``docker stop``, ``timeout``): as Ctrl-C, safe stop first
==========  ==================================================================================
"""

from __future__ import annotations

import importlib
import signal
import sys
from collections.abc import Sequence

import click

from servobus import __version__
from servobus.errors import ServobusError

__all__ = ["SAFE_EXITS", "SIGNALLED", "cli", "main", "safe_exits", "stopped_by"]

#: What the Buses of this command sent their commanded motors when their blocks were left, for the
#: line Ctrl-C prints (:func:`servobus.cli._connect.note_exit`): (bus name, family, safe command,
#: the ids that acknowledged it, the ids it left for without an answer, the ids it did not leave for).
SAFE_EXITS: list[tuple[str, str, str, tuple[int, ...], tuple[int, ...], tuple[int, ...]]] = []

#: The signals other than Ctrl-C's that cancelled this command's run (SIGTERM:
#: :func:`servobus.cli._motors.run`), for the line and the exit code (128 + the signal).
SIGNALLED: list[signal.Signals] = []

#: subcommand -> "module:attribute" (imported on first use)
COMMANDS: dict[str, str] = {
    "demo": "servobus.cli.demo:demo",
    "scan": "servobus.cli.scan:scan",
    "status": "servobus.cli.status:status",
    "monitor": "servobus.cli.status:monitor",
    "move": "servobus.cli.setpoints:move",
    "speed": "servobus.cli.setpoints:speed",
    "torque": "servobus.cli.setpoints:torque",
    "mit": "servobus.cli.setpoints:mit",
    "stop": "servobus.cli.oneshots:stop",
    "off": "servobus.cli.oneshots:off",
    "brake": "servobus.cli.oneshots:brake",
    "zero": "servobus.cli.oneshots:zero",
    "set-id": "servobus.cli.oneshots:set_id",
    "clear-errors": "servobus.cli.oneshots:clear_errors",
    "reset": "servobus.cli.oneshots:reset",
    "config": "servobus.cli.config:config",
    "record": "servobus.cli.record:record",
    "plot": "servobus.cli.plot:plot",
    "decode": "servobus.cli.decode:decode",
    "dbc": "servobus.cli.dbc:dbc",
    "sim": "servobus.cli.sim:sim",
    "bench": "servobus.cli.bench:bench",
    "bridge": "servobus.cli.bridge:bridge",
    "dashboard": "servobus.cli.dashboard:dashboard",
}


class LazyGroup(click.Group):
    """A group whose subcommands are imported when they are run or asked for help, each given the
    grouped ``--help`` and ``--debug`` of :func:`servobus.cli._help.with_help` as it is resolved."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = COMMANDS.get(cmd_name)
        if target is None:
            return None
        module, _, attribute = target.partition(":")
        command = getattr(importlib.import_module(module), attribute)
        assert isinstance(command, click.Command), target
        from servobus.cli._help import with_help

        return with_help(command)


@click.group(
    cls=LazyGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog="Examples:\n\n\b\n  servobus demo --duration 5\n  servobus scan --sim 4\n"
    "  servobus status -i slcan -c /dev/ttyACM0 --ids 1-3\n  servobus decode candump.log\n\n"
    "Exit codes: 0 done, 1 the job failed, 2 bad usage, 130 interrupted (Ctrl-C: motors being driven "
    "are sent their stop first), 143 terminated (SIGTERM: as Ctrl-C).",
)
@click.version_option(__version__, "--version", prog_name="servobus")
@click.option("--debug", is_flag=True, help="Show the traceback of an error.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Drive buses of servo actuators: MyActuator RMD-X, LK-TECH and hollow-series motors."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def _one_line(message: str) -> str:
    return " ".join(message.split())


def _ids(ids: Sequence[int]) -> str:
    """``motor 3``, ``motors 1, 2``, ``motors 1-16, 20`` (runs of three or more as ranges)."""
    runs: list[list[int]] = []
    for i in sorted(ids):
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    parts = [f"{r[0]}-{r[-1]}" if len(r) >= 3 else ", ".join(map(str, r)) for r in runs]
    return ("motor " if len(ids) == 1 else "motors ") + ", ".join(parts)


def _interrupted(by: signal.Signals = signal.SIGINT) -> str:
    """The line for Ctrl-C (or another signal ``by``, named): which motors were sent their safe
    command, and which were not (only what the Buses reported; nothing is claimed for a command that
    commanded no motor)."""
    line = "servobus: interrupted" if by == signal.SIGINT else f"servobus: interrupted by {by.name}"
    return line + safe_exits()


def stopped_by() -> str:
    """What ended a command that ends on a signal: ``"Ctrl-C"``, or the other signal's name."""
    return SIGNALLED[0].name if SIGNALLED else "Ctrl-C"


def safe_exits() -> str:
    """``; stop sent to myactuator motors 1, 2 on can0`` for each Bus left, naming the motors that
    did not acknowledge their safe command and those it never left for (empty: no Bus stopped any)."""
    line = ""
    for bus, family, safe, acknowledged, unanswered, missed in SAFE_EXITS:
        if acknowledged:
            line += f"; {safe} sent to {family} {_ids(acknowledged)} on {bus}"
        if unanswered:
            line += f"; {safe} sent to {family} {_ids(unanswered)} on {bus}, NOT acknowledged"
        if missed:
            line += f"; {safe} NOT sent to {family} {_ids(missed)} on {bus}"
    return line


def _broken_pipe(exc: BaseException) -> bool:
    """``exc`` was raised on the way out of a write to a closed pipe (EPIPE)."""
    seen: BaseException | None = exc
    for _ in range(16):  # (a chain, not a cycle)
        if seen is None:
            break
        if isinstance(seen, BrokenPipeError):
            return True
        seen = seen.__cause__ or seen.__context__
    # click >= 8.5 exits outside its handler (no chain), having swapped stdout for its wrapper that
    # silences the EPIPE on flush: that swap happens on a closed pipe and nowhere else.
    return type(sys.stdout).__name__.lstrip("_") == "PacifyFlushWrapper"


def main(argv: Sequence[str] | None = None) -> int:
    """The console script: run ``cli`` and turn every error into one line and an exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    SAFE_EXITS.clear()
    SIGNALLED.clear()
    debug = "--debug" in args
    try:
        # Without standalone mode click returns the code of a click.exceptions.Exit raised inside a
        # command (a delegated server's status) instead of raising it.
        code = cli.main(args=args, prog_name="servobus", standalone_mode=False)
        if isinstance(code, int) and not isinstance(code, bool):
            return code
    except click.exceptions.Exit as done:
        return done.exit_code
    except SystemExit as exc:  # click's and rich's answer to a closed stdout: exit 1
        if _broken_pipe(exc):  # servobus monitor --json | head: the reader has what it wanted
            return 0  # (the Buses were left through their safe stop on the way out)
        raise
    except click.UsageError as exc:
        if debug:  # (a value the library refused: its own traceback)
            if isinstance(exc.__cause__, ValueError):
                raise exc.__cause__ from None
            raise
        from servobus.cli._help import did_you_mean

        where = f"{exc.ctx.command_path}: " if exc.ctx is not None else "servobus: "
        message = did_you_mean(exc) or exc.format_message()
        click.echo(f"{where}error: {_one_line(message)}", err=True)
        return 2
    except (click.Abort, KeyboardInterrupt) as exc:  # (click turns a KeyboardInterrupt into Abort)
        by = SIGNALLED[0] if SIGNALLED else signal.SIGINT
        said = f": {exc}" if isinstance(exc, click.Abort) and str(exc) else ""  # (confirm's)
        click.echo(_interrupted(by) + said, err=True)
        return 128 + by
    except ValueError as exc:  # the job failed (a reply or file that did not parse), not an argument:
        if debug:  # the values from the command line are checked first (servobus.cli._output.refused)
            raise
        click.echo(f"servobus: error: {_one_line(str(exc)) or type(exc).__name__}", err=True)
        from servobus.limits import LimitExceeded  # (imported on the way out only: --help stays light)

        # beyond --limits (or a bridge's) once the motor's state was known (a relative move): bad usage
        return 2 if isinstance(exc, LimitExceeded) else 1
    except (ServobusError, OSError, click.ClickException) as exc:
        if debug:
            raise
        message = exc.format_message() if isinstance(exc, click.ClickException) else str(exc)
        click.echo(f"servobus: error: {_one_line(message) or type(exc).__name__}", err=True)
        return exc.exit_code if isinstance(exc, click.ClickException) else 1
    return 0

"""How the command line helps: ``--help`` in groups, ``--debug`` on every command, and "did you mean".

``--help`` shows a command's own options first (its required ones near the top, ``--debug`` and
``--help`` last among them), then the options that say where the motors are (``Connection``), then
those of a bus on a bridge (``Remote (a bridge's bus)``): an option carries its heading
(:class:`GroupedOption`, made by :mod:`servobus.cli._connect` and :mod:`servobus.cli._remote`), and
:func:`with_help` applies the layout once to each command as the group resolves it
(:class:`servobus.cli.LazyGroup`), so no command module says anything about it.

A mistyped command or option is one line, exit 2, with the closest name (difflib) when one is
close: ``servobus: error: No such command 'scna'. Did you mean 'scan'?``
"""

from __future__ import annotations

import difflib
import types
import weakref
from collections.abc import Sequence
from typing import Any

import click
from click.exceptions import NoSuchCommand

__all__ = ["CONNECTION", "OPTIONS", "REMOTE", "GroupedOption", "did_you_mean", "with_help"]

#: the headings of --help, in their order on the page
OPTIONS = "Options"
CONNECTION = "Connection"
REMOTE = "Remote (a bridge's bus)"


class GroupedOption(click.Option):
    """An option shown under ``help_group`` in ``--help`` (:func:`with_help`), after the command's own."""

    def __init__(self, *args: Any, help_group: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.help_group = help_group


#: the widest option names click keeps beside their help (longer ones get a line of their own)
_COL_MAX = 30
#: the commands :func:`with_help` has done (LazyGroup resolves a command each time it is named)
_HELPED: weakref.WeakSet[click.Command] = weakref.WeakSet()


def _debug_option() -> click.Option:
    # (servobus.cli.main looks for --debug anywhere on the line: here it is only accepted and shown)
    return click.Option(["--debug"], is_flag=True, expose_value=False, help="Show the traceback of an error.")


def with_help(command: click.Command) -> click.Command:
    """``command`` (and a group's subcommands) with the grouped ``--help`` and a ``--debug`` option;
    done once per command object (a command resolved again is returned as it is)."""
    if command in _HELPED:
        return command
    _HELPED.add(command)
    if not any(param.name == "debug" for param in command.params):
        command.params.append(_debug_option())
    # click has no hook for the layout of one command's options but its format_options method
    command.format_options = types.MethodType(_format_options, command)  # type: ignore[method-assign]
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            with_help(sub)
    return command


def _format_options(self: click.Command, ctx: click.Context, formatter: click.HelpFormatter) -> None:
    """The command's options under their headings: its own first, ``--debug`` and ``--help`` ending
    them, then each :class:`GroupedOption`'s heading in the order the options come."""
    sections: dict[str, list[tuple[str, str]]] = {OPTIONS: []}
    last: list[tuple[str, str]] = []
    for param in self.get_params(ctx):
        record = param.get_help_record(ctx)
        if record is None:
            continue
        group = getattr(param, "help_group", None)
        if group is None and (param.name == "debug" or set(param.opts) & set(ctx.help_option_names)):
            last.append(record)
        else:
            sections.setdefault(group or OPTIONS, []).append(record)
    sections[OPTIONS] += last
    # one column for the help texts on the whole page: click sizes it per section (to the longest
    # name that fits, at most 30), so each section's first name is padded to the page's widest
    terms = [len(term) for rows in sections.values() for term, _ in rows]
    width = max((n for n in terms if n <= _COL_MAX), default=0)
    for title, rows in sections.items():
        if rows:
            with formatter.section(title):
                formatter.write_dl(_padded(rows, width), col_max=_COL_MAX)
    if isinstance(self, click.Group):
        self.format_commands(ctx, formatter)


def _padded(rows: list[tuple[str, str]], width: int) -> list[tuple[str, str]]:
    """``rows`` with the name of the first that has a help text padded to ``width`` (an argument
    without one would end its line in spaces)."""
    for i, (term, text) in enumerate(rows):
        if text:
            return [*rows[:i], (term.ljust(width), text), *rows[i + 1 :]]
    return rows


def did_you_mean(exc: click.UsageError) -> str | None:
    """The one-line message of a mistyped command or option, with the closest name when one is
    close; None for another usage error."""
    ctx = exc.ctx
    if ctx is None:
        return None
    if isinstance(exc, NoSuchCommand) and isinstance(ctx.command, click.Group):
        word, what, known = exc.command_name, "command", ctx.command.list_commands(ctx)
    elif isinstance(exc, click.NoSuchOption):
        word, what = exc.option_name, "option"
        params = ctx.command.get_params(ctx)
        known = [opt for p in params for opt in (*p.opts, *p.secondary_opts) if opt.startswith("--")]
    else:
        return None
    line = f"No such {what} {word!r}."
    close = _closest(word, known)
    if close:
        line += " Did you mean " + " or ".join(repr(name) for name in close) + "?"
    return line


def _closest(word: str, known: Sequence[str]) -> list[str]:
    """The closest of ``known`` to ``word`` (difflib's ratio, at least 0.6; of a tie, the names
    ``word`` begins: ``--rate`` is ``--rate-hz``, not ``--bitrate``), two when they still tie."""
    scored = sorted(
        ((difflib.SequenceMatcher(None, word, name).ratio(), name.startswith(word), name) for name in known),
        key=lambda entry: (-entry[0], not entry[1]),
    )
    if not scored or scored[0][0] < 0.6:
        return []
    top, prefix, _ = scored[0]
    return [name for score, starts, name in scored if (score, starts) == (top, prefix)][:2]

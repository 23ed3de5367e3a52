"""What every command shares for output: the rich consoles, ``--json``, tables, replies as plain data.

Tables and progress go through rich; ``--json`` output is plain JSON on stdout (one document, or one
line per sample for live commands), so scripts never parse a table. Errors are not printed here: they
are raised (``click.ClickException``, ``click.UsageError``) and ``servobus.cli.main`` prints one line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import functools
import json
import math
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, TypeVar

import click
from rich.console import Console
from rich.table import Table

from servobus.protocols import Message

__all__ = [
    "SETTINGS",
    "FloatRange",
    "NegativeNumbers",
    "confirm",
    "console",
    "emit_json",
    "examples",
    "fmt",
    "json_option",
    "jsonable",
    "message_fields",
    "message_text",
    "refused",
    "table",
    "yes_option",
]

F = TypeVar("F", bound=Callable[..., Any])

#: every command's context settings (help text up to 100 columns wide)
SETTINGS: dict[str, Any] = {"max_content_width": 100}


def examples(*lines: str) -> str:
    """A command's epilog: its example command lines, kept as written (``\b``: click does not rewrap)."""
    return "Examples:\n\n\b\n" + "\n".join(f"  {line}" for line in lines)


def console(*, stderr: bool = False) -> Console:
    """A rich console on stdout (or stderr, for progress and live views that are not the output).

    Made per call, so it writes to whatever ``sys.stdout`` is now (tests capture it).
    """
    return Console(stderr=stderr, highlight=False, soft_wrap=False)


class FloatRange(click.FloatRange):
    """click's FloatRange, refusing NaN: it passes every range check (each comparison is false), so a
    ``--duration nan`` would never end and a ``--rate-hz nan`` would fail only after a set-point left."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = super().convert(value, param, ctx)
        if isinstance(number, float) and math.isnan(number):
            self.fail(f"{value!r} is not a number", param, ctx)
        return number


#: a negative number (``-5``, ``-0.5``, ``-.5``, ``-1e3``, ``-0x10``, ``-1,2,3``): no option looks like one
_NEGATIVE = re.compile(r"-\.?\d")


class NegativeNumbers(click.Command):
    """A command whose arguments may be negative numbers: ``servobus config set KEY -5`` gives ``-5``
    as the value, where click would look for an option ``-5`` (options already take ``--x -5``)."""

    def make_parser(self, ctx: click.Context) -> Any:
        parser = super().make_parser(ctx)
        # click has no public hook for how an argument that starts with "-" is taken (its parser's
        # own method decides): wrapped here, the one place the command line reaches into click
        parser._process_opts = functools.partial(_negative_number, parser._process_opts)  # type: ignore[method-assign]  # noqa: SLF001 (click's parser: no public hook for a "-5" argument)
        return parser


def _negative_number(process_opts: Callable[[str, Any], None], arg: str, state: Any) -> None:
    """Click's option processing of ``arg``, except that a negative number is an argument."""
    if _NEGATIVE.match(arg):
        state.largs.append(arg)  # a value in its place among the arguments
    else:
        process_opts(arg, state)


@contextlib.contextmanager
def refused() -> Iterator[None]:
    """Inside the block, a ValueError is a value from the command line the library refused (out of
    range, a command the revision lacks): bad usage, one line, exit 2. Outside such blocks a
    ValueError is the job failing (exit 1), not the user's argument.

    Raises:
        click.UsageError: the ValueError's message.
    """
    try:
        yield
    except ValueError as exc:
        raise click.UsageError(str(exc)) from exc


def json_option(func: F) -> F:
    """``--json``: machine-readable output on stdout; the command receives ``as_json``."""
    return click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")(func)


def yes_option(func: F) -> F:
    """``--yes``/``-y``: skip the confirmation of a ROM write or an id change."""
    return click.option("--yes", "-y", is_flag=True, help="Do not ask for confirmation.")(func)


def confirm(question: str, yes: bool) -> None:
    """Ask ``question`` on the terminal unless ``yes``.

    Raises:
        click.ClickException: declined, or no answer (stdin closed): nothing is sent (exit 1).
        click.Abort: Ctrl-C at the question: ``interrupted: nothing was sent`` (exit 130).
    """
    if yes:
        return
    try:
        answer = click.confirm(question, default=False, err=True)
    except click.Abort as exc:  # (click's answer to Ctrl-C and to a closed stdin alike)
        if isinstance(exc.__context__, KeyboardInterrupt):
            click.echo(err=True)  # (the line ends after the question's ^C)
            raise click.Abort("nothing was sent") from None
        answer = False  # stdin closed: no answer
    except OSError:  # stdin unreadable: no answer
        answer = False
    if not answer:
        raise click.ClickException("not confirmed (give --yes to skip the question): nothing was sent")


def jsonable(value: Any) -> Any:
    """``value`` as JSON data: enums by name, flags as a list of names, a command or reply as its
    :func:`message_fields`, other dataclasses as dicts."""
    if isinstance(value, enum.Flag):
        return [member.name for member in type(value) if member.value and member in value and member.name]
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, Message):
        return message_fields(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value) if f.repr}
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, Iterable) and not isinstance(value, bytes | bytearray):
        return [jsonable(v) for v in value]
    if isinstance(value, bytes | bytearray):
        return value.hex(" ")
    return str(value)


def message_fields(message: Message) -> dict[str, Any]:
    """A command's or reply's fields as :func:`servobus.tools.logs.message_values` gives them (scalars, units
    in the names: the shape ``decode``, ``record`` and ``plot`` share), non-finite floats as text."""
    from servobus.tools.logs import message_values  # (python-can loads with it: only when needed)

    return {name: jsonable(value) for name, value in message_values(message).items()}


def message_text(message: Message) -> str:
    """A command or reply in a line: its class name, then ``name=value`` for each of its fields."""
    fields = " ".join(f"{name}={value}" for name, value in message_fields(message).items())
    return f"{type(message).__name__} {fields}".rstrip()


def emit_json(data: Any) -> None:
    """``data`` as one JSON document on stdout."""
    click.echo(json.dumps(jsonable(data), ensure_ascii=False))


def fmt(value: Any, digits: int = 2) -> str:
    """A cell: numbers rounded, flags joined, nothing as an empty cell."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    if isinstance(value, list):
        return ",".join(str(v) for v in value) or "none"
    if isinstance(value, dict):
        return ",".join(f"{k}={v}" for k, v in value.items())
    return str(value)


def table(title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> Table:
    """A rich table; numeric-looking columns (``*_deg``, ``*_a``, ...) are right-aligned by the caller's
    formatting, every cell through :func:`fmt`."""
    out = Table(title=title, title_justify="left", header_style="bold")
    for column in columns:
        out.add_column(column, justify="left" if column in _LEFT else "right")
    for row in rows:
        out.add_row(*(fmt(cell) for cell in row))
    return out


_LEFT = frozenset(
    {"family", "revision", "model", "state", "errors", "error", "key", "figure", "benchmark", "sent", "reply"}
)

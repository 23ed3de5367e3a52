"""A mkdocs hook (mkdocs.yml ``hooks:``): docs/reference/cli.md says what ``servobus COMMAND --help`` says.

mkdocs-click 0.9 renders a command's help, usage and options, with two gaps this fills:

- a table's Default column shows the option's raw ``default``: with click 8.3 and later that is
  ``Sentinel.UNSET`` for every option without one, and a flag shows ``False``. Its row formatter is
  replaced by one whose Default column is click's own (``Option.get_help_extra``: the default where
  the option shows one, else "required" or nothing);
- the epilog (every command's ``Examples:``, the group's exit codes) is left out. It follows the
  options here, each of click's no-rewrap paragraphs (``\\b``) as a code block, as ``--help`` keeps
  them.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Iterator
from typing import Any

import click
from mkdocs_click import _docs

_make_options: Callable[..., Iterator[str]] = _docs._make_options  # noqa: SLF001 (wrapped below)


def _row(option: click.Option) -> str:
    names = ", ".join(f"`{opt}`" for opt in option.opts)
    if option.secondary_opts:
        names += " / " + ", ".join(f"`{opt}`" for opt in option.secondary_opts)
    value_type = _docs._format_table_option_type(option)  # noqa: SLF001 (the row's one helper kept)
    description = " ".join((option.help or "").split()).replace("|", "&#124;")
    extra = option.get_help_extra(click.Context(click.Command("servobus")))
    default = f"`{extra['default']}`" if extra.get("default") else ""
    if option.required:
        default = "required"
    return f"| {names} | {value_type} | {description} | {default} |"


def epilog(text: str) -> Iterator[str]:
    """Markdown lines of a click epilog: a ``\\b`` paragraph as a code block, a ``Heading:`` in bold."""
    for paragraph in text.strip().split("\n\n"):
        if paragraph.startswith("\b\n"):
            yield "```text"
            yield textwrap.dedent(paragraph[2:]).rstrip()
            yield "```"
        elif paragraph.endswith(":") and "\n" not in paragraph:
            yield f"**{paragraph}**"
        else:
            yield " ".join(paragraph.split())
        yield ""


def _options_and_epilog(ctx: click.Context, *args: Any, **kwargs: Any) -> Iterator[str]:
    yield from _make_options(ctx, *args, **kwargs)
    if ctx.command.epilog:
        yield ""
        yield from epilog(ctx.command.epilog)


def on_startup(**kwargs: Any) -> None:
    _docs._format_table_option_row = _row  # noqa: SLF001 (the one row formatter, replaced)
    _docs._make_options = _options_and_epilog  # noqa: SLF001 (the options, then the epilog)

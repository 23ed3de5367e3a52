"""A mkdocs hook (mkdocs.yml ``hooks:``): the option tables of docs/reference/cli.md say what ``--help`` says.

mkdocs-click 0.9 fills a table's Default column with the option's raw ``default``: with click 8.3 and
later that is ``Sentinel.UNSET`` for every option without one, and a flag shows ``False``. This
replaces its row formatter with one whose Default column is click's own (``Option.get_help_extra``:
the default where the option shows one, else "required" or nothing), so the page and
``servobus COMMAND --help`` agree.
"""

from __future__ import annotations

from typing import Any

import click
from mkdocs_click import _docs


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


def on_startup(**kwargs: Any) -> None:
    _docs._format_table_option_row = _row  # noqa: SLF001 (the one row formatter, replaced)

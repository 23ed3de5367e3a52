"""``servobus dbc``: a DBC of a family's frames, generated from its codec's field tables (cantools)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from servobus.cli._connect import FAMILIES, parse_ids

__all__ = ["dbc"]

EPILOG = """\b
One message per motor for its requests (0x140+ID) and one for its replies (0x240+ID), plus the 0x280
broadcast, each multiplexed on DATA[0]; each field a signal with the factor, range and unit of the
codec's field table. What a DBC multiplexed on DATA[0] cannot carry is listed on stderr (motion-mode
frames, text, layouts told apart by another byte). Only myactuator has field tables to generate
from. Needs cantools: pip install 'servobus[dbc]'.

\b
Examples:
  servobus dbc --family myactuator --ids 1-4 -o myactuator.dbc
  servobus dbc --revision V4_3 --ids 1 > v43.dbc
  servobus dbc --ids 1-2 --json -o ma.dbc     # the summary as JSON on stdout"""


@click.command(epilog=EPILOG)
@click.option(
    "--family",
    "-f",
    type=click.Choice(FAMILIES),
    default="myactuator",
    show_default=True,
    help="Protocol family.",
)
@click.option("--revision", help="Protocol revision (myactuator V4_3/V4_4) [default: the newest].")
@click.option("--ids", "ids_text", default="1", show_default=True, metavar="IDS", help="Motor ids, e.g. 1-4.")
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="File [default: stdout]."
)
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout (needs -o).")
def dbc(
    family: str, revision: str | None, ids_text: str, output: Path | None, force: bool, as_json: bool
) -> None:
    """Export a DBC of a family's frames (cantools loads and decodes it)."""
    try:
        ids = parse_ids(ids_text)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--ids") from None
    if as_json and output is None:
        raise click.UsageError("--json prints the summary on stdout: give -o for the DBC")
    if output is not None and output.exists() and not force:
        raise click.UsageError(f"{output} exists (--force overwrites it)")
    try:
        import cantools  # noqa: F401
    except ImportError:
        raise click.ClickException("dbc needs cantools: pip install 'servobus[dbc]'") from None
    from servobus.dbc import build_database, dbc_text

    try:
        database, left_out = build_database(family, ids, revision)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--family/--revision/--ids") from None
    text = dbc_text(database)
    if output is None:
        click.echo(text, nl=False)
    else:
        with output.open("w" if force else "x", encoding="utf-8", newline="\n") as out:
            out.write(text)
    summary = {
        "output": str(output) if output is not None else None,
        "messages": [m.name for m in database.messages],
        "left_out": left_out,
    }
    if as_json:
        click.echo(json.dumps(summary))
        return
    where = output if output is not None else "stdout"
    click.echo(f"dbc: {len(database.messages)} messages -> {where}; left out:", err=True)
    for reason in left_out:
        click.echo(f"  {reason}", err=True)

"""``servobus dbc``: a DBC of a family's CAN frames, generated from its codec's definitions (cantools).

The family is any registered one (built-in or by entry point); its DBC options are its dbc part's
(``servobus.protocols.dbc.DbcFamily.options``): the flags below for the built-in ones, ``--option NAME=VALUE``
for any.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from servobus.cli._connect import FamilyChoice, parse_ids
from servobus.protocols import DEFAULT_FAMILY

__all__ = ["dbc"]

EPILOG = """\b
Each field is a signal named as servobus names it (currents_a[0]: currents_a_0), with the factor, range
and unit of the codec's field tables or of the C core's bit layouts; a field laid out two ways on one
identifier keeps its name in one layout, and the others get their DATA[0] as a suffix (angle_deg_92).
What a DBC cannot carry is listed on stderr (text, layouts told apart by another byte, frames that
share an identifier). What each family's DBC holds, and its options (-O NAME=VALUE, or the flags above
for the options they name), is its dbc part's; a family without one (a plug-in's) gets a DBC derived
from its classes' FIELDS and its bound codec's identifiers. Needs cantools: pip install 'servobus[dbc]'.

\b
Examples:
  servobus dbc --family myactuator --ids 1-4 -o myactuator.dbc
  servobus dbc --revision V4_3 --ids 1 > v43.dbc
  servobus dbc --family lk --model MF --encoder-bits 16 --ids 1-4 -o lk.dbc
  servobus dbc --family hollow --can-mode fd --model 3507 --ids 1-4 -o hollow-fd.dbc
  servobus dbc --ids 1-2 --json -o ma.dbc     # the summary as JSON on stdout"""

#: The flags of options several families' DBCs take, by option name (any option: -O NAME=VALUE).
FLAGS = {
    "model": "--model",
    "encoder_bits": "--encoder-bits",
    "can_mode": "--can-mode",
    "host_id": "--host-id",
    "max_torque_nm": "--max-torque",
}


class _DbcCommand(click.Command):
    """``servobus dbc``, whose help ends with each registered family's DBC and options (read from the
    families' dbc parts when the help is shown)."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        super().format_epilog(ctx, formatter)
        from servobus.protocols import available_families, get_family
        from servobus.protocols.dbc import dbc_part

        for name in available_families():
            try:
                part = dbc_part(get_family(name))
            except (ImportError, LookupError, TypeError, ValueError) as exc:
                summary, rows = f"(not loaded: {exc})", []
            else:
                summary = part.summary or "derived from its classes' declarations and its bound codec's ids"
                rows = [(f"-O {o.name}=...", o.help) for o in part.options]
            with formatter.section(f"--family {name}"):
                formatter.write_text(summary)
                if rows:
                    formatter.write_dl(rows)


@click.command(cls=_DbcCommand, epilog=EPILOG)
@click.option(
    "--family",
    "-f",
    type=FamilyChoice(),
    default=DEFAULT_FAMILY,
    show_default=True,
    help="Protocol family (a registered name, see below).",
)
@click.option("--revision", help="Protocol revision [default: the family's].")
@click.option("--ids", "ids_text", default="1", show_default=True, metavar="IDS", help="Motor ids, e.g. 1-4.")
@click.option("--model", help="The family's model option (-O model=...).")
@click.option("--encoder-bits", type=int, help="The family's encoder_bits option.")
@click.option("--can-mode", help="The family's can_mode option.")
@click.option("--host-id", type=int, help="The family's host_id option.")
@click.option("--max-torque", type=float, metavar="NM", help="The family's max_torque_nm option.")
@click.option(
    "--option",
    "-O",
    "extra",
    multiple=True,
    metavar="NAME=VALUE",
    help="A DBC option of the family by its name (repeatable), e.g. -O can_mode=fd.",
)
@click.option(
    "--direction",
    type=click.Choice(["request", "reply"]),
    help="Only the requests' or the replies' messages [default: both, or the family's choice].",
)
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="File [default: stdout]."
)
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout (needs -o).")
def dbc(
    family: str,
    revision: str | None,
    ids_text: str,
    model: str | None,
    encoder_bits: int | None,
    can_mode: str | None,
    host_id: int | None,
    max_torque: float | None,
    extra: tuple[str, ...],
    direction: str | None,
    output: Path | None,
    force: bool,
    as_json: bool,
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
    from servobus.protocols import get_family
    from servobus.protocols.dbc import dbc_part
    from servobus.tools.dbc import database, dbc_text, owners_of, plan

    part = dbc_part(get_family(family))
    given = {
        "model": model,
        "encoder_bits": encoder_bits,
        "can_mode": can_mode,
        "host_id": host_id,
        "max_torque_nm": max_torque,
    }
    options = {option: value for option, value in given.items() if value is not None}
    flags = {option: FLAGS[option] for option in options}
    for text in extra:
        option, sep, value_text = text.partition("=")
        option = option.strip()
        if not sep or not option:
            raise click.BadParameter(f"{text!r} is not NAME=VALUE", param_hint="--option")
        wanted = part.option(option)
        flags[option] = "--option"
        try:
            options[option] = value_text if wanted is None else wanted.parse(value_text)
        except ValueError as exc:
            raise click.BadParameter(f"{option}: {exc}", param_hint="--option") from None
    for option, flag in flags.items():
        if part.option(option) is None:
            owners = owners_of(option)
            says = f"is an option of {owners}, not of {family}" if owners else f"is not an option of {family}"
            name = option if flag == "--option" else flag
            raise click.BadParameter(f"{name} {says}", param_hint=flag)
    try:
        p = plan(family, ids, revision, direction=direction, **options)
    except ValueError as exc:
        # A bad option value names the option (``can_mode='turbo' is not ...``): blame its flag.
        said = str(exc)
        hint = next((flag for o, flag in flags.items() if said.startswith(f"{o}=")), None)
        raise click.BadParameter(said, param_hint=hint or "--family/--revision/--ids/--model") from None
    db = database(p)
    text = dbc_text(db)
    if output is None:
        click.echo(text, nl=False)
    else:
        with output.open("w" if force else "x", encoding="utf-8", newline="\n") as out:
            out.write(text)
    summary = {
        "output": str(output) if output is not None else None,
        "messages": [m.name for m in db.messages],
        "left_out": list(p.left_out),
    }
    if as_json:
        click.echo(json.dumps(summary))
        return
    where = output if output is not None else "stdout"
    said = "left out:" if p.left_out else "nothing left out"
    click.echo(f"dbc: {len(db.messages)} messages -> {where}; {said}", err=True)
    for reason in p.left_out:
        click.echo(f"  {reason}", err=True)

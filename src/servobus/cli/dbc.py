"""``servobus dbc``: a DBC of a family's CAN frames, generated from its codec's definitions (cantools).

The family is any registered one (built-in or by entry point); its DBC options are its dbc part's
(``servobus.dbc.DbcFamily.options``): the flags below for the built-in ones, ``--option NAME=VALUE``
for any.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from servobus.cli._connect import parse_ids

__all__ = ["dbc"]

EPILOG = """\b
myactuator: per motor its requests (0x140+ID) and replies (0x240+ID), multiplexed on DATA[0], and its
motion-mode command (0x400+ID) and reply (0x500+ID); the 0x280 broadcast. lk: per motor its requests
(0x140+ID) and replies (0x180+ID; V2.35 replies share 0x140+ID, so that DBC holds the replies unless
--direction request), parameter frames multiplexed again on their parameter byte; V2.35's 0x280.
hollow: per motor its requests (on the motor id; --can-mode normal, extended or fd: they share the
ids) and the mode-switch/PI frames (extended id), and one reply message on the host id.

\b
Each field is a signal named as servobus names it (currents_a[0]: currents_a_0), with the factor, range
and unit of the codec's field tables or of the C core's bit layouts; a field laid out two ways on one
identifier keeps its name in one layout, and the others get their DATA[0] as a suffix (angle_deg_92).
What a DBC cannot carry is listed on stderr (text, layouts told apart by another byte, hollow's special
commands). A family of a plug-in takes its options as --option NAME=VALUE; without a dbc part of its
own, its DBC is derived from its classes' FIELDS and its bound codec's identifiers.
Needs cantools: pip install 'servobus[dbc]'.

\b
Examples:
  servobus dbc --family myactuator --ids 1-4 -o myactuator.dbc
  servobus dbc --revision V4_3 --ids 1 > v43.dbc
  servobus dbc --family lk --model MF --encoder-bits 16 --ids 1-4 -o lk.dbc
  servobus dbc --family hollow --can-mode fd --model 3507 --ids 1-4 -o hollow-fd.dbc
  servobus dbc --ids 1-2 --json -o ma.dbc     # the summary as JSON on stdout"""


@click.command(epilog=EPILOG)
@click.option(
    "--family",
    "-f",
    default="myactuator",
    show_default=True,
    help="Protocol family (myactuator, lk, hollow, or a plug-in's).",
)
@click.option(
    "--revision",
    help="Protocol revision (myactuator V4_3/V4_4, lk V2_36/V2_35, hollow HO_SERIES) [default: the newest].",
)
@click.option("--ids", "ids_text", default="1", show_default=True, metavar="IDS", help="Motor ids, e.g. 1-4.")
@click.option(
    "--model",
    help="lk: motor type MS/MF/MH/MG [MG]; hollow: motor model (default, 3507) [default].",
)
@click.option("--encoder-bits", type=int, help="lk: encoder width, 14/15/16/18 [14].")
@click.option(
    "--can-mode",
    type=click.Choice(["normal", "extended", "fd"]),
    help="hollow: the frames on the motor and host ids [normal].",
)
@click.option("--host-id", type=int, help="hollow: the identifier replies go to [100].")
@click.option("--max-torque", type=float, metavar="NM", help="myactuator V4.4: the motion-mode torque range.")
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
    help="Only the requests' or the replies' messages [default: both; lk V2.35: replies].",
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
    from servobus.dbc import database, dbc_part, dbc_text, option_owners, plan
    from servobus.protocols import available_families, get_family

    known = available_families()
    if family not in known:
        raise click.BadParameter(f"no family {family!r} (known: {', '.join(known)})", param_hint="--family")
    part = dbc_part(get_family(family))
    given: dict[str, tuple[str, object]] = {
        "model": ("--model", model),
        "encoder_bits": ("--encoder-bits", encoder_bits),
        "can_mode": ("--can-mode", can_mode),
        "host_id": ("--host-id", host_id),
        "max_torque_nm": ("--max-torque", max_torque),
    }
    options: dict[str, object] = {}
    for option, (_flag, value) in given.items():
        if value is not None:
            options[option] = value
    for text in extra:
        option, sep, value_text = text.partition("=")
        option = option.strip()
        if not sep or not option:
            raise click.BadParameter(f"{text!r} is not NAME=VALUE", param_hint="--option")
        wanted = part.option(option)
        if wanted is None:
            given[option] = ("--option", value_text)
            options[option] = value_text
            continue
        try:
            options[option] = wanted.parse(value_text)
        except ValueError as exc:
            raise click.BadParameter(f"{option}: {exc}", param_hint="--option") from None
    for option in options:
        if part.option(option) is None:
            flag = given[option][0]
            owners = " and ".join(option_owners(option))
            name = flag if flag != "--option" else option
            says = f"is an option of {owners}, not of {family}" if owners else f"is not an option of {family}"
            raise click.BadParameter(f"{name} {says}", param_hint=flag)
    try:
        p = plan(family, ids, revision, direction=direction, **options)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--family/--revision/--ids/--model") from None
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

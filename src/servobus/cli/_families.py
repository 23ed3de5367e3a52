"""What each CLI command sends, asked of the family: its ``cli`` part (:mod:`servobus.cli.plugin`).

The CLI names no family: ``--family NAME`` is looked up with ``get_family(NAME).part("cli")``, and a
command, a setting or a status read the family's part does not offer is refused here in one line
(exit 2), with the family's reason where it gives one.
"""

from __future__ import annotations

from collections.abc import Iterator

import click

from servobus.cli._connect import FamilyChoice
from servobus.cli.plugin import CliFamily, Op, Setting
from servobus.protocols import Family, get_family

__all__ = ["cli_part", "current_limit_users", "op", "setting", "settings", "status_reads"]


def cli_part(family: str | Family) -> CliFamily:
    """The family's ``cli`` part; a family without one gets the commands that need no table.

    Raises:
        click.ClickException: the family's ``cli`` part does not import or is not a
            :class:`CliFamily` (exit 1).
    """
    found = get_family(family) if isinstance(family, str) else family
    try:
        part = found.part("cli")
    except LookupError:
        return CliFamily()
    except (ImportError, AttributeError) as exc:  # a plug-in's broken part: its error, in one line
        raise click.ClickException(
            f"the {found.name} family's cli part ({found.parts['cli']}): {exc}"
        ) from exc
    if not isinstance(part, CliFamily):
        raise click.ClickException(
            f"the {found.name} family's cli part ({found.parts['cli']}) is {type(part).__name__}, "
            "not a servobus.cli.plugin.CliFamily"
        )
    return part


def op(family: str, command: str) -> Op:
    """What CLI command ``command`` sends to a motor of ``family``.

    Raises:
        click.UsageError: the family has no such command (exit 2), with the reason where known.
    """
    part = cli_part(family)
    entry = part.op(command)
    if entry is None:
        raise click.UsageError(_refusal(family, command, part.why_not.get(command)))
    return entry


def status_reads(family: str) -> Op:
    """The reads ``status``, ``monitor`` and ``scan`` send (refused where the family has none).

    Raises:
        click.UsageError: the family has no read-only request (exit 2).
    """
    found = get_family(family)
    part = cli_part(found)
    reads = tuple(part.status_reads(found))
    if not reads:
        why = part.why_not.get("status")
        if why is None and part.status is None:
            why = "none of its commands is declared a read of position, speed, current or faults"
        raise click.UsageError(_refusal(family, "status", why))
    return Op(first=lambda codec, v: tuple(read() for read in reads))


def _refusal(family: str, command: str, why: str | None) -> str:
    return f"{family} motors have no {command} command" + (f": {why}" if why else "")


def settings(family: str) -> dict[str, Setting]:
    """The family's settings by key."""
    return {s.key: s for s in cli_part(family).settings}


def setting(family: str, key: str) -> Setting:
    """The setting ``key`` of ``family``.

    Raises:
        click.UsageError: the family has no settings (exit 2).
        click.BadParameter: no such key for the family (exit 2), naming the keys there are.
    """
    known = settings(family)
    if not known:
        raise click.UsageError(f"{family} motors have no settings the CLI can read or write")
    found = known.get(key)
    if found is None:
        raise click.BadParameter(
            f"{family} motors have no setting {key!r} (servobus config list --family {family})",
            param_hint="KEY",
        )
    return found


def current_limit_users() -> str:
    """``"hollow move and speed, lk speed"``: the commands that take ``--max-current-a``, by family
    (the families whose part does not load are left out)."""
    return ", ".join(_limit_users())


def _limit_users() -> Iterator[str]:
    for name in FamilyChoice().choices:  # the built-ins first, then the plug-ins'
        try:
            ops = cli_part(name).ops
        except Exception:  # a plug-in that does not load is not this command's error
            continue
        names = [command for command, entry in ops.items() if entry.current_limit]
        if names:
            yield f"{name} {' and '.join(names)}"

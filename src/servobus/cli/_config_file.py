"""A motor's settings as a file: the TOML ``servobus config dump`` writes and ``config restore`` reads.

The file holds the family, the revision and one table per motor id (``[motor.3]``), each key a
setting of the family's ``cli`` part (:class:`~servobus.cli.plugin.Setting`) with the value as
``config get`` shows it and ``config set`` takes it (numbers, ``true``/``false``, a list for a
setting of several numbers, ``"none"``), a comment above it saying what it is and where a write
goes (RAM or ROM). Python reads TOML (tomllib) but does not write it: the few forms used here are
written below.

Settings the motor cannot report (write-only) are written commented out, without a value: given one,
restore writes it every time (nothing to compare with, nothing to read back). Settings that cannot
be written (read-only) are written commented out with their value: uncommented, restore compares
them and says where they differ, and writes nothing.

Everything a restore needs from the file is checked here, before any bus is opened: each value goes
through the setting's own parser and write builder (its range checks) and the motor's codec (the
revision has it), so a bad file is one line and exit 2 with nothing sent.
"""

from __future__ import annotations

import enum
import math
import re
import struct
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any

import click

from servobus.cli.plugin import Setting
from servobus.limits import Limits
from servobus.protocols import Command

__all__ = [
    "Entry",
    "SettingsFile",
    "entries",
    "file_value",
    "load",
    "render",
    "same",
    "shown",
    "text_of",
    "where",
]

#: a key TOML takes without quotes
_BARE = re.compile(r"[A-Za-z0-9_-]+")


def where(s: Setting, rom: bool = False) -> str:
    """Where a write of ``s`` goes: ``ROM``, ``RAM``, or ``RAM (ROM with --rom)``; with ``rom``
    (restore's ``--rom``) the choice made."""
    if s.rom is None:
        return "ROM" if rom else "RAM (ROM with --rom)"
    return "ROM" if s.rom else "RAM"


def file_value(value: Any) -> Any:
    """A value read from a motor as the file holds it: numbers and booleans as they are, nothing as
    ``"none"``, an enum by name, a record of numbers (LK's PID gains) as a list in field order."""
    if value is None:
        return "none"
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, bool | int | float | str):
        return value
    if is_dataclass(value) and not isinstance(value, type):
        return [file_value(getattr(value, f.name)) for f in fields(value) if f.init]
    if isinstance(value, list | tuple):
        return [file_value(v) for v in value]
    return str(value)


def text_of(value: Any) -> str:
    """A file's value as the command line gives it to the setting's parser (``config set KEY TEXT``).

    Raises:
        ValueError: a value no setting takes (a table, a date).
    """
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return value
    if isinstance(value, list):
        return ",".join(text_of(v) for v in value)
    raise ValueError(f"a {type(value).__name__} is not a setting's value")


def _float(value: float) -> str:
    """``value`` in TOML, in the fewest digits that give the same float32 where it is one (a
    float32 PID gain read as 0.10000000149011612 is written 0.1: the same bits on the wire)."""
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    packed = struct.pack("<f", value) if abs(value) < 3.4e38 else b""
    if packed and struct.unpack("<f", packed)[0] == value:
        for digits in range(1, 10):
            short = float(f"{value:.{digits}g}")
            if struct.pack("<f", short) == packed:
                return repr(short)
    return repr(value)


def _toml(value: Any) -> str:
    """A value in TOML: the scalars, strings and lists a setting has."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _float(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    raise TypeError(f"no TOML form here for a {type(value).__name__}")


def shown(value: Any) -> str:
    """A value (read from a motor, or a file's) as the file writes it."""
    return _toml(file_value(value))


def _key(key: str) -> str:
    return key if _BARE.fullmatch(key) else _toml(key)


def key_line(key: str, value: Any) -> str:
    """``key = value`` in TOML (the key quoted where it has a dot)."""
    return f"{_key(key)} = {_toml(value)}"


def _comment(text: str) -> str:
    return "# " + " ".join(text.split())


def render(
    family: str,
    revision: str,
    motors: Mapping[int, Mapping[str, Any]],
    settings: Sequence[Setting],
    missing: Sequence[str] = (),
) -> str:
    """The file of ``motors`` (id -> key -> the value read, as :func:`file_value` gives it).

    Args:
        settings: the family's settings this revision has, in the order written.
        missing: the family's settings this revision lacks (named in the header).
    """
    ids = ", ".join(str(i) for i in motors)
    lines = [
        f"# servobus config dump: the settings of {family} {revision} motor(s) {ids}.",
        "# Edit a value and give the file to `servobus config restore FILE`: it shows what differs",
        "# and asks before it writes. RAM: the running value, lost at power-off; ROM: kept.",
        "# Write-only settings (the motor cannot report them) are commented out without a value:",
        "# give one a value and restore writes it (it cannot be read back to check).",
    ]
    if missing:
        lines.append(_comment(f"Not in {revision}: {', '.join(missing)}."))
    lines += ["", f"family = {_toml(family)}", f"revision = {_toml(revision)}"]
    for motor_id, values in motors.items():
        lines += ["", f"[motor.{motor_id}]"]
        for s in settings:
            if s.read is None:
                lines.append(_comment(f"{s.help} [{where(s)}; write-only]"))
                lines.append(f"# {_key(s.key)} =")
            elif s.write is None:
                lines.append(_comment(f"{s.help} [read-only: compared, never written]"))
                lines.append(f"# {key_line(s.key, values[s.key])}")
            else:
                lines.append(_comment(f"{s.help} [{where(s)}]"))
                lines.append(key_line(s.key, values[s.key]))
    return "\n".join(lines) + "\n"


# ---- reading ----


@dataclass(frozen=True, slots=True)
class Entry:
    """One key of one motor's table, checked: the value as the file gives it, as the write takes
    it, and the write command (None for a read-only setting)."""

    setting: Setting
    value: Any
    parsed: Any
    command: Command | None


@dataclass(frozen=True, slots=True)
class SettingsFile:
    """A settings file as read: family, revision, and each motor's table (id -> key -> value)."""

    path: str
    family: str
    revision: str
    motors: dict[int, dict[str, Any]]


def load(path: Path) -> SettingsFile:
    """The settings file at ``path``, its shape checked (the values are checked by :func:`entries`).

    Raises:
        click.UsageError: unreadable, not TOML, or not a settings file (exit 2).
    """
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise click.UsageError(f"{path}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise click.UsageError(f"{path}: not TOML: {exc}") from None
    family, revision, motors = data.get("family"), data.get("revision"), data.get("motor")
    if not isinstance(family, str) or not isinstance(revision, str):
        raise click.UsageError(
            f"{path}: not a settings file: family and revision missing (servobus config dump)"
        )
    unknown = sorted(set(data) - {"family", "revision", "motor"})
    if unknown:
        raise click.UsageError(f"{path}: unknown top-level key {unknown[0]!r} (family, revision, [motor.ID])")
    if not isinstance(motors, dict) or not motors:
        raise click.UsageError(f"{path}: no [motor.ID] table")
    tables: dict[int, dict[str, Any]] = {}
    for name, table in motors.items():
        if not name.isdigit() or not isinstance(table, dict):
            raise click.UsageError(f"{path}: [motor.{name}]: a motor's table is [motor.ID], ID a number")
        flat = list(_flat(table))
        keys = [key for key, _ in flat]
        twice = sorted({key for key in keys if keys.count(key) > 1})
        if twice:
            raise click.UsageError(f"{path}: [motor.{name}]: {twice[0]} is given twice")
        tables[int(name)] = dict(flat)
    return SettingsFile(str(path), family, revision, tables)


def _flat(table: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """A table's keys with the dots put back: ``pid.speed_kp = 0.5`` without quotes is TOML's
    dotted key, a table ``pid`` holding ``speed_kp``; both spellings name the setting."""
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _flat(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def entries(
    file: SettingsFile,
    motor_id: int,
    known: Mapping[str, Setting],
    codec: Any,
    rom: bool,
    limits: Limits | None = None,
) -> list[Entry]:
    """Motor ``motor_id``'s table, each value parsed and built into its write (the setting's range
    checks), within the motor's host-side ``limits`` (``--limits``; never clamped: a restore writes
    what the file says or nothing), and encoded by ``codec`` (the revision's), in the family's order
    of settings.

    Raises:
        click.UsageError: an unknown key, a value the setting or the limits refuse (naming key, value
            and the limit), or a setting the revision lacks (exit 2).
    """
    table = file.motors[motor_id]
    where_ = f"{file.path}: [motor.{motor_id}]"
    for key in table:
        if key not in known:
            raise click.UsageError(
                f"{where_}: {file.family} motors have no setting {key!r} "
                f"(servobus config list --family {file.family})"
            )
    out = []
    for key, s in known.items():
        if key not in table:
            continue
        value = table[key]
        try:
            shown = _toml(value)
        except TypeError:  # a date, a table in a list: refused below
            shown = repr(value)
        try:
            parsed = s.parse(text_of(value))
            command = None if s.write is None else s.write(parsed, rom)
            if command is not None and limits is not None:
                limits.check(command)
            for made in (command, s.read() if s.read is not None else None):
                if made is not None:
                    codec.encode(made)  # the revision has it
        except ValueError as exc:
            raise click.UsageError(f"{where_}: {key} = {shown}: {exc}") from None
        out.append(Entry(s, value, parsed, command))
    return out


def same(entry: Entry, now: Any, codec: Any, rom: bool) -> bool:
    """Whether the value read (``now``) is the entry's: the same bytes on the wire when written
    (a float32 or a scaled field reads back rounded), else equal as the file holds them."""
    if entry.command is not None:
        try:
            again = entry.setting.write(entry.setting.parse(text_of(file_value(now))), rom)  # type: ignore[misc]
            return bool(codec.encode(again) == codec.encode(entry.command))
        except ValueError:
            pass  # a value read that the write refuses: compared as it is
    return bool(file_value(now) == entry.value)

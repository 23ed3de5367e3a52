"""``servobus plot``: position, speed and current against time per motor, from a ``record`` file,
with the set-points ``record --drive`` stored (``setpoint_*`` columns) dashed beside them.

:func:`draw` makes the figure from rows (what the command saves, and what tests read the lines of)."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["draw", "plot", "read_rows"]

EPILOG = """\b
Reads the telemetry `servobus record` writes (.csv or .jsonl) and draws three panels against
time_s, one line per motor: position (the first column named position*, angle* or encoder*), speed
(speed*, velocity*) and current (current*, iq*). A set-point column (setpoint_angle_deg,
setpoint_speed_dps, setpoint_current_a: what `record --drive` stores) is drawn dashed in its motor's
colour on the panel of its quantity, in the response's unit (dps as rad/s beside speed_rad_s).
Needs matplotlib: pip install 'servobus[plot]'.

\b
Examples:
  servobus record --sim 4 --drive sine --stagger --duration 3 -o run.csv && servobus plot run.csv -o run.png
  servobus plot run.jsonl -o run.png --size 1600x1200 --title "bench run 3\""""

#: the prefix of a set-point's column (``setpoint_angle_deg``): drawn on the panel of the rest
SETPOINT = "setpoint_"
#: panel -> column-name prefixes, in order of preference
QUANTITIES = {
    "position": ("position", "angle", "encoder"),
    "speed": ("speed", "velocity"),
    "current": ("current", "iq"),
}
INSTALL = "plot needs matplotlib: pip install 'servobus[plot]'"


@click.command(epilog=EPILOG)
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="The PNG to write."
)
@click.option("--size", default="1200x900", show_default=True, metavar="WxH", help="Image size in pixels.")
@click.option("--title", help="Figure title [default: the file name].")
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
def plot(file: Path, output: Path, size: str, title: str | None, force: bool) -> None:
    """Plot position, speed and current against time per motor from a telemetry file."""
    width, height = _size(size)
    if output.suffix.lower() != ".png":
        raise click.BadParameter(f"{output}: the plot is written as a .png", param_hint="-o")
    if output.exists() and not force:
        raise click.UsageError(f"{output} exists (--force overwrites it)")
    try:  # (the extra, before any file is read)
        import matplotlib.backends.backend_agg  # noqa: F401
    except ImportError:
        raise click.ClickException(INSTALL) from None
    rows = read_rows(file)
    if not rows:
        raise click.ClickException(f"{file}: no telemetry rows")
    figure = draw(rows, title=title if title is not None else file.name, size=(width, height))
    if figure is None:
        raise click.ClickException(f"{file}: no position, speed or current column")
    motors = _motors(rows)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=figure.dpi)
    with output.open("wb" if force else "xb") as out:  # written whole: no half-drawn file on error
        out.write(buffer.getvalue())
    click.echo(f"plot: {len(rows)} rows, {len(motors)} motors -> {output}", err=True)


def draw(rows: list[dict[str, Any]], *, title: str, size: tuple[int, int] = (1200, 900)) -> Figure | None:
    """Three panels (position, speed, current) against ``time_s``, a line per motor, and each
    motor's set-point (a ``setpoint_*`` column) dashed in the same colour; None when the rows have
    no column to draw.

    Raises:
        ImportError: matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    columns = {panel: _column(rows, prefixes) for panel, prefixes in QUANTITIES.items()}
    targets = {
        panel: _column(rows, tuple(SETPOINT + p for p in prefixes)) for panel, prefixes in QUANTITIES.items()
    }
    if not any(columns.values()) and not any(targets.values()):
        return None
    dpi = 100
    figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    FigureCanvasAgg(figure)  # the Agg backend: no display needed
    axes = figure.subplots(len(QUANTITIES), 1, sharex=True)
    motors = _motors(rows)
    for ax, panel in zip(axes, QUANTITIES, strict=True):
        column, target = columns[panel], targets[panel]
        ax.set_ylabel(column or target or f"{panel} (none)")
        ax.grid(True, alpha=0.3)
        for n, motor in enumerate(motors):
            colour = f"C{n % 10}"
            xs, ys = _points(rows, motor, column)
            if xs:
                ax.plot(xs, ys, color=colour, label=f"motor {motor}", linewidth=1)
            xs, ys = _points(rows, motor, target)
            scale = _scale(target, column)
            ys = [y * scale for y in ys] if scale != 1.0 else ys
            if xs:  # (one legend entry says what a dashed line is: its colour is its motor's)
                ax.plot(xs, ys, color=colour, linestyle="--", linewidth=1, label=f"_set-point {motor}")
        handles, _ = ax.get_legend_handles_labels()
        if target is not None:
            handles.append(Line2D([], [], color="0.3", linestyle="--", linewidth=1, label="set-point"))
        if (len(motors) > 1 or target is not None) and ax.has_data():  # (beside the panel: over no line)
            ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
            figure.subplots_adjust(right=0.8)
    axes[-1].set_xlabel("time_s")
    figure.suptitle(title)
    return figure


#: (a set-point column's unit, the response column's) -> the factor between them
_SCALES = {
    ("dps", "rad_s"): math.pi / 180.0,
    ("deg", "rad"): math.pi / 180.0,
    ("rad_s", "dps"): 180.0 / math.pi,
    ("rad", "deg"): 180.0 / math.pi,
}


def _scale(target: str | None, column: str | None) -> float:
    """What a set-point in ``target``'s unit is multiplied by to be drawn in ``column``'s (hollow
    replies give speed in rad/s; ``record --drive`` its set-point in dps)."""
    if target is None or column is None:
        return 1.0
    for (mine, theirs), factor in _SCALES.items():
        if target.endswith(f"_{mine}") and column.endswith(f"_{theirs}"):
            return factor
    return 1.0


def _motors(rows: list[dict[str, Any]]) -> list[int]:
    return sorted({row["motor_id"] for row in rows if isinstance(row.get("motor_id"), int)})


def _points(rows: list[dict[str, Any]], motor: int, column: str | None) -> tuple[list[Any], list[Any]]:
    """The (time_s, value) of ``motor``'s rows where both are numbers."""
    if column is None:
        return [], []
    points = [
        (row["time_s"], row[column])
        for row in rows
        if row.get("motor_id") == motor and _number(row.get(column)) and _number(row.get("time_s"))
    ]
    return [x for x, _ in points], [y for _, y in points]


def _size(text: str) -> tuple[int, int]:
    width, sep, height = text.lower().partition("x")
    try:
        size = int(width), int(height)
    except ValueError:
        size = (0, 0)
    if not sep or not all(16 <= s <= 10_000 for s in size):
        raise click.BadParameter(f"{text!r}: expected WIDTHxHEIGHT in pixels, 16..10000", param_hint="--size")
    return size


def read_rows(file: Path) -> list[dict[str, Any]]:
    """The rows of a record CSV or JSONL file, values as numbers where they are.

    Raises:
        click.ClickException: the file is not a record telemetry file (exit 1).
    """
    return list(_rows(file))


def _rows(file: Path) -> Iterator[dict[str, Any]]:
    """The rows of a record CSV or JSONL file, values as numbers where they are."""
    try:
        with file.open(encoding="utf-8", newline="") as f:
            if file.suffix.lower() in (".jsonl", ".json"):
                for line in f:
                    if line.strip():
                        row = json.loads(line)
                        if not isinstance(row, dict):
                            raise ValueError("a line is not a JSON object")
                        yield row
            else:
                for raw in csv.DictReader(f):
                    yield {key: _parse(value) for key, value in raw.items()}
    except (ValueError, UnicodeDecodeError, csv.Error) as exc:
        raise click.ClickException(f"{file}: not a record telemetry file ({exc})") from None


def _parse(value: str | None) -> Any:
    if value is None or value == "":
        return None
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _column(rows: list[dict[str, Any]], prefixes: tuple[str, ...]) -> str | None:
    """The first column (in the rows' order) whose name starts with one of ``prefixes``, in the order
    of ``prefixes``, and that holds a number."""
    names = list(dict.fromkeys(name for row in rows for name in row))
    for prefix in prefixes:
        for name in names:
            if name.startswith(prefix) and any(_number(row.get(name)) for row in rows):
                return name
    return None

"""``servobus decode``: CAN logs or frames typed on the command line, decoded for a family."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import click

from servobus.cli._connect import family_option, parse_ids, revision_option
from servobus.frame import Frame
from servobus.tools.logs import Decoded, FrameDecoder, LogFrames, parse_frame, read_log

__all__ = ["decode"]

EPILOG = """\b
Each SOURCE is a log file (candump .log, .asc, .blf, .csv: python-can's readers), "-" for candump
lines on stdin, or one frame as candump writes it: ID#DATA (141#9C00000000000000; an 8-digit ID is
extended; ID##1DATA is CAN FD with bit-rate switch). --hex takes the bytes with spaces, ID first.
Requests and replies both decode (MyActuator 0x140+ID and 0x240+ID, LK, hollow); a log's R/T marks
(candump), Rx/Tx (ASC, BLF) tell them apart where they share an identifier (LK V2.35).

\b
Examples:
  servobus decode candump.log
  servobus decode --family myactuator 141#9C00000000000000 241#9C326400F4012D00
  servobus decode --hex "241 9C 32 64 00 F4 01 2D 00"
  servobus decode --family lk --revision V2_35 --json trace.asc > trace.jsonl
  candump -L can0 | servobus decode -

Frames that do not decode are printed as such. A log line that does not parse (a damaged line, a
last line cut short) is reported on stderr with its line number and skipped; decoding goes on. A
summary line goes to stderr. Exit status: 0 when at least one frame decoded, 1 when none did (no
frames, or none of the family's), 2 for bad arguments."""


@click.command(epilog=EPILOG)
@click.argument("sources", nargs=-1, metavar="[SOURCE]...")
@click.option("--hex", "hex_frames", multiple=True, metavar='"ID B0 B1 ..."', help="A frame as hex bytes.")
@family_option
@revision_option
@click.option("--ids", "ids_text", metavar="IDS", help="Motor ids to decode for, e.g. 1-4 (default: all).")
@click.option("--json", "as_json", is_flag=True, help="One JSON object per frame (JSON lines).")
def decode(
    sources: tuple[str, ...],
    hex_frames: tuple[str, ...],
    family: str,
    revision: str | None,
    ids_text: str | None,
    as_json: bool,
) -> None:
    """Decode CAN frames (logs or the command line) for a motor family, requests and replies."""
    if not sources and not hex_frames:
        raise click.UsageError("give a log file, a frame (ID#DATA), '-' for stdin, or --hex")
    inputs = [_source(text) for text in sources]
    inputs += [("frame", _frame(text, "--hex")) for text in hex_frames]
    options = {} if revision is None else {"revision": revision}
    try:
        ids = parse_ids(ids_text) if ids_text else None
        decoder = FrameDecoder(family, ids=ids, **options)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--revision/--ids") from None
    total = failed = skipped = bad = broken = 0
    for kind, source in inputs:
        frames = source if isinstance(source, LogFrames) else [source]
        count = 0
        cut = False
        try:
            for decoded in _decoded(decoder, frames):
                count += 1
                failed += not decoded.ok
                click.echo(json.dumps(decoded.as_dict()) if as_json else _text(decoded, timed=kind == "log"))
        except ValueError as exc:  # a binary log's damaged part: its reader cannot go on past it
            broken += 1
            cut = True
            click.echo(
                f"decode: {source}: does not parse as a CAN log after {count} frames ({exc})", err=True
            )
        total += count
        if isinstance(source, LogFrames):
            skipped += source.skipped
            bad += len(source.bad_lines)
            if not (count or cut or source.bad_lines or source.skipped):
                click.echo(f"decode: {source}: no CAN frames in it", err=True)
    extra = f", {skipped} error or remote frames skipped" if skipped else ""
    extra += f", {bad} bad {'line' if bad == 1 else 'lines'} skipped" if bad else ""
    extra += f", {broken} {'log' if broken == 1 else 'logs'} cut short by a damaged part" if broken else ""
    summary = f"decode: {total} frames, {total - failed} decoded, {failed} not decoded{extra}"
    if total - failed == 0:
        hint = " (another --family or --revision?)" if total else ""
        click.echo(f"{summary}: nothing decoded{hint}", err=True)
        raise click.exceptions.Exit(1)
    click.echo(summary, err=True)


def _bad_line(name: str) -> Callable[[int, str, str], None]:
    def report(number: int, line: str, why: str) -> None:
        shown = line if len(line) <= 60 else line[:57] + "..."
        click.echo(f"decode: {name}:{number}: not a CAN log line ({why}): {shown!r}", err=True)

    return report


def _source(text: str) -> tuple[str, LogFrames | Frame]:
    if text == "-":
        return "log", read_log(sys.stdin, name="<stdin>", on_bad_line=_bad_line("<stdin>"))
    path = Path(text)
    if "#" in text and not path.exists():
        return "frame", _frame(text, "SOURCE")
    if not path.is_file():
        raise click.BadParameter(f"{text}: no such file (nor a frame ID#DATA)", param_hint="SOURCE")
    try:
        import can

        can.LogReader(path).stop()  # python-can refuses an unknown format here, before any output
    except ValueError as exc:
        raise click.BadParameter(f"{text}: {exc}", param_hint="SOURCE") from None
    except OSError:
        raise
    except Exception as exc:  # a reader's own error on the file's head (BLF: BLFParseError)
        raise click.ClickException(
            f"{text}: does not parse as a CAN log ({type(exc).__name__}: {exc})"
        ) from None
    return "log", read_log(path, on_bad_line=_bad_line(text))


def _frame(text: str, hint: str) -> Frame:
    try:
        return parse_frame(text)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint=hint) from None


def _decoded(decoder: FrameDecoder, frames: Iterable[Frame]) -> Iterator[Decoded]:
    """Each frame decoded; a log's part that does not parse (where its reader cannot go on) as
    ValueError (a reader's own error included: :class:`LogFrames` turns those into ValueError)."""
    for frame in frames:
        yield decoder.decode(frame)


def _text(decoded: Decoded, *, timed: bool) -> str:
    frame = decoded.frame
    ident = f"{frame.arbitration_id:0{8 if frame.is_extended_id else 3}X}"
    sep = "##" + ("1" if frame.bitrate_switch else "0") if frame.is_fd else "#"
    head = f"({frame.timestamp:.6f}) " if timed else ""
    head += f"{ident}{sep}{frame.data.hex().upper()}"
    if decoded.message is None:
        return f"{head}  not decoded: {decoded.error}"
    way = "to" if decoded.direction == "request" else "from"
    who = (
        f"motor {decoded.motor_id}"
        if decoded.motor_id is not None
        else "every motor"
        if way == "to"
        else "a motor"
    )
    fields = " ".join(f"{name}={value}" for name, value in decoded.values().items())
    return f"{head}  {decoded.direction} {way} {who}: {decoded.type}" + (f" {fields}" if fields else "")

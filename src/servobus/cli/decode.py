"""``servobus decode``: CAN logs or frames typed on the command line, decoded for a family."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path

import click

from servobus.cli._connect import family_option, parse_ids, revision_option
from servobus.frame import Frame
from servobus.logs import Decoded, FrameDecoder, LogFrames, parse_frame, read_log

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

Frames that do not decode are printed as such; a summary line goes to stderr."""


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
    total = failed = skipped = 0
    for kind, source in inputs:
        frames = source if isinstance(source, LogFrames) else [source]
        for decoded in _decoded(decoder, frames, kind):
            total += 1
            failed += not decoded.ok
            click.echo(json.dumps(decoded.as_dict()) if as_json else _text(decoded, timed=kind == "log"))
        if isinstance(source, LogFrames):
            skipped += source.skipped
    extra = f", {skipped} error or remote frames skipped" if skipped else ""
    click.echo(f"decode: {total} frames, {total - failed} decoded, {failed} not decoded{extra}", err=True)


def _source(text: str) -> tuple[str, LogFrames | Frame]:
    if text == "-":
        return "log", read_log(sys.stdin)
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
    return "log", read_log(path)


def _frame(text: str, hint: str) -> Frame:
    try:
        return parse_frame(text)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint=hint) from None


def _decoded(decoder: FrameDecoder, frames: Iterable[Frame], kind: str) -> Iterator[Decoded]:
    iterator = iter(frames)
    while True:
        try:
            frame = next(iterator)
        except StopIteration:
            return
        except (ValueError, IndexError) as exc:  # a line python-can cannot parse: the file is bad
            source = getattr(frames, "source", "the log")
            raise click.ClickException(f"{source}: does not parse as a CAN log ({exc})") from None
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

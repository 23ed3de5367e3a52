"""Frames of either direction decoded for a family, and CAN logs read through python-can.

:class:`FrameDecoder` finds what a frame is through the bound codecs only (``Family.bind``: a motor's
``request_ids``, ``reply_ids``, ``shared_ids`` and ``classify``), so it never asks which family it
decodes: a frame a motor's codec claims is a reply and decodes with that codec (the Bus's own path);
a frame on a motor's request identifier (or a shared one, such as a broadcast) is a request and decodes
with ``Family.decode_request``. Where a reply and a request share an identifier (LK V2.35, MyActuator's
0x300) the frame's direction decides: python-can's ``is_rx``, which candump logs (``R``/``T``), ASC and
BLF keep; a frame that does not decode as a reply is tried as a request.

:func:`message_values` turns a typed command or reply into named scalar values (units in the names, as
the message classes spell them), the one shape ``decode --json``, ``record`` and ``plot`` share::

    decoder = FrameDecoder("myactuator")
    for frame in read_log("candump.log"):
        print(decoder.decode(frame).as_dict())
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import enum
import inspect
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import can

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, FrameKind, Message, get_family
from servobus.protocols._bound import id_key
from servobus.transports.can import frame_from_message

__all__ = [
    "BadLine",
    "Decoded",
    "FrameDecoder",
    "LogFrames",
    "Scalar",
    "message_values",
    "parse_frame",
    "read_log",
]

#: The ids tried when none are given: every id a family's ``bind`` accepts among these.
ALL_IDS = range(256)

Scalar = int | float | bool | str | None


def message_values(message: Message) -> dict[str, Scalar]:
    """A command or reply's fields as scalars: enums by name, flags as ints, tuples as ``name[i]``.

    A field holding another message (MyActuator's ``Echo(command=...)``) gives that message's class
    name and then its own fields as ``command.name``; configuration objects a message carries to be
    self-contained (a hollow ``model``, MyActuator's motion ``scales``) are left out.
    """
    values: dict[str, Scalar] = {}
    for field in dataclasses.fields(message):  # type: ignore[arg-type]
        _put(values, field.name, getattr(message, field.name))
    return values


def _put(values: dict[str, Scalar], name: str, value: Any) -> None:
    if isinstance(value, Message):
        values[name] = type(value).__name__
        for key, inner in message_values(value).items():
            values[f"{name}.{key}"] = inner
    elif isinstance(value, enum.Flag):
        values[name] = int(value.value)
    elif isinstance(value, enum.Enum):
        values[name] = value.name
    elif value is None or isinstance(value, bool | int | float | str):
        values[name] = value
    elif isinstance(value, tuple):
        for i, item in enumerate(value):
            _put(values, f"{name}[{i}]", item)
    # anything else is configuration (a model, motion scales), not a value the frame carried


@dataclass(frozen=True, slots=True)
class Decoded:
    """One frame and what it decoded to.

    Attributes:
        frame: the frame (its ``timestamp`` as the log gave it).
        direction: ``"request"`` or ``"reply"``; None when the frame did not decode.
        motor_id: the motor it goes to or comes from; None for a frame on an identifier every motor
            shares that names none (a broadcast request, MyActuator's 0x79), and for undecoded frames.
        message: the typed command or reply, or None.
        error: why it did not decode, or None.
    """

    frame: Frame
    direction: str | None = None
    motor_id: int | None = None
    message: Message | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.message is not None

    @property
    def type(self) -> str | None:
        """The message's class name (``StatusReply``), or None."""
        return None if self.message is None else type(self.message).__name__

    def values(self) -> dict[str, Scalar]:
        """:func:`message_values` of the message (empty when it did not decode)."""
        return {} if self.message is None else message_values(self.message)

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready record: the frame, then ``direction``, ``motor_id``, ``type`` and ``fields``
        (or ``error``)."""
        frame = self.frame
        record: dict[str, Any] = {
            "time": frame.timestamp,
            "id": frame.arbitration_id,
            "extended": frame.is_extended_id,
            "fd": frame.is_fd,
            "rx": frame.is_rx,
            "data": frame.data.hex().upper(),
        }
        if self.message is None:
            record["error"] = self.error
        else:
            record.update(direction=self.direction, motor_id=self.motor_id, type=self.type)
            record["fields"] = self.values()
        return record


class FrameDecoder:
    """Decodes the CAN frames of one family's motors, requests and replies alike.

    Args:
        family: the family's registry name.
        ids: the motors' ids (default: every id the family accepts, so any motor's frames decode).
        **bind_options: ``revision``, ``model`` and the family's other ``bind`` options.

    Raises:
        ValueError: an unknown family, a bad option, or ids none of which the family accepts.
    """

    def __init__(self, family: str, *, ids: Iterable[int] | None = None, **bind_options: Any) -> None:
        self.family = get_family(family)
        self._request_params = inspect.signature(self.family.decode_request).parameters
        self._replies: dict[int, list[BoundCodec]] = {}
        self._requests: dict[int, list[BoundCodec]] = {}
        if bind_options.get("revision") is not None:
            self.family.revision(bind_options["revision"])  # a bad name is refused here, by name
        wanted = list(ALL_IDS if ids is None else ids)
        self._refused: ValueError | None = None
        for link in self.family.links:
            codecs = self._bind(wanted, link, ids is not None, bind_options)
            if codecs and codecs[0].framing is not None:
                continue  # a serial link: its frames are not in CAN logs
            for codec in codecs:
                for ident in codec.reply_ids | codec.shared_ids:
                    self._replies.setdefault(ident, []).append(codec)
                for ident in codec.request_ids | codec.shared_ids:
                    self._requests.setdefault(ident, []).append(codec)
        if not self._replies and not self._requests:
            if self._refused is not None:  # every bind refused: a bad option (revision, model)
                raise self._refused
            raise ValueError(f"{family}: no motor ids among {_describe(wanted)} to decode for")

    def _bind(self, ids: Sequence[int], link: str, strict: bool, options: dict[str, Any]) -> list[BoundCodec]:
        codecs = []
        for motor_id in ids:
            try:
                codecs.append(self.family.bind(motor_id, link=link, **options))
            except ValueError as exc:
                if strict and link == self.family.links[0]:
                    raise
                self._refused = self._refused or exc
        return codecs

    def decode(self, frame: Frame) -> Decoded:
        """What ``frame`` is: a reply of one of the motors, a request to one, or neither (with why)."""
        key = id_key(frame.arbitration_id, frame.is_extended_id)
        error: str | None = None
        claimants = self._replies.get(key, ())
        for i, codec in enumerate(claimants):
            kind, _ = codec.classify(frame)
            if kind is FrameKind.NOT_OURS:
                continue
            try:
                reply = codec.decode(frame)
            except ProtocolError as exc:
                error = str(exc)
                break
            return Decoded(frame, "reply", self._sender(codec, claimants[i + 1 :], frame), reply)
        requests = self._requests.get(key)
        if requests:
            codec = requests[0]
            try:
                command = self._decode_request(codec, frame)
            except ProtocolError as exc:
                error = error or str(exc)
            else:
                shared = key in codec.shared_ids and key not in codec.request_ids
                return Decoded(frame, "request", None if shared else codec.motor_id, command)
        if error is None:
            where = f"0x{frame.arbitration_id:0{8 if frame.is_extended_id else 3}X}"
            error = f"{where} is no identifier of the {self.family.name} motors"
        return Decoded(frame, error=error)

    @staticmethod
    def _sender(codec: BoundCodec, others: Sequence[BoundCodec], frame: Frame) -> int | None:
        """The motor a reply comes from: None when the next motor's codec claims it too (a reply on an
        identifier every motor shares that does not name its sender: MyActuator's 0x79 on 0x300)."""
        other = next((c for c in others if c.motor_id != codec.motor_id), None)
        if other is not None and other.classify(frame)[0] is not FrameKind.NOT_OURS:
            return None
        return codec.motor_id

    def _decode_request(self, codec: BoundCodec, frame: Frame) -> Message:
        params = self._request_params
        options: dict[str, Any] = {"revision": codec.revision}
        for name, value in (
            ("model", codec.model),
            ("is_extended_id", frame.is_extended_id),
            ("is_fd", frame.is_fd),
        ):
            if name in params:
                options[name] = value
        try:
            command: Message = self.family.decode_request(frame.arbitration_id, frame.data, **options)
        except ValueError as exc:  # not ProtocolError: a revision or model the decoder refused
            raise ProtocolError(str(exc), raw=frame.data) from None
        return command


def _describe(ids: Sequence[int]) -> str:
    return f"{ids[0]}..{ids[-1]}" if ids and list(ids) == list(range(ids[0], ids[-1] + 1)) else str(ids)


#: A line of a text log that did not parse: (its line number in the file, the line, why).
BadLine = tuple[int, str, str]

#: python-can's text readers whose reading can go on after a line that does not parse (they read one
#: line at a time; what they learn from a header is kept): candump ``.log``, ``.asc``, ``.csv``, ``.trc``
_RESUMABLE = (can.CanutilsLogReader, can.ASCReader, can.CSVReader, can.TRCReader)


class LogFrames:
    """The data frames of a CAN log (candump ``.log``, ``.asc``, ``.blf``, ``.csv``, ...), read by
    python-can's ``can.LogReader``; error and remote frames are skipped and counted in ``skipped``.

    A line of a text log (candump, ASC, CSV, TRC) that does not parse is skipped: it is recorded in
    ``bad_lines`` with its line number (and passed to ``on_bad_line`` as it is met), and reading goes
    on with the next line. A candump line with an odd number of data hex digits (a line cut short, as a
    killed ``candump`` leaves its last one) is such a line.

    Args:
        source: a path, or an open text stream of candump lines (stdin).
        name: what messages call the source (default: the path, or the stream's ``name``).
        on_bad_line: called with ``(line number, line, why)`` for each line that does not parse.

    Raises:
        ValueError: a file python-can has no reader for, or one that does not parse at a place it cannot
            go on from (on iteration: a binary log's damaged part, such as BLF's BLFParseError and
            zlib.error; a text log that is not text).
        OSError: the file cannot be read.
    """

    def __init__(
        self,
        source: str | Path | TextIO,
        *,
        name: str | None = None,
        on_bad_line: Callable[[int, str, str], None] | None = None,
    ) -> None:
        self.source = source
        if name is None:
            name = str(source) if isinstance(source, str | Path) else getattr(source, "name", None)
        self.name: str = name if isinstance(name, str) else "<stream>"
        self.skipped = 0
        self.bad_lines: list[BadLine] = []
        self._on_bad_line = on_bad_line

    def __str__(self) -> str:
        return self.name

    def __iter__(self) -> Iterator[Frame]:
        with self._unparsed():
            if isinstance(self.source, str | Path):
                reader: Any = can.LogReader(self.source)
            else:  # an open text stream of candump lines (stdin)
                reader = can.io.CanutilsLogReader(self.source)
        lines: _Lines | None = None
        if isinstance(reader, _RESUMABLE):
            lines = _Lines(reader.file, candump=isinstance(reader, can.CanutilsLogReader))
            reader.file = lines  # type: ignore[assignment]  # (the readers only iterate and close it)
        with reader:
            messages = iter(reader)
            while True:
                try:
                    with self._unparsed():
                        message = next(messages, None)
                except ValueError as exc:
                    if lines is None or isinstance(exc.__cause__ or exc, UnicodeError):
                        raise
                    self._bad(lines, exc)
                    reader = _resumed(reader, lines)  # the reader's generator ended with its error
                    messages = iter(reader)
                    continue
                if message is None:
                    return
                if message.is_error_frame or message.is_remote_frame:
                    self.skipped += 1
                    continue
                try:
                    frame = frame_from_message(message, message.timestamp)
                except ValueError as exc:  # a frame that cannot exist (9 bytes in a classic frame)
                    if lines is None:
                        raise
                    self._bad(lines, exc)
                    continue
                yield frame

    def _bad(self, lines: _Lines, exc: BaseException) -> None:
        bad = (lines.number, lines.last.strip(), str(exc))
        self.bad_lines.append(bad)
        if self._on_bad_line is not None:
            self._on_bad_line(*bad)

    @contextlib.contextmanager
    def _unparsed(self) -> Iterator[None]:
        """A reader's error that is not ValueError or OSError, as ValueError naming the error."""
        try:
            yield
        except (ValueError, OSError):
            raise
        except Exception as exc:
            raise ValueError(f"{type(exc).__name__}: {exc}") from exc


class _Lines:
    """A text log's lines as python-can's reader takes them, counted (and candump's checked)."""

    def __init__(self, file: TextIO, *, candump: bool) -> None:
        self.file = file
        self.number = 0
        self.last = ""
        self._candump = candump
        self._pending: list[str] = []

    def __iter__(self) -> _Lines:
        return self

    def __next__(self) -> str:
        if self._pending:
            return self._pending.pop()
        self.last = next(self.file)
        self.number += 1
        if self._candump:
            _check_candump(self.last)
        return self.last

    def push(self, line: str) -> None:
        """Give ``line`` next (not counted: not the file's)."""
        self._pending.append(line)

    def close(self) -> None:
        self.file.close()


def _check_candump(line: str) -> None:
    """python-can reads a data field with an odd number of hex digits as if the last one were a byte
    (``241#9C3`` as 9C 03): a cut line, refused."""
    fields = line.split()
    if len(fields) < 3 or "#" not in fields[2]:
        return  # python-can refuses it itself
    data = fields[2].split("#", 1)[1]
    if data.startswith("#"):
        data = data[2:]
    if data[:1] not in ("R", "r") and len(data) % 2:
        raise ValueError(f"{fields[2]}: an odd number of data hex digits (a line cut short?)")


class _ResumedAsc(can.ASCReader):
    """An ASC reader that goes on after a bad line: its header (base, start time) was read already."""

    def _extract_header(self) -> None:
        return None


class _ResumedTrc(can.TRCReader):
    """A TRC reader that goes on after a bad line: its header (version, columns) was read already."""

    def _extract_header(self) -> None:  # type: ignore[override]  # (None: no first data line read)
        return None


def _resumed(reader: Any, lines: _Lines) -> Any:
    """A reader that goes on with ``lines`` where ``reader`` stopped, knowing what its header said."""
    again = copy.copy(reader)
    if isinstance(reader, can.CSVReader):
        lines.push("")  # what CSVReader skips as its header line
    elif isinstance(reader, can.ASCReader):  # (the same reader, its header not read again)
        again.__class__ = _ResumedAsc
    elif isinstance(reader, can.TRCReader):
        again.__class__ = _ResumedTrc
    return again


def read_log(
    source: str | Path | TextIO,
    *,
    name: str | None = None,
    on_bad_line: Callable[[int, str, str], None] | None = None,
) -> LogFrames:
    """:class:`LogFrames` of ``source`` (a path, or an open stream of candump lines)."""
    return LogFrames(source, name=name, on_bad_line=on_bad_line)


def parse_frame(text: str) -> Frame:
    """A frame written on the command line, in one of two forms:

    * candump's ``ID#DATA``: ``141#9C00000000000000``; an 8-digit id is extended (``00000064#...``);
      ``ID##F DATA`` is CAN FD with flags digit F (1: bit-rate switch), as candump writes it;
    * hex bytes with spaces, the identifier first: ``"241 9C 32 64 00 F4 01 2D 00"`` (a classic frame,
      extended if the identifier has more than 3 digits).

    Raises:
        ValueError: text in neither form, or a frame that cannot exist (id or length out of range).
    """
    text = text.strip()
    try:
        if "#" in text:
            ident, _, data = text.partition("#")
            fd = data.startswith("#")
            flags = int(data[1], 16) if fd and len(data) > 1 else 0
            payload = bytes.fromhex(data[2:] if fd else data)
            return Frame(
                arbitration_id=int(ident, 16),
                data=payload,
                is_extended_id=len(ident) > 3,
                is_fd=fd,
                bitrate_switch=bool(flags & 1),
            )
        ident, *octets = text.split()
        if any(len(octet) != 2 for octet in octets):
            raise ValueError("bytes are two hex digits each")
        return Frame(
            arbitration_id=int(ident, 16),
            data=bytes.fromhex("".join(octets)),
            is_extended_id=len(ident) > 3,
        )
    except (ValueError, IndexError) as exc:
        raise ValueError(
            f"{text!r} is not a frame: expected ID#DATA (141#9C00000000000000) or hex bytes with the "
            f"id first ('241 9C 32 64 00 F4 01 2D 00'): {exc}"
        ) from None

"""What ``servobus record`` writes: telemetry rows (CSV, JSONL), raw frames (candump), and its files.

* :class:`TapLink` wraps a FrameLink and shows every frame that went out (at its send report) and
  every frame that came in to a callback, before the Bus sees it; the Bus works as without it (a
  FrameLink itself: its send reports echo the Bus's handles). Logging both directions of any link
  is this: docs/recording.md has a runnable example.
* :class:`CandumpWriter` writes those frames through python-can's ``CanutilsLogWriter``, ``R``/``T``
  marking direction, so :class:`servobus.tools.logs.FrameDecoder` tells requests from replies on reading.
* :class:`TelemetryWriter` writes one row per decoded reply: ``time_s``, ``motor_id``, ``family``,
  ``reply``, the set-points in effect (``record --drive``) and the reply's fields
  (:func:`servobus.tools.logs.message_values`: units in the names).
* :class:`NewFiles` opens outputs without overwriting what exists (unless told: then the old file is
  replaced only when the new one is kept) and, on failure, removes only the files it created.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Self, TextIO

import can

from servobus.frame import Frame
from servobus.protocols import Reply
from servobus.tools.logs import Scalar, message_values
from servobus.transports.base import SendReporter
from servobus.transports.can import message_from_frame
from servobus.transports.contract import Consumer, LineRules
from servobus.transports.events import TransportEvent
from servobus.transports.stats import TransportStats

__all__ = ["CandumpWriter", "NewFiles", "TapLink", "TelemetryWriter", "telemetry_row"]

#: ``(frame, received, timestamp on the loop's clock)``
FrameCallback = Callable[[Frame, bool, float], object]


class TapLink:
    """A FrameLink around ``inner`` that shows ``on_frame`` every frame of both directions: each frame
    sent, once its send report says it left, and each frame received, before the Bus sees it. The
    way to log a link (``servobus record --log`` is built on it); the Bus works as without it.

    Wrap the transport and give the tap to the Bus::

        async with Bus(TapLink(SimTransport(devices=...), on_frame, clock=anyio.current_time)) as bus:
            ...

    ``on_frame(frame, received, timestamp)`` is called on the event loop:

    * ``received=False``: a frame the Bus sent, when the link reported it sent (``timestamp``: the
      link's sent time, else ``clock()``). A frame the link refused or dropped (its report carries a
      reason) is not shown: only what left is.
    * ``received=True``: every frame the link received, ours or not: replies, stream frames, other
      nodes' traffic, another controller's requests to our motors (``timestamp``: the frame's own,
      else ``clock()``). Frames in a batch are shown in order, before the Bus decodes the batch.

    The frames are the link's own objects (immutable); decode them with
    :class:`servobus.tools.logs.FrameDecoder`, or write them with :class:`CandumpWriter`. The callback
    runs on the receive and send-report paths: it must not block (hand slow work to a task or a
    queue) and must not raise (what it raises escapes into the link's receive or send-report path).

    It follows the FrameLink contract (:mod:`servobus.transports.contract`): its rules and stats are
    the inner link's, and the Bus's send handles are echoed to the Bus's reporter untouched. A send
    goes to ``inner`` with a handle of the tap's own that carries the frame and the caller's handle,
    so the tap knows which frame left whatever the inner link copies or re-encodes. Anything else
    (a transport's own API: ``unplug``, ``network``) is read from ``inner``. Opening and closing the
    tap opens and closes ``inner``.

    Args:
        inner: the link to wrap (a transport: ``SimTransport``, ``CanTransport``, ...), not yet open.
        on_frame: called with ``(frame, received, timestamp)`` for each frame, as above.
        clock: the clock the timestamps are on where a frame carries none: the event loop's
            (``anyio.current_time``; the Bus's, ``servobus.runtime.current().time``).
    """

    def __init__(self, inner: Any, on_frame: FrameCallback, clock: Callable[[], float]) -> None:
        self._inner = inner
        self._on_frame = on_frame
        self._clock = clock
        self.name: str = inner.name

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    @property
    def rules(self) -> LineRules:
        rules: LineRules = self._inner.rules
        return rules

    @property
    def is_open(self) -> bool:
        return bool(self._inner.is_open)

    async def open(self) -> None:
        await self._inner.open()

    async def close(self) -> None:
        await self._inner.close()

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    def stats(self) -> TransportStats:
        stats: TransportStats = self._inner.stats()
        return stats

    def send(self, frame: Frame, handle: object = None) -> None:
        self._inner.send(frame, _Tapped(frame, frame if handle is None else handle))

    def set_consumer(self, consumer: Consumer | None) -> None:
        if consumer is None:
            self._inner.set_consumer(None)
            return

        def tapped(frames: list[Frame]) -> object:
            now = self._clock()
            for frame in frames:
                self._on_frame(frame, True, frame.timestamp or now)
            return consumer(frames)

        self._inner.set_consumer(tapped)

    def set_send_reporter(self, reporter: SendReporter | None) -> None:
        if reporter is None:
            self._inner.set_send_reporter(None)
            return

        def tapped(handle: object, sent_at: float | None, reason: str | None) -> object:
            if not isinstance(handle, _Tapped):  # not sent through the tap: not the Bus's
                return None
            if reason is None:
                self._on_frame(handle.frame, False, sent_at if sent_at is not None else self._clock())
            return reporter(handle.handle, sent_at, reason)

        self._inner.set_send_reporter(tapped)

    def add_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        self._inner.add_listener(listener)

    def remove_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        self._inner.remove_listener(listener)


class _Tapped:
    """The handle the tap sends with: the frame it saw, and the sender's own handle."""

    __slots__ = ("frame", "handle")

    def __init__(self, frame: Frame, handle: object) -> None:
        self.frame = frame
        self.handle = handle


class CandumpWriter:
    """Frames to a candump log through python-can, stamped ``epoch + (loop time - origin)``."""

    def __init__(self, file: TextIO, *, channel: str = "can0", epoch: float, origin: float) -> None:
        self._writer = can.io.CanutilsLogWriter(file, channel=channel)
        self._offset = epoch - origin
        self.count = 0

    def write(self, frame: Frame, received: bool, timestamp: float) -> None:
        message = message_from_frame(frame)
        message.timestamp = timestamp + self._offset
        message.is_rx = received
        self._writer.on_message_received(message)
        self.count += 1

    def close(self) -> None:
        self._writer.stop()


def telemetry_row(
    time_s: float, family: str, motor_id: int, reply: Reply, setpoints: Mapping[str, Scalar] | None = None
) -> dict[str, Scalar]:
    """One row: ``time_s``, ``motor_id``, ``family``, ``reply`` (its class), the ``setpoints`` given
    (``setpoint_angle_deg``: the set-point in effect when the reply came), then the reply's fields."""
    row: dict[str, Scalar] = {
        "time_s": round(time_s, 6),
        "motor_id": motor_id,
        "family": family,
        "reply": type(reply).__name__,
    }
    if setpoints:
        row.update(setpoints)
    for name, value in message_values(reply).items():
        row.setdefault(name, value)  # a reply's own motor_id is the row's
    return row


class TelemetryWriter:
    """Rows as JSON lines, or as CSV.

    A CSV's columns are fixed by its header: those of the first rows, in the order they came. With
    ``reply_types`` above one (a recording that asks more than one kind of reply: LK's set-point and
    its angle read), the header waits for that many kinds of rows (or :data:`HOLD_ROWS` rows, or
    :meth:`flush`) and holds all their columns; a row leaves blank the columns it lacks. A row with a
    column the header lacks is not written and is counted in ``skipped`` (JSONL keeps every row).
    """

    #: the most rows a CSV holds back waiting for its reply types
    HOLD_ROWS = 1000

    def __init__(self, file: TextIO, fmt: str, *, reply_types: int = 1) -> None:
        if fmt not in ("csv", "jsonl"):
            raise ValueError(f"telemetry format {fmt!r} is not csv or jsonl")
        self._file = file
        self._fmt = fmt
        self._csv: csv.DictWriter[str] | None = None
        self._columns: frozenset[str] = frozenset()
        self._types = reply_types
        self._held: list[dict[str, Scalar]] = []
        self._kinds: set[tuple[str, ...]] = set()
        self.count = 0
        self.skipped = 0

    def write(self, row: dict[str, Scalar]) -> None:
        if self._fmt == "jsonl":
            self._file.write(json.dumps(row) + "\n")
            self.count += 1
            return
        if self._csv is None:
            self._held.append(row)
            self._kinds.add(tuple(row))
            if len(self._kinds) >= self._types or len(self._held) >= self.HOLD_ROWS:
                self.flush()
            return
        self._put(row)

    def flush(self) -> None:
        """Write the header and the rows held back for it (a CSV of fewer kinds than expected)."""
        if self._csv is not None or not self._held:
            return
        columns = list(dict.fromkeys(name for row in self._held for name in row))
        self._csv = csv.DictWriter(self._file, fieldnames=columns, lineterminator="\n", restval="")
        self._columns = frozenset(columns)
        self._csv.writeheader()
        held, self._held = self._held, []
        for row in held:
            self._put(row)

    def _put(self, row: dict[str, Scalar]) -> None:
        assert self._csv is not None
        if not self._columns.issuperset(row):
            self.skipped += 1
            return
        self._csv.writerow(row)
        self.count += 1

    def close(self) -> None:
        self.flush()
        self._file.close()


class NewFiles:
    """Output files opened for writing: an existing one only with ``force``; :meth:`discard` removes
    the ones that did not exist before (never a file this object did not create).

    With ``force``, an existing file is written as a temporary file beside it that replaces it when
    :meth:`close` keeps the output: a run that fails (:meth:`discard`) leaves the old file whole.
    """

    def __init__(self, *, force: bool = False) -> None:
        self.force = force
        self.created: list[Path] = []
        self._open: list[TextIO] = []
        self._replacing: list[tuple[Path, Path]] = []  # (temporary file, the existing file it replaces)

    def check(self, paths: Iterable[Path]) -> None:
        """Refuse up front what :meth:`open` would refuse.

        Raises:
            FileExistsError: a path exists and ``force`` is off.
        """
        for path in paths:
            if path.exists() and not self.force:
                raise FileExistsError(f"{path} exists (--force overwrites it)")

    def open(self, path: Path) -> TextIO:
        """``path`` open for writing text.

        Raises:
            FileExistsError: it exists and ``force`` is off.
            OSError: it cannot be created.
        """
        if self.force and path.exists():
            fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
            self._replacing.append((Path(name), path))
            file = open(fd, "w", encoding="utf-8", newline="")  # noqa: SIM115 - closed by close()
        else:
            file = path.open("x", encoding="utf-8", newline="")
            self.created.append(path)
        self._open.append(file)
        return file

    def close(self) -> None:
        """Close everything and keep it: the files written over existing ones replace them now."""
        self._close()
        for part, path in self._replacing:
            os.replace(part, path)
        self._replacing.clear()

    def discard(self) -> None:
        """Close everything and remove the files this object created; existing files stay as they were."""
        self._close()
        for path in [*self.created, *(part for part, _ in self._replacing)]:
            with contextlib.suppress(FileNotFoundError):
                os.remove(path)
        self.created.clear()
        self._replacing.clear()

    def _close(self) -> None:
        for file in self._open:
            if not file.closed:
                file.close()

"""How a :class:`~servobus.transports.can.CanTransport` writes to its python-can bus from a worker thread:
in order, with a minimum gap, and by its ENOBUFS policy (private).

python-can's ``send`` blocks on most interfaces, so a batch of queued frames is sent by
:meth:`BlockingSender.send_batch` in a worker thread (``anyio.to_thread``). What became of each frame
goes back to the loop in one :class:`SendReport`, handed over by the thread itself, so frames are
accounted for even when the task that awaited the batch was cancelled by a loss or a close.
"""

from __future__ import annotations

import contextlib
import errno
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import can

from servobus.frame import Frame

__all__ = ["BlockingSender", "SendReport", "buffer_full"]

_ENOBUFS_RETRY_S = 0.0005


@dataclass(slots=True)
class SendReport:
    """What the writer thread did with one batch (each entry is the queued item, an ``Outgoing``;
    times on the loop's clock)."""

    sent: list[tuple[Any, float]] = field(default_factory=list)
    stale: list[Any] = field(default_factory=list)
    purged: list[Any] = field(default_factory=list)
    enobufs_waits: int = 0
    enobufs_dropped: list[Any] = field(default_factory=list)
    error: BaseException | None = None


class BlockingSender:
    """The sending half of one CAN transport: gap, freshness and the ENOBUFS policy, in a thread.

    Args:
        min_gap_s: least time between the starts of two frames.
        enobufs: ``"wait"`` (retry until ``enobufs_timeout_s``, then drop) or ``"drop"`` (at once).
        send_timeout_s: the timeout given to python-can's ``send``.
        stale_after_s: a frame older than this when its turn comes is not sent.
    """

    def __init__(
        self,
        *,
        min_gap_s: float,
        enobufs: Literal["wait", "drop"],
        enobufs_timeout_s: float,
        send_timeout_s: float | None,
        stale_after_s: float | None,
    ) -> None:
        self.min_gap_s = min_gap_s
        self.enobufs = enobufs
        self.enobufs_timeout_s = enobufs_timeout_s
        self.send_timeout_s = send_timeout_s
        self.stale_after_s = stale_after_s
        self.abort = threading.Event()  # set by a loss or a close: cuts a gap's sleep short
        self._last_send = 0.0  # perf_counter of the last frame's start (writer thread only)

    def renew(self) -> None:
        """A new connection: its gaps may be slept again."""
        self.abort = threading.Event()

    def send_batch(
        self,
        bus: can.BusABC,
        batch: list[Any],
        shift: float,
        current: Callable[[], bool],
        report_to: Callable[[SendReport], object],
        to_message: Callable[[Frame], can.Message],
    ) -> None:
        """Writer thread: send ``batch`` (``Outgoing`` items) in order, honouring the gap and the policy.

        ``shift`` turns ``time.monotonic()`` into the loop's clock; ``current()`` says whether the
        connection still stands (a loss stops the batch: the frames not yet sent are purged, never
        written after the device comes back). The report goes to ``report_to`` (a thread-safe hand-over
        to the loop) in any case.
        """
        report = SendReport()
        clock = time.perf_counter
        stale_after_s = self.stale_after_s
        abort = self.abort
        for index, outgoing in enumerate(batch):
            if not current():
                report.purged = batch[index:]
                break
            if stale_after_s is not None and time.monotonic() + shift - outgoing.queued_at > stale_after_s:
                report.stale.append(outgoing)  # waited out an ENOBUFS stretch or a long gap
                continue
            if self.min_gap_s and (wait := self._last_send + self.min_gap_s - clock()) > 0:
                abort.wait(wait)  # a sleep that a loss or close cuts short
                if not current():
                    report.purged = batch[index:]
                    break
            sent = self._send_one(bus, to_message(outgoing.item), report)
            if sent is None:
                report.purged = batch[index + 1 :]
                break
            if sent:
                report.sent.append((outgoing, time.monotonic() + shift))
            else:
                report.enobufs_dropped.append(outgoing)
        with contextlib.suppress(RuntimeError):  # the loop is gone: nobody is left to count
            report_to(report)

    def _send_one(self, bus: can.BusABC, message: can.Message, report: SendReport) -> bool | None:
        """Send with the ENOBUFS policy: True sent, False dropped by the policy, None when the bus
        failed (``report.error`` says how).

        A full adapter buffer (ENOBUFS) and a stalled adapter (a serial write timeout, as python-can's
        slcan reports it) are both backpressure: wait and retry, or drop, by the policy.
        """
        give_up = time.perf_counter() + self.enobufs_timeout_s
        while True:
            try:
                bus.send(message, timeout=self.send_timeout_s)
            except can.CanError as exc:
                if not buffer_full(exc):
                    report.error = exc
                    return None
                if self.enobufs == "drop" or time.perf_counter() >= give_up:
                    return False
                report.enobufs_waits += 1
                time.sleep(_ENOBUFS_RETRY_S)
            except Exception as exc:
                report.error = exc
                return None
            else:
                self._last_send = time.perf_counter()
                return True


def buffer_full(exc: can.CanError) -> bool:
    """python-can's ways of saying "the adapter's send buffer is full, try again"."""
    if isinstance(exc, can.CanTimeoutError):
        return True
    code = getattr(exc, "error_code", None)
    if code in (errno.ENOBUFS, errno.EAGAIN):
        return True
    cause = exc.__cause__
    if isinstance(cause, OSError) and cause.errno in (errno.ENOBUFS, errno.EAGAIN):
        return True
    if type(cause).__name__ == "SerialTimeoutException":  # pyserial: a stalled adapter, not a lost one
        return True
    text = str(exc).lower()
    return "buffer full" in text or "write timeout" in text

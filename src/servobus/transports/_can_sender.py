"""How a :class:`~servobus.transports.can.CanTransport` writes to its python-can bus from a worker thread:
in order, with a minimum gap, and by its ENOBUFS policy (private).

A full adapter buffer (ENOBUFS) costs the loop at most one short wait per episode: the first frame
that meets it is retried for ``enobufs_timeout_s`` (a controller's queue drains a frame every
~0.13 ms at 1 Mbit/s, so a burst finds room at once); once a wait ran out the buffer is taken to
be full, and each later frame gets one try, not sent if refused, until one goes through. A
refused ENETDOWN is bus-off, a state of the link: that frame and the rest of its batch are not
sent (each would be refused the same), and the loop is told.

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

__all__ = ["BlockingSender", "SendReport", "buffer_full", "controller_off"]

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
    bus_off: list[Any] = field(default_factory=list)
    bus_off_cause: BaseException | None = None
    bus_off_at: float = 0.0  # when the adapter refused with ENETDOWN (loop clock)
    error: BaseException | None = None


class BlockingSender:
    """The sending half of one CAN transport: gap, freshness and the ENOBUFS policy, in a thread.

    Args:
        min_gap_s: least time between the starts of two frames.
        enobufs: ``"wait"`` (retry until ``enobufs_timeout_s``, then drop; while the buffer stays
            full, later frames get one try each) or ``"drop"`` (at once).
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
        self._full = False  # the adapter's buffer stayed full through a whole wait (writer thread only)

    def renew(self) -> None:
        """A new connection: its gaps may be slept again, and its buffer is waited for again."""
        self.abort = threading.Event()
        self._full = False

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
                if report.bus_off_cause is not None:
                    report.bus_off_at = time.monotonic() + shift
                    report.bus_off = batch[index:]  # each would be refused the same: not tried
                else:
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
        failed (``report.error`` says how) or is bus-off (``report.bus_off_cause``).

        A full adapter buffer (ENOBUFS) and a stalled adapter (a serial write timeout, as python-can's
        slcan reports it) are both backpressure: wait and retry, or drop, by the policy.
        """
        give_up = time.perf_counter() + self.enobufs_timeout_s
        while True:
            try:
                bus.send(message, timeout=self.send_timeout_s)
            except can.CanError as exc:
                if controller_off(exc):
                    report.bus_off_cause = exc
                    return None
                if not buffer_full(exc):
                    report.error = exc
                    return None
                if self.enobufs == "drop" or self._full:
                    return False
                if time.perf_counter() >= give_up:
                    self._full = True  # until a frame goes through, later ones are not waited for
                    return False
                report.enobufs_waits += 1
                time.sleep(_ENOBUFS_RETRY_S)
            except Exception as exc:
                report.error = exc
                return None
            else:
                self._last_send = time.perf_counter()
                self._full = False
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


def controller_off(exc: can.CanError) -> bool:
    """python-can's way of saying "the controller is bus-off" on a send: ENETDOWN (SocketCAN)."""
    code = getattr(exc, "error_code", None)
    cause = exc.__cause__
    return code == errno.ENETDOWN or (isinstance(cause, OSError) and cause.errno == errno.ENETDOWN)

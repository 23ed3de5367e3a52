"""The scheduler's part that decides what leaves when (:class:`Pacing`, a part of
:class:`~servobus.scheduler.Scheduler`): the in-flight limit, one exchange per key, a half-duplex
line's rest, keys held for a late reply, commands gone stale in the queue.

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable, Iterable, Sequence
from typing import TYPE_CHECKING

from servobus._request import FROM, Recent, Request, RequestState, illegal
from servobus.errors import TransportError

if TYPE_CHECKING:
    from servobus.protocols import BoundCodec

__all__ = ["Pacing"]

_FAILED = RequestState.FAILED
_SENDING = RequestState.SENDING
_TO_SENDING = FROM[_SENDING]
_NOTHING: tuple[Sequence[Request], Sequence[Request]] = ((), ())


class Pacing:
    """Requests out, in order and in time (the scheduler's state is declared here for the type checker)."""

    name: str
    max_in_flight: int
    stale_after_s: float | None
    report_within_s: float | None
    _queue: deque[Request]
    _pending: dict[Hashable, deque[Request]]
    _in_flight: dict[Request, None]
    _audit_at: float | None
    _held: dict[Hashable, float]
    _recent: Recent
    _doubtful: set[Hashable]
    _rest_until: float

    if TYPE_CHECKING:

        def _count(self, codec: BoundCodec, name: str) -> None: ...

        def _move(self, request: Request, state: RequestState) -> None: ...

    def blocking(self, keys: Iterable[Hashable], now: float) -> tuple[float | None, list[Request]]:
        """What a frame that skips the queue (a broadcast) waits for before it may go out: the requests
        in flight with one of ``keys``, and when the last hold of one of them ends (None: none held).

        Its replies come on ``keys``; while one is in flight or held for a late reply, a reply could
        answer the wrong request, as for a queued request (:meth:`poll`).
        """
        held = self._held
        ends = [held[key] for key in keys if key in held and held[key] > now]
        flying = [request for key in keys for request in self._pending.get(key, ())]
        return (max(ends) if ends else None), flying

    @property
    def quiet(self) -> bool:
        """Nothing is in flight with a key and no key is held: no request would wait (:meth:`busy`)."""
        return not self._pending and not self._held

    def busy(self, key: Hashable | None, now: float) -> bool:
        """Would a request with ``key`` wait now: one with that key is in flight, or the key is held
        for a late reply (:meth:`poll`)?"""
        if key is None:
            return False
        if key in self._pending:
            return True
        until = self._held.get(key)
        return until is not None and until > now

    def poll(self, now: float) -> tuple[Sequence[Request], Sequence[Request]]:
        """What happens now: the requests that may leave, in order (they become SENDING: hand their
        frames to the link), and the commands that waited too long for their turn (FAILED with a
        TransportError in ``request.error``: tell their callers).

        A request whose key is already on the wire waits for that exchange to end: two replies with
        one key cannot be told apart, so a duplicated or late frame could otherwise answer the
        second request with the first one's data.
        """
        held = self._held
        if held:
            for key in [k for k, until in held.items() if until <= now]:
                del held[key]
                # its late reply never came: it may come yet, while its late window is open
                if any(e[0] > now for e in self._recent.late.get(key, ())):
                    self._doubtful.add(key)
        if self._rest_until:
            if now < self._rest_until:
                return _NOTHING
            self._rest_until = 0.0  # the rest is over (and no longer a deadline)
        if not self._queue:
            return _NOTHING
        out: list[Request] = []
        stale: list[Request] = []
        waiting: deque[Request] = deque()
        queue = self._queue
        limit = self.stale_after_s
        pending, in_flight = self._pending, self._in_flight
        while queue and len(in_flight) < self.max_in_flight:
            request = queue.popleft()
            if limit is not None and request.queued_at is not None and now - request.queued_at > limit:
                request.error = TransportError(
                    f"{self.name}: {request.describe()} not sent (stale: waited its turn longer than "
                    f"stale_after_s={limit:g} s)"
                )
                self._move(request, _FAILED)
                self._count(request.codec, "failed")
                self._count(request.codec, "not_sent_stale")
                stale.append(request)
                continue
            key = request.key
            if key is not None and (key in pending or key in held):
                waiting.append(request)
                continue
            if request.state not in _TO_SENDING:  # (the table, read on the hot path)
                illegal(request, _SENDING)
            request.state = _SENDING
            request.attempts += 1
            request.handed_at = now
            in_flight[request] = None
            if key is not None:
                pending[key] = deque((request,))
            out.append(request)
        waiting.extend(queue)
        self._queue = waiting
        if out and self._audit_at is None and self.report_within_s is not None:
            self._audit_at = now + self.report_within_s  # (see Timing.expire)
        return out, stale

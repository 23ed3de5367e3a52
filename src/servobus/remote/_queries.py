"""Zenoh's threads -> the bridge's event loop, for queries (:class:`Queries`): bounded and fair.

On Zenoh's thread, before anything of it is decoded, a query is sized (``_limits.oversized``: too
long, it is dropped) and put in a lane of its class:

* **commanders**: ``request`` and ``read`` queries whose client id is that of a live client (its
  liveliness token is declared), one lane per client;
* **readers**: the rest: ``read`` and ``request`` queries of a client id without a token, one lane
  per id; ``metrics`` (it carries no id), one lane;
* **info**: ``info`` queries (a client's ``connect`` asks one), a class of their own, so that no
  flood of reads or metrics refuses a client its connection.

A lane or a class whose queue is full drops the query there (its client's get ends at once), counted
``shed``. The loop begins queries round-robin over each class's lanes, each lane up to its quota in
flight, each class up to its cap (and readers' at most ``READS_PER_S``), so a reader's flood neither
delays a commander's query nor grows the bridge, and an id forged afresh for each query buys a lane
but no more of its class's queue, flight or rate. The numbers are in ``_limits``.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Awaitable, Callable, Hashable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import anyio
import anyio.abc

from servobus import runtime
from servobus.remote import _limits, wire
from servobus.remote._session import to_loop

if TYPE_CHECKING:
    from servobus.remote._served import Served

logger = logging.getLogger("servobus.remote.bridge")

Handler = Callable[["Served", Any], Awaitable[None]]
_Item = tuple[Handler, "Served", Any]  # (handler, served, the zenoh.Query)


@dataclass(frozen=True, slots=True)
class Quota:
    """What one class of queries may hold: waiting and in flight per lane and in all, and how many
    may begin a second (None: no rate), in bursts of ``burst``."""

    lane_waiting: int
    lane_running: int
    waiting: int
    running: int
    per_s: float | None = None
    burst: int = 1


COMMANDERS = Quota(
    _limits.COMMANDER_WAITING,
    _limits.COMMANDER_RUNNING,
    _limits.COMMANDERS_WAITING,
    _limits.COMMANDERS_RUNNING,
)
INFOS = Quota(
    _limits.INFO_WAITING,
    _limits.INFO_RUNNING,
    _limits.INFO_WAITING,
    _limits.INFO_RUNNING,
    _limits.INFOS_PER_S,
    _limits.INFO_BURST,
)
READERS = Quota(
    _limits.READER_WAITING,
    _limits.READER_RUNNING,
    _limits.READERS_WAITING,
    _limits.READERS_RUNNING,
    _limits.READS_PER_S,
    _limits.READ_BURST,
)


class _Class:
    """One class's lanes (insertion order: the round-robin's), what each has in flight, its tokens."""

    def __init__(self, quota: Quota) -> None:
        self.quota = quota
        self.lanes: dict[Hashable, deque[_Item]] = {}
        self.waiting = 0
        self.running = 0
        self.running_by: dict[Hashable, int] = {}
        self.tokens = float(quota.burst)
        self.refilled: float | None = None

    def admit(self, lane: Hashable, item: _Item) -> bool:
        """(Under the lock) Queue ``item`` in ``lane``; False: a queue is full."""
        queue = self.lanes.get(lane)
        full = queue is not None and len(queue) >= self.quota.lane_waiting
        if full or self.waiting >= self.quota.waiting:
            return False
        if queue is None:
            queue = self.lanes[lane] = deque()
        queue.append(item)
        self.waiting += 1
        return True

    def take(self, now: float, out: list[tuple[_Class, Hashable, _Item]]) -> float | None:
        """(Under the lock) Move to ``out`` what may begin now, round-robin; the seconds until the
        rate allows the next (None: no wait for the rate)."""
        quota = self.quota
        if quota.per_s is not None:
            if self.refilled is not None:
                self.tokens = min(float(quota.burst), self.tokens + (now - self.refilled) * quota.per_s)
            self.refilled = now
        moved = True
        while moved and self.waiting and self.running < quota.running:
            moved = False
            for lane in list(self.lanes):
                if self.running >= quota.running:
                    break
                if quota.per_s is not None and self.tokens < 1.0:
                    return (1.0 - self.tokens) / quota.per_s
                if self.running_by.get(lane, 0) >= quota.lane_running:
                    continue
                queue = self.lanes.pop(lane)  # (and put back last: the next lane goes first next)
                item = queue.popleft()
                if queue:
                    self.lanes[lane] = queue
                self.waiting -= 1
                self.running += 1
                self.running_by[lane] = self.running_by.get(lane, 0) + 1
                if quota.per_s is not None:
                    self.tokens -= 1.0
                out.append((self, lane, item))
                moved = True
        return None

    def done(self, lane: Hashable) -> None:
        """(Under the lock) A query of ``lane`` ended."""
        self.running -= 1
        left = self.running_by[lane] - 1
        if left:
            self.running_by[lane] = left
        else:
            del self.running_by[lane]

    def drain(self) -> list[_Item]:
        """(Under the lock) Every query waiting, taken out."""
        items = [item for queue in self.lanes.values() for item in queue]
        self.lanes.clear()
        self.waiting = 0
        return items


class Queries:
    """The queries one bridge's loop (``lane``) serves; ``live(public id)``: whether a client's
    token lives (read from Zenoh's threads: a set's ``in``)."""

    def __init__(self, lane: runtime.Runtime, live: Callable[[str], bool]) -> None:
        self._lane = lane
        self._live = live
        self._commanders = _Class(COMMANDERS)
        self._readers = _Class(READERS)
        self._infos = _Class(INFOS)
        self._lock = threading.Lock()
        self._woken = False  # a wake-up is on its way to the loop
        self._closed = False
        self._event = anyio.Event()

    def callback(self, handler: Handler, served: Served) -> Callable[[Any], None]:
        """A queryable's callback: each query, sized and queued, is answered by
        ``await handler(served, query)`` on the loop, in :meth:`run`."""

        def callback(query: Any) -> None:
            key = str(query.key_expr)
            payload = query.payload
            # (a query refused is dropped, not answered: a reply could block this thread; and it is
            # dropped with this callback's last reference to it: ``query.drop()`` would give up and
            # take again the GIL, which the loop then waits for once more)
            if _limits.oversized(served, key, payload):
                return
            leaf = key.rsplit("/", 1)[-1]
            lane: Hashable = leaf
            kind = self._infos if leaf == "info" else self._readers
            if leaf in ("request", "read"):
                # (at most REQUEST_BYTES: a cheap copy) the client id, after version and kind
                lane = b"" if payload is None else payload.to_bytes()[2 : 2 + wire.CLIENT_ID_BYTES]
                if len(lane) == wire.CLIENT_ID_BYTES and self._live(wire.public_id(lane.hex())):
                    kind = self._commanders
            with self._lock:
                taken = not self._closed and kind.admit(lane, (handler, served, query))
                wake = taken and not self._woken
                self._woken = self._woken or wake
            if not taken:
                _limits.count(served, "shed")
            elif wake:
                to_loop(self._lane, self._wake)

        return callback

    def _wake(self) -> None:
        self._event.set()

    async def run(self) -> None:
        """Begin the queued queries as their quotas allow, each in a task of its own; when this
        ends, those still waiting are answered nothing, at once."""
        try:
            async with anyio.create_task_group() as group:
                while True:
                    self._event = anyio.Event()
                    with self._lock:
                        self._woken = False
                    wait_s = self._begin(group)
                    with anyio.move_on_after(math.inf if wait_s is None else wait_s):
                        await self._event.wait()
        finally:
            with self._lock:
                self._closed = True
                items = self._commanders.drain() + self._readers.drain() + self._infos.drain()
            for _, _, query in items:
                query.drop()

    def _begin(self, group: anyio.abc.TaskGroup) -> float | None:
        """Start what may begin; the seconds until a rate (readers', info's) allows more (None: no wait)."""
        now = self._lane.time()
        out: list[tuple[_Class, Hashable, _Item]] = []
        with self._lock:
            self._commanders.take(now, out)
            waits = [w for w in (self._readers.take(now, out), self._infos.take(now, out)) if w is not None]
        for kind, lane, item in out:
            group.start_soon(self._serve, kind, lane, item)
        return min(waits, default=None)

    async def _serve(self, kind: _Class, lane: Hashable, item: _Item) -> None:
        handler, served, query = item
        try:
            await handler(served, query)
        except Exception:  # (the handlers answer their own errors: this is a bug, logged)
            logger.exception("%s: answering a query failed", query.key_expr)
            query.drop()
        finally:
            with self._lock:
                kind.done(lane)
            self._event.set()

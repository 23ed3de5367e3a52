"""Zenoh -> the bridge's event loop (:class:`Handover`, for set-points).

Zenoh receives on its own threads; the bridge's state lives on its event loop. Each kind of message
is handed over by its own rule:

* set-points (:meth:`Handover.latest`): they wait in Zenoh's own ring channel of each subscriber
  (Rust: no Python, no GIL per message on Zenoh's side) and each bus's tick takes them first
  thing (:meth:`Handover.take`), so a flood costs the loop a few microseconds a message and never takes
  the GIL from it; beyond ``SETPOINTS_WAITING`` untaken, Zenoh drops the oldest. A tick decodes at
  most ``MESSAGES_PER_TICK`` of them (the rest wait for the next, in order), each at most its bus's
  motors' set-points (checked from the header first), so no sender makes a tick long. Then, of each
  client's messages on each key, at most the ``PER_SLOT`` latest wait for their handler, in order;
  an older one beyond them is dropped there (counted ``overwritten``), so a client that publishes
  faster than the bridge takes them costs no queue and no lag, while one whose successive batches
  name different motors loses none of them to the next unless it is that far ahead. Only a client
  whose liveliness token lives has slots of its own (checked before anything is decoded, by the
  hash of the secret id its messages carry), at most one
  per key of its bus; the messages of every other id share one slot per bus that holds the latest
  one only and is taken every ``TOKENLESS_PERIOD_S`` (:meth:`Handover.drain`): set-points under
  fresh random ids, however many, cost the loop at most one message a period and take no room from
  the clients that may command;
* queries: per client and kind, with quotas (:class:`servobus.remote._queries.Queries`);
* liveliness: never dropped, coalesced per client (:class:`servobus.remote._tokens.Tokens`, no
  need of this class).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import anyio
import zenoh

from servobus.remote import _limits

if TYPE_CHECKING:
    from servobus.remote._served import Served

logger = logging.getLogger("servobus.remote.bridge")

PER_SLOT = 8  # set-point messages of one client on one key that may wait for the loop
SETPOINTS_WAITING = 1024  # set-point messages a subscriber's channel holds per tick (beyond: oldest dropped)
#: set-point messages decoded per tick at most (each holds at most its bus's motors' set-points, so a
#: tick's decoding is bounded however many clients send): the rest wait for the next tick, in order
MESSAGES_PER_TICK = 64
TOKENLESS_PERIOD_S = 0.01  # how often the set-points of ids without a live token are taken (the latest)


class Handover:
    """The set-points Zenoh's channels hold for one bridge's event loop (every method runs there)."""

    def __init__(self, backlog: int) -> None:
        self._limit = backlog
        # (key, client id) -> [served, [(key, message, when it came), ...] oldest first, how many were
        # dropped]; (bus, None): the one slot of a bus's set-points from ids without a live token
        self._latest: dict[tuple[str, bytes | None], list[Any]] = {}
        self._slots: dict[tuple[str, bytes], int] = {}  # (bus, client id) -> its slots waiting
        self._tokenless: dict[str, Callable[[Served, tuple[str, bytes, int]], object]] = {}  # bus -> handler
        self._pulled: dict[str, list[tuple[Any, Callable[[Any], None]]]] = {}  # bus -> (subscriber, callback)
        self._new: list[tuple[Callable[[Served, tuple[str, bytes, int]], object], tuple[str, bytes]]] = []
        self.dropped = 0  # set-points dropped because the backlog was full

    def latest(
        self,
        handler: Callable[[Served, tuple[str, bytes, int]], object],
        served: Served,
        admits: Callable[[bytes], bool],
    ) -> Callable[[Any], None]:
        """A callback for set-points: ``handler(served, (key, payload, arrived_ns))`` on the loop,
        for each client's latest ``PER_SLOT`` messages on each key, oldest first, if ``admits(its
        secret id)`` (its token lives); else the latest of all the others'
        (:meth:`drain`)."""
        per_client = len(served.motors) + 1  # (a slot per key: the bus's, each motor's)
        self._tokenless[served.name] = handler

        def callback(sample: Any) -> None:
            if _limits.oversized(served, str(sample.key_expr), sample.payload):  # (before any copy)
                return
            key, payload = str(sample.key_expr), sample.payload.to_bytes()
            client = payload[2:18]  # (the client's id: in wire.py's header, after version and kind)
            arrived_ns = time.time_ns()
            if not admits(client):
                entry = self._latest.get((served.name, None))
                if entry is None:
                    self._latest[(served.name, None)] = [served, [(key, payload, arrived_ns)], 0]
                else:
                    entry[1][0] = (key, payload, arrived_ns)
                    entry[2] += 1
                return
            slot = (key, client)
            entry = self._latest.get(slot)
            if entry is not None:
                waiting = entry[1]
                waiting.append((key, payload, arrived_ns))
                if len(waiting) > PER_SLOT:
                    del waiting[0]
                    entry[2] += 1
                return
            mine = self._slots.get((served.name, client), 0)
            if len(self._latest) >= self._limit or mine >= per_client:
                self.dropped += 1
                return
            self._slots[(served.name, client)] = mine + 1
            self._latest[slot] = [served, [(key, payload, arrived_ns)], 0]
            self._new.append((handler, slot))  # (taken at the end of this pull)

        return callback

    @staticmethod
    def channel() -> Any:
        """The handler to declare a set-point subscriber with (then :meth:`pull` it)."""
        return zenoh.handlers.RingChannel(SETPOINTS_WAITING)

    def pull(self, served: Served, subscriber: Any, callback: Callable[[Any], None]) -> None:
        """Have :meth:`take` give each message of ``subscriber`` (declared with :meth:`channel`) to
        ``callback`` (one of :meth:`latest`)."""
        self._pulled.setdefault(served.name, []).append((subscriber, callback))

    def take(self, served: Served) -> None:
        """(The loop: ``served``'s tick, first thing) take the set-point messages waiting in Zenoh's
        channels of ``served``, and hand each client's latest to the handler now: what came since
        the last tick goes out in this one."""
        for subscriber, callback in self._pulled.get(served.name, ()):
            for _ in range(SETPOINTS_WAITING):  # (however fast they come, the tick gets back to its work)
                try:
                    sample = subscriber.try_recv()
                    if sample is None:
                        break
                    callback(sample)
                except Exception:  # one bad sample must not end the tick (and with it the bridge)
                    logger.exception("taking a set-point message failed")
        new, self._new = self._new, []
        budget = MESSAGES_PER_TICK
        for at, (handler, slot) in enumerate(new):
            if budget <= 0:  # (the rest wait for the next tick, in order: a tick's cost is bounded)
                self._new[:0] = new[at:]
                break
            budget -= self._take(handler, slot)

    async def drain(self) -> None:
        """Take the latest set-point message of ids without a live token, each bus's, every
        ``TOKENLESS_PERIOD_S`` (they are refused there, or taken if the token came meanwhile)."""
        while True:
            await anyio.sleep(TOKENLESS_PERIOD_S)
            for name, handler in self._tokenless.items():
                if (name, None) in self._latest:
                    self._take(handler, (name, None))

    def _take(
        self, handler: Callable[[Served, tuple[str, bytes, int]], object], slot: tuple[str, bytes | None]
    ) -> int:
        """Hand the messages waiting in ``slot`` to ``handler``; how many."""
        served, waiting, overwritten = self._latest.pop(slot)
        client = slot[1]
        if client is not None:
            mine = self._slots.pop((served.name, client)) - 1
            if mine:
                self._slots[(served.name, client)] = mine
        served.counts["overwritten"] += overwritten
        for item in waiting:
            try:
                handler(served, item)
            except Exception:  # one bad message must not end anything
                logger.exception("handling set-points failed")
        return len(waiting)

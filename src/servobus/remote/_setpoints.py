"""The bridge's set-points (:class:`Setpoints`): taken from the clients' messages, and sent by each
bus's own tick loop.

A set-point carries the time after which it must not be applied (never held longer than
``max_valid_s``). :meth:`Setpoints.take` checks a message (from its header first: a client without
a live token costs no decoding), keeps each motor's latest in its bus's ``Served.held`` and makes the
client the motor's holder. :meth:`Setpoints.run` is a bus's tick loop: every tick it sends the fresh
set-points through ``Bus.cycle()``, drops the stale ones, and stops a motor whose set-point has been
stale for ``stop_after_s`` (:class:`~servobus.remote._stops.Stops`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from servobus import runtime
from servobus.limits import LimitExceeded
from servobus.remote import wire
from servobus.remote._clients import Clients
from servobus.remote._handover import Handover
from servobus.remote._served import Held, Served
from servobus.remote._stops import Stops
from servobus.remote.keys import Keys
from servobus.ticks import ticks
from servobus.timing import format_duration

__all__ = ["Setpoints"]

logger = logging.getLogger("servobus.remote.bridge")


class Setpoints:
    """The set-point rules of one bridge (its limits) and the loop that applies them, on the bridge's
    event loop. The set-points themselves live in each bus's :class:`Served`."""

    def __init__(
        self,
        *,
        node: str,
        keys: Keys,
        clients: Clients,
        stops: Stops,
        lane: runtime.Runtime,
        handover: Handover,
        take_tokens: Callable[[], None],
        hz: float,
        stop_after_s: float,
        max_valid_s: float,
    ) -> None:
        self._node = node
        self._keys = keys
        self._clients = clients
        self._stops = stops
        self._lane = lane
        self._handover = handover
        self._take_tokens = take_tokens  # (the token events waiting, taken now)
        self._hz = hz
        self._stop_after_s = stop_after_s
        self._max_valid_s = max_valid_s

    def take(self, served: Served, item: tuple[str, bytes, int]) -> None:
        """Take a set-point message (``key``, ``payload``, the wall ns Zenoh handed it over)."""
        key, payload, _ = item
        clients = self._clients
        try:
            # (from the header alone, before the commands are decoded: no more set-points than the
            # bus has motors, and a client without a live token costs no decoding at all)
            secret, count = wire.peek_setpoints(payload)
            if count > len(served.motors):
                raise wire.WireError(f"{count} set-points for a bus of {len(served.motors)} motors")
            client = clients.public(secret)
            if client not in clients.live:
                self._take_tokens()  # (a token declared just before its first set-points)
                if client not in clients.live:
                    served.counts["refused"] += count
                    return
            message = wire.decode_setpoints(served.schemas.get, payload)
            if key.endswith("/setpoint"):
                _, mid, _ = self._keys.parse_motor(key)
                if [m for m, _ in message.items] != [mid]:
                    raise wire.WireError(f"a set-point on motor {mid}'s key must be for motor {mid} alone")
        except (wire.WireError, ValueError) as exc:
            served.counts["malformed"] += 1
            logger.debug("%s: malformed set-points dropped: %s", key, exc)
            return
        left_ns = min(
            message.deadline_unix_ns - time.time_ns(),
            message.deadline_unix_ns - message.sent_unix_ns,
            int(self._max_valid_s * 1e9),
        )
        if left_ns <= 0:
            served.counts["stale"] += len(message.items)
            return
        expires = self._lane.time() + left_ns / 1e9
        for mid, command in message.items:
            if clients.holder(served, mid, client) is not None:
                served.counts["refused"] += 1
                continue
            motor = served.motors[mid]
            # beyond its limits: refused here (or clamped), not by the tick it would void
            if motor.limits is not None:
                try:
                    command = motor.limited(command)
                except LimitExceeded as exc:
                    served.counts["limited"] += 1
                    logger.debug("%s: set-point for motor %s refused: %s", key, mid, exc)
                    continue
            try:  # what the motor's codec refuses (a command its revision lacks) never reaches a tick
                motor.codec.encode(command)
            except ValueError as exc:
                served.counts["malformed"] += 1
                logger.debug("%s: set-point for motor %s refused by its codec: %s", key, mid, exc)
                continue
            held = served.held.get(mid)
            if held is not None and held.client == client and _older(message.seq, held.seq):
                served.counts["reordered"] += 1
                continue
            served.counts["setpoints"] += 1
            served.commanded[mid] += 1
            if served.owners.get(mid) != client:  # (a motor released or revoked has no owner)
                clients.take(served, mid, client)
            served.stale_since.pop(mid, None)
            served.held[mid] = Held(client, message.seq, command, message.sent_unix_ns, expires)

    async def run(self, served: Served) -> None:
        """``served``'s tick loop: every tick, its fresh set-points through ``Bus.cycle()``."""
        clock = self._lane.time
        handover = self._handover
        stop_after_s = self._stop_after_s
        async for _ in ticks(self._hz, spin_s=0.0):
            self._take_tokens()  # (a client that left loses its motors before anything of it is sent)
            handover.take(served)  # (the set-points that came since the last tick)
            now = clock()
            items = []
            fresh: list[Held] = []
            for mid, held in list(served.held.items()):
                if now > held.expires:
                    del served.held[mid]
                    served.stale_since[mid] = held.expires
                    served.counts["expired"] += 1
                    continue
                items.append((served.motors[mid], held.command))
                if not held.applied:
                    fresh.append(held)
            due = [mid for mid, since in served.stale_since.items() if now - since >= stop_after_s]
            if due:
                for mid in due:
                    self._clients.revoke(served, mid)
                self._stops.stop(served, due, f"set-points stale for {format_duration(stop_after_s)}")
            if not items:
                continue
            handed = time.time_ns()
            for held in fresh:
                held.applied = True
                served.to_wire_ns.append(handed - held.sent_unix_ns)
            served.counts["applied"] += len(fresh)
            try:
                await served.bus.cycle(items)
            except ValueError:  # (checked on intake; if a codec still refuses, the tick must go on)
                logger.exception("%s/%s: a tick's set-points were refused; dropped", self._node, served.name)
                served.counts["malformed"] += len(items)
                for motor, _ in items:  # stale from now: stopped after stop_after_s like any other
                    served.held.pop(motor.motor_id, None)
                    served.stale_since[motor.motor_id] = now


def _older(seq: int, than: int) -> bool:
    """Whether sequence number ``seq`` came before ``than`` (32-bit, wrapping)."""
    return seq != than and ((than - seq) & 0xFFFFFFFF) < 0x80000000

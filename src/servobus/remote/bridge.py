"""The bridge: local Buses served to other computers over a Zenoh session.

The control loop stays next to its bus. Each bus gets its own tick task that sends, every tick, the
latest fresh set-point of each motor through ``Bus.cycle()``; clients only change what that loop
sends. A set-point carries the time after which it must not be applied (and is never held longer
than ``max_valid_s``): a stale one is dropped and counted, and a motor whose set-point has been stale
for ``stop_after_s``, or whose commanding client is gone (its liveliness token vanished), gets its
safe command. Requests run one command through the Bus and answer with the typed reply or the
error. States (latest reply, online flag, fault) are published as they change, at most ``state_hz``
per motor, and every second besides (a client that joins late sees them).

Zenoh calls us on its own threads; every callback only hands its bytes to the event loop, where all
the state lives; set-points and liveliness samples wait in Zenoh's own channels instead, for the
loop to take them (``_handover``, ``_tokens``). Of the set-points, only each client's latest few
messages on each key wait for the loop (an older one is dropped); queries wait in bounded queues per
client and kind, served round-robin with quotas (``_queries``; beyond them they are dropped on
Zenoh's thread, and counted); a message longer than its key allows is dropped before anything of it
is decoded (``_limits``); a client's liveliness changes are never dropped.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from types import TracebackType
from typing import Any, Self

import anyio
import anyio.abc
import zenoh

from servobus import runtime
from servobus.bus import Bus, Motor, MotorStatus
from servobus.bus.safety import stop_motors
from servobus.protocols import Command
from servobus.remote import _requests, _tokens, wire
from servobus.remote._clients import Clients
from servobus.remote._handover import Handover
from servobus.remote._queries import Queries
from servobus.remote._served import Held, Served
from servobus.remote._session import close_session
from servobus.remote._withdraw import withdraw
from servobus.remote.keys import Keys
from servobus.ticks import ticks

__all__ = ["Bridge"]

logger = logging.getLogger(__name__)

_BACKLOG = 4096  # set-point slots waiting for the loop; more are dropped (queries: _queries)
_LEFT = "client left"  # why a motor is stopped when its client's token went
_METRICS_EVERY_S = 0.5  # a metrics answer is computed again at most this often (it sorts 20k samples)


class Bridge:
    """Serve local buses over Zenoh as ``servobus/<node>/<bus>/<motor>/...``.

    Use ``async with Bridge(node, {"can0": (bus, motors)}, config=...) as bridge:`` inside the blocks
    of the Buses it serves (the Buses' own safe stop still runs when they are left). The session
    configuration comes from :func:`servobus.remote.security.bridge_config` (loopback only unless
    authenticated).

    A motor a client commanded gets its safe command when that client leaves (its process ends or
    its link is lost for the 1 s lease), and when its set-point stays stale for ``stop_after_s``:
    the Bus's ``safe`` kind, or ``"stop"`` for a Bus whose ``safe`` is None. A motor a client made
    safe itself (a stop, shutdown or brake request) is no longer that client's. A client that loses
    a motor (it left, its set-points went stale, it was taken over, the bridge closes) loses with it
    its commands still queued on the Bus, withdrawn before the stop is submitted (``_withdraw``); one
    stopped for stale set-points takes the motor back by a set-point or a stop request, not by the
    requests it may have sent before the stop.

    Args:
        node: this bridge's name, the second key segment (a host name, ``arm``).
        buses: ``{bus name: (Bus, motors)}``; the motors are those served (ids unique per bus).
        config: the ``zenoh.Config`` (default: ``bridge_config(node)``, loopback, no auth).
        hz: the tick rate of each bus's set-point loop.
        state_hz: the most states published per motor per second.
        stop_after_s: how long a motor's set-point may be stale before the motor is stopped.
        max_valid_s: the longest a set-point is held, whatever deadline its client gave.
        allow_takeover: whether a client may command a motor another live client holds.
    """

    def __init__(
        self,
        node: str,
        buses: Mapping[str, tuple[Bus, Sequence[Motor]]],
        *,
        config: Any = None,
        hz: float = 1000.0,
        state_hz: float = 100.0,
        stop_after_s: float = 0.05,
        max_valid_s: float = 1.0,
        allow_takeover: bool = False,
    ) -> None:
        for name, value in (("hz", hz), ("state_hz", state_hz), ("max_valid_s", max_valid_s)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} must be a positive number")
        if not (math.isfinite(stop_after_s) and stop_after_s >= 0):
            raise ValueError(f"stop_after_s={stop_after_s!r} must be >= 0")
        self.keys = Keys(node)
        self.node = node
        self.hz = float(hz)
        self.state_hz = float(state_hz)
        self.stop_after_s = float(stop_after_s)
        self.max_valid_s = float(max_valid_s)
        self.served = {name: Served(name, bus, motors) for name, (bus, motors) in buses.items()}
        if not self.served:
            raise ValueError("a bridge needs at least one bus")
        self._config = config
        self._session: Any = None
        self._declared: list[Any] = []
        self.clients = Clients(allow_takeover)
        self._group: anyio.abc.TaskGroup | None = None
        self._lane: runtime.Runtime | None = None
        self._stops, self._stops_in = anyio.create_memory_object_stream[tuple[Served, list[Motor]]](math.inf)
        self._handover: Handover | None = None
        self._queries: Queries | None = None
        self._metrics: dict[str, tuple[float, bytes]] = {}  # bus -> (when, the metrics answer)
        self._tokens: _tokens.Tokens | None = None
        self.stop_log: deque[tuple[int, str, int, str]] = deque(maxlen=1000)  # (unix ns, bus, id, why)
        self._closing = False

    # ---- life cycle ----

    async def __aenter__(self) -> Self:
        if self._config is None:
            from servobus.remote.security import bridge_config

            self._config = bridge_config(self.node)
        self._lane = runtime.current()
        self._handover = Handover(_BACKLOG)
        self._queries = Queries(self._lane, self.clients.live.__contains__)
        self._session = await anyio.to_thread.run_sync(zenoh.open, self._config)
        try:
            self._declare()
            self._group = anyio.create_task_group()
            await self._group.__aenter__()
        except BaseException:
            await self._close()
            raise
        assert self._tokens is not None
        self._group.start_soon(self._queries.run)
        self._group.start_soon(self._handover.drain)
        self._group.start_soon(self._tokens.run)
        self._group.start_soon(self._take_stops)
        for served in self.served.values():
            self._group.start_soon(self._tick, served)
            self._group.start_soon(self._publish_states, served)
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        try:
            if self._group is not None:
                with anyio.CancelScope(shield=True):  # the clients' motors, before the tasks go
                    self._closing = True  # (no token makes a client live again now)
                    self.clients.live.clear()  # (closing: their requests meanwhile are refused)
                    released = []  # (every bus's motors released before the first stop is awaited)
                    for served in self.served.values():
                        held = set(served.owners) | set(served.held) | set(served.stale_since)
                        released.append((served, self._release(served, sorted(held), "bridge closing")))
                    for served, motors in released:
                        if motors:
                            await self._send_stop(served, motors)
                self._group.cancel_scope.cancel()
                await self._group.__aexit__(exc_type, exc, tb)
        finally:
            self._group = None
            await self._close()
        return None

    async def _close(self) -> None:
        session, self._session = self._session, None
        declared, self._declared = self._declared, []
        await close_session(session, declared)

    def _declare(self) -> None:
        session, keys, handover, lane = self._session, self.keys, self._handover, self._lane
        queries = self._queries
        assert handover is not None and lane is not None and queries is not None
        tokens = session.liveliness().declare_subscriber(keys.clients, _tokens.channel(), history=True)
        self._declared.append(tokens)
        self._tokens = _tokens.Tokens(tokens, self._on_clients)
        for served in self.served.values():
            name = served.name
            setpoints = handover.latest(self._on_setpoints, served, self.clients.admits)
            query = queries.callback(self._on_query, served)
            for key in (keys.bus(name, "setpoints"), keys.motor(name, "*", "setpoint")):
                self._declared.append(session.declare_subscriber(key, handover.channel()))
                handover.pull(served, self._declared[-1], setpoints)
            self._declared += [
                session.declare_queryable(keys.motor(name, "*", "request"), query),
                session.declare_queryable(keys.motor(name, "*", "read"), query),
                session.declare_queryable(keys.bus(name, "info"), queries.callback(self._on_info, served)),
                session.declare_queryable(
                    keys.bus(name, "metrics"), queries.callback(self._on_metrics, served)
                ),
            ]
            for mid in served.motors:
                served.publishers[mid] = session.declare_publisher(keys.motor(name, mid, "state"))
                self._declared.append(served.publishers[mid])
            served.bus.subscribe(served.changed)
            served.bus.subscribe_status(functools.partial(self._on_status, served))
        # Last: a client that sees the bridge alive finds every bus's keys declared (a wildcard info
        # query sent as soon as the token shows must not miss the buses declared after it).
        self._declared.append(session.liveliness().declare_token(keys.alive))

    # ---- clients ----

    def _take_tokens(self) -> None:
        """(The loop) the token events waiting, now rather than at the next poll: a client's token
        reaches the bridge before its first query (``connect`` asks for ``info``), so once that is
        answered its set-points and requests find it live."""
        if self._tokens is not None:
            batch = self._tokens.take()
            if batch:
                self._on_clients(batch)

    def _on_clients(self, batch: dict[str, tuple[bool, bool]]) -> None:
        """(The loop) clients' tokens came or went (``{public id: (went, alive)}``, ``_tokens``); a
        client whose token went, even for an instant, has its motors stopped."""
        gone = set()
        for client, (went, alive) in batch.items():
            if went:
                self.clients.left(client)
                gone.add(client)
            if alive and not self._closing:
                self.clients.live.add(client)
        if not gone:
            return
        for served in self.served.values():
            held = [mid for mid, owner in served.owners.items() if owner in gone]
            self._stop(served, held, _LEFT)

    def _stop(self, served: Served, motor_ids: Iterable[int], why: str) -> None:
        """Release the motors (set-points, holder) and send each its safe command, in a task."""
        motors = self._release(served, motor_ids, why)
        if motors:
            try:
                self._stops.send_nowait((served, motors))
            except (anyio.BrokenResourceError, anyio.ClosedResourceError):  # (closed: stopped on exit)
                logger.warning("%s/%s: the bridge is closed: no stop for %s", self.node, served.name, motors)

    def _release(self, served: Served, motor_ids: Iterable[int], why: str) -> list[Motor]:
        """Release the motors, withdraw their holders' commands still queued (before the stop is
        submitted: they would follow it) and write down why they are stopped; the motors."""
        motors = [served.motors[mid] for mid in motor_ids]
        for motor in motors:
            withdraw(served, motor.motor_id, why, client_left=why == _LEFT)
            served.release(motor.motor_id)
        if motors:
            served.counts["stops"] += len(motors)
            now = time.time_ns()
            self.stop_log.extend((now, served.name, m.motor_id, why) for m in motors)
            ids = [m.motor_id for m in motors]
            logger.warning("%s/%s: stopping motors %s (%s)", self.node, served.name, ids, why)
        return motors

    async def _take_stops(self) -> None:
        assert self._group is not None
        async with self._stops_in:
            try:
                async for served, motors in self._stops_in:
                    self._group.start_soon(self._send_stop, served, motors)
            finally:  # (cancelled: the stops queued meanwhile still go; _send_stop is shielded)
                while True:
                    try:
                        served, motors = self._stops_in.receive_nowait()
                    except (anyio.WouldBlock, anyio.EndOfStream):
                        break
                    self._group.start_soon(self._send_stop, served, motors)

    async def _send_stop(self, served: Served, motors: list[Motor]) -> None:
        """The motors' safe commands, past the watchdog, again until acknowledged or the Bus's
        ``safe_timeout_s`` ended (what the Bus's own safe stop does); shielded."""
        commands: dict[Motor, Command] = {}
        for motor in motors:
            command = served.stop_commands[motor.motor_id]
            if command is not None:
                commands[motor] = command
        with anyio.CancelScope(shield=True):
            try:
                outcome = await stop_motors(served.bus, commands, served.bus.safe_timeout_s)
            except Exception:  # the bridge must outlive a stop that failed; it is logged
                logger.exception("%s/%s: the stop of %s failed", self.node, served.name, motors)
                return
        missing = [m.motor_id for m in commands if m not in outcome.acknowledged]
        if missing:
            logger.warning("%s/%s: motors %s did not acknowledge their stop", self.node, served.name, missing)

    # ---- set-points ----

    def _on_setpoints(self, served: Served, item: tuple[str, bytes, int]) -> None:
        """Take a set-point message (``key``, ``payload``, the wall ns Zenoh handed it over)."""
        key, payload, _ = item
        try:
            # (from the header alone, before the commands are decoded: no more set-points than the
            # bus has motors, and a client without a live token costs no decoding at all)
            secret, count = wire.peek_setpoints(payload)
            if count > len(served.motors):
                raise wire.WireError(f"{count} set-points for a bus of {len(served.motors)} motors")
            client = self.clients.public(secret)
            if client not in self.clients.live:
                self._take_tokens()  # (a token declared just before its first set-points)
                if client not in self.clients.live:
                    served.counts["refused"] += count
                    return
            message = wire.decode_setpoints(served.schemas.get, payload)
            if key.endswith("/setpoint"):
                _, mid, _ = self.keys.parse_motor(key)
                if [m for m, _ in message.items] != [mid]:
                    raise wire.WireError(f"a set-point on motor {mid}'s key must be for motor {mid} alone")
        except (wire.WireError, ValueError) as exc:
            served.counts["malformed"] += 1
            logger.debug("%s: malformed set-points dropped: %s", key, exc)
            return
        left_ns = min(
            message.deadline_unix_ns - time.time_ns(),
            message.deadline_unix_ns - message.sent_unix_ns,
            int(self.max_valid_s * 1e9),
        )
        if left_ns <= 0:
            served.counts["stale"] += len(message.items)
            return
        assert self._lane is not None
        expires = self._lane.time() + left_ns / 1e9
        for mid, command in message.items:
            if self.clients.holder(served, mid, client) is not None:
                served.counts["refused"] += 1
                continue
            try:  # what the motor's codec refuses (a command its revision lacks) never reaches a tick
                served.motors[mid].codec.encode(command)
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
                self.clients.take(served, mid, client)
            served.stale_since.pop(mid, None)
            served.held[mid] = Held(client, message.seq, command, message.sent_unix_ns, expires)

    async def _tick(self, served: Served) -> None:
        assert self._lane is not None
        clock = self._lane.time
        handover = self._handover
        assert handover is not None
        async for _ in ticks(self.hz, spin_s=0.0):
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
            due = [mid for mid, since in served.stale_since.items() if now - since >= self.stop_after_s]
            if due:
                for mid in due:
                    self.clients.revoke(served, mid)
                self._stop(served, due, f"set-points stale for {self.stop_after_s * 1e3:.0f} ms")
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
                logger.exception("%s/%s: a tick's set-points were refused; dropped", self.node, served.name)
                served.counts["malformed"] += len(items)
                for motor, _ in items:  # stale from now: stopped after stop_after_s like any other
                    served.held.pop(motor.motor_id, None)
                    served.stale_since[motor.motor_id] = now

    # ---- requests, info, metrics ----

    async def _on_query(self, served: Served, query: zenoh.Query) -> None:
        await _requests.answer(served, query, self.keys, self.clients)

    async def _on_info(self, served: Served, query: zenoh.Query) -> None:
        self._take_tokens()
        limits = {
            "hz": self.hz,
            "state_hz": self.state_hz,
            "stop_after_s": self.stop_after_s,
            "max_valid_s": self.max_valid_s,
        }
        body = json.dumps(served.info(self.node, limits)).encode()
        # (on the bus's own key: the answers to a wildcard query, servobus/N/*/info, stay apart)
        await _requests.reply(query, self.keys.bus(served.name, "info"), body)

    async def _on_metrics(self, served: Served, query: zenoh.Query) -> None:
        assert self._lane is not None
        now = self._lane.time()
        cached = self._metrics.get(served.name)
        if cached is None or now - cached[0] >= _METRICS_EVERY_S:  # (not a sort per query)
            cached = self._metrics[served.name] = (now, json.dumps(served.metrics()).encode())
        await _requests.reply(query, self.keys.bus(served.name, "metrics"), cached[1])

    # ---- states ----

    def _on_status(self, served: Served, status: MotorStatus) -> None:
        assert self._lane is not None
        mid = status.motor.motor_id
        if served.motors.get(mid) is status.motor and mid in served.publishers:
            served.publish(mid, self._lane.time())

    async def _publish_states(self, served: Served) -> None:
        assert self._lane is not None
        period = 1.0 / self.state_hz
        while True:
            await anyio.sleep(period / 2)
            served.publish_due(self._lane.time(), period)

    # ---- numbers ----

    @property
    def dropped_events(self) -> int:
        """Set-points dropped on arrival because the backlog was full (queries refused on arrival
        are counted in each bus's ``shed`` and ``oversized``)."""
        return self._handover.dropped if self._handover is not None else 0

    def metrics(self) -> dict[str, dict[str, Any]]:
        """Each served bus's metrics: the Bus's, the bridge's counters, set-point-to-wire latency."""
        return {name: served.metrics() for name, served in self.served.items()}


def _older(seq: int, than: int) -> bool:
    """Whether sequence number ``seq`` came before ``than`` (32-bit, wrapping)."""
    return seq != than and ((than - seq) & 0xFFFFFFFF) < 0x80000000

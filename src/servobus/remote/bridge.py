"""The bridge: local Buses served to other computers over a Zenoh session.

The control loop stays next to its bus. Each bus gets its own tick task that sends, every tick, the
latest fresh set-point of each motor through ``Bus.cycle()``; clients only change what that loop
sends. A set-point carries the time after which it must not be applied (and is never held longer
than ``max_valid_s``): a stale one is dropped and counted, and a motor whose set-point has been stale
for ``stop_after_s``, or whose commanding client is gone (its liveliness token vanished), gets its
safe command. Requests run one command through the Bus and answer with the typed reply or the
error. States (latest reply, online flag, fault) are published as they change, at most ``state_hz``
per motor.

Zenoh calls us on its own threads; every callback only hands its bytes to the event loop, where all
the state lives. Of the set-points, only each client's latest message on each key waits for the loop
(a newer one replaces it); queries wait in a bounded backlog (beyond it they are dropped on Zenoh's
thread, and counted); a client's liveliness changes are never dropped.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from types import TracebackType
from typing import Any, Self

import anyio
import anyio.abc
import zenoh

from servobus import runtime
from servobus.bus import Bus, Motor, MotorStatus
from servobus.errors import ServobusError
from servobus.protocols import Command
from servobus.remote import wire
from servobus.remote._served import Held, Served
from servobus.remote._session import close_session, sample_kind
from servobus.remote.keys import Keys
from servobus.safety import stop_motors
from servobus.ticks import ticks

__all__ = ["Bridge"]

logger = logging.getLogger(__name__)

_BACKLOG = 4096  # set-points and queries waiting for the loop; more are dropped on Zenoh's thread


class Bridge:
    """Serve local buses over Zenoh as ``servobus/<node>/<bus>/<motor>/...``.

    Use ``async with Bridge(node, {"can0": (bus, motors)}, config=...) as bridge:`` inside the blocks
    of the Buses it serves (the Buses' own safe stop still runs when they are left). The session
    configuration comes from :func:`servobus.remote.security.bridge_config` (loopback only unless
    authenticated).

    A motor a client commanded gets its safe command when that client leaves (its process ends or
    its link is lost for the 1 s lease), and when its set-point stays stale for ``stop_after_s``:
    the Bus's ``safe`` kind, or ``"stop"`` for a Bus whose ``safe`` is None. A motor a client made
    safe itself (a stop, shutdown or brake request) is no longer that client's.

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
        self.allow_takeover = allow_takeover
        self.served = {name: Served(name, bus, motors) for name, (bus, motors) in buses.items()}
        if not self.served:
            raise ValueError("a bridge needs at least one bus")
        self._config = config
        self._session: Any = None
        self._declared: list[Any] = []
        self._clients: set[str] = set()  # public ids of the clients whose token is alive
        self._public: dict[str, str] = {}  # secret id -> public id (a cache)
        self._group: anyio.abc.TaskGroup | None = None
        self._lane: runtime.Runtime | None = None
        self._events, self._events_in = anyio.create_memory_object_stream[tuple[Any, tuple[Any, ...]]](
            math.inf
        )
        self._stops, self._stops_in = anyio.create_memory_object_stream[tuple[Served, list[Motor]]](math.inf)
        self._backlog = 0  # events handed to the loop and not yet taken (approximate: two threads)
        # (key, client id) -> [served, the latest set-point message, when it came, how many it replaced]
        self._latest: dict[tuple[str, bytes], list[Any]] = {}
        self._latest_lock = threading.Lock()
        self.dropped_events = 0  # set-points and queries dropped because _BACKLOG were waiting
        self.stop_log: deque[tuple[int, str, int, str]] = deque(maxlen=1000)  # (unix ns, bus, id, why)

    # ---- life cycle ----

    async def __aenter__(self) -> Self:
        if self._config is None:
            from servobus.remote.security import bridge_config

            self._config = bridge_config(self.node)
        self._lane = runtime.current()
        self._session = await anyio.to_thread.run_sync(zenoh.open, self._config)
        try:
            self._declare()
            self._group = anyio.create_task_group()
            await self._group.__aenter__()
        except BaseException:
            await self._close()
            raise
        self._group.start_soon(self._take_events)
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
        session, keys = self._session, self.keys
        self._declared.append(
            session.liveliness().declare_subscriber(keys.clients, self._on_liveliness, history=True)
        )
        self._declared.append(session.liveliness().declare_token(keys.alive))
        for served in self.served.values():
            name = served.name
            setpoints = self._setpoints_callback(served)
            query = self._handed(self._on_query, served)
            self._declared += [
                session.declare_subscriber(keys.bus(name, "setpoints"), setpoints),
                session.declare_subscriber(keys.motor(name, "*", "setpoint"), setpoints),
                session.declare_queryable(keys.motor(name, "*", "request"), query),
                session.declare_queryable(keys.motor(name, "*", "read"), query),
                session.declare_queryable(keys.bus(name, "info"), self._handed(self._on_info, served)),
                session.declare_queryable(keys.bus(name, "metrics"), self._handed(self._on_metrics, served)),
            ]
            for mid in served.motors:
                served.publishers[mid] = session.declare_publisher(keys.motor(name, mid, "state"))
                self._declared.append(served.publishers[mid])
            served.bus.subscribe(served.changed)
            served.bus.subscribe_status(functools.partial(self._on_status, served))

    # ---- Zenoh's threads -> the loop ----

    def _handed(
        self,
        handler: Callable[[Served, Any], None],
        served: Served,
        extract: Callable[[Any], Any] | None = None,
    ) -> Callable[[Any], None]:
        """A Zenoh callback that hands ``extract(item)`` (or the item, a query) to ``handler``, which
        runs in the bridge's intake task (so it may start tasks), in the order Zenoh called; beyond
        ``_BACKLOG`` waiting it drops the item here, on Zenoh's thread (a query: answered nothing)."""
        lane = self._lane
        assert lane is not None
        put = self._put_event

        def callback(item: Any) -> None:
            if self._backlog >= _BACKLOG:
                self.dropped_events += 1
                if extract is None:
                    item.drop()
                return
            self._backlog += 1
            try:
                lane.call_soon_threadsafe(put, handler, (served, extract(item) if extract else item))
            except RuntimeError:  # the loop is closed: we are shutting down
                logger.debug("a zenoh callback after the loop closed was dropped")

        return callback

    def _put_event(self, handler: Any, args: tuple[Any, ...]) -> None:
        try:
            self._events.send_nowait((handler, args))
        except (anyio.BrokenResourceError, anyio.ClosedResourceError):  # closing
            self._backlog -= 1
            if hasattr(args[-1], "drop"):
                args[-1].drop()

    async def _take_events(self) -> None:
        async with self._events_in:
            async for handler, args in self._events_in:
                self._backlog -= 1
                try:
                    handler(*args)
                except Exception:  # one bad event must not end the bridge's intake
                    logger.exception("%s: handling a message failed", self.node)

    def _setpoints_callback(self, served: Served) -> Callable[[zenoh.Sample], None]:
        """A Zenoh callback for set-points: only the latest message of each client on each key waits
        for the loop (a newer one replaces it there, counted ``overwritten``), so a client that
        publishes faster than the bridge takes them costs no queue and no lag, only replaced batches."""
        lane = self._lane
        assert lane is not None
        take = self._take_setpoints

        def callback(sample: zenoh.Sample) -> None:
            key, payload = _payload(sample)
            slot = (key, payload[2:18])  # (the client's id: wire.py's header, version and kind first)
            with self._latest_lock:
                entry = self._latest.get(slot)
                if entry is not None:
                    entry[1:] = [payload, time.time_ns(), entry[3] + 1]
                    return
                if len(self._latest) >= _BACKLOG:
                    self.dropped_events += 1
                    return
                self._latest[slot] = [served, payload, time.time_ns(), 0]
            try:
                lane.call_soon_threadsafe(take, slot)
            except RuntimeError:  # the loop is closed: we are shutting down
                logger.debug("set-points after the loop closed were dropped")

        return callback

    def _take_setpoints(self, slot: tuple[str, bytes]) -> None:
        with self._latest_lock:
            served, payload, arrived_ns, overwritten = self._latest.pop(slot)
        served.counts["overwritten"] += overwritten
        try:
            self._on_setpoints(served, (slot[0], payload, arrived_ns))
        except Exception:  # one bad message must not end anything
            logger.exception("%s: handling set-points failed", self.node)

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        """(Zenoh's thread) a client's token came or went: handed to the loop, never dropped."""
        item = (str(sample.key_expr).rsplit("/", 1)[-1], sample_kind(sample))
        assert self._lane is not None
        try:
            self._lane.call_soon_threadsafe(self._on_client, item)
        except RuntimeError:  # the loop is closed: we are shutting down
            logger.debug("a liveliness change after the loop closed was dropped")

    # ---- clients ----

    def _on_client(self, item: tuple[str, str]) -> None:
        client, kind = item
        if kind == "PUT":
            self._clients.add(client)
            return
        self._clients.discard(client)
        for served in self.served.values():
            self._stop(
                served, [mid for mid, owner in served.owners.items() if owner == client], "client left"
            )

    def _client(self, secret: str) -> str:
        """The public id of the client whose messages carry ``secret``."""
        found = self._public.get(secret)
        if found is None:
            if len(self._public) > 4096:
                self._public.clear()
            found = self._public[secret] = wire.public_id(secret)
        return found

    def _holder(self, served: Served, mid: int, client: str) -> str | None:
        """The live client other than ``client`` that holds motor ``mid``; None: free to command."""
        owner = served.owners.get(mid)
        if owner is None or owner == client or owner not in self._clients or self.allow_takeover:
            return None
        return owner

    def _stop(self, served: Served, motor_ids: Iterable[int], why: str) -> None:
        """Release the motors (set-points, holder) and send each its safe command, in a task."""
        motors = [served.motors[mid] for mid in motor_ids]
        if not motors:
            return
        for motor in motors:
            served.release(motor.motor_id)
        served.counts["stops"] += len(motors)
        now = time.time_ns()
        self.stop_log.extend((now, served.name, m.motor_id, why) for m in motors)
        ids = [m.motor_id for m in motors]
        logger.warning("%s/%s: stopping motors %s (%s)", self.node, served.name, ids, why)
        self._stops.send_nowait((served, motors))

    async def _take_stops(self) -> None:
        assert self._group is not None
        async with self._stops_in:
            async for served, motors in self._stops_in:
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
            message = wire.decode_setpoints(served.schemas.get, payload)
            if key.endswith("/setpoint"):
                _, mid, _ = self.keys.parse_motor(key)
                if [m for m, _ in message.items] != [mid]:
                    raise wire.WireError(f"a set-point on motor {mid}'s key must be for motor {mid} alone")
        except (wire.WireError, ValueError) as exc:
            served.counts["malformed"] += 1
            logger.debug("%s: malformed set-points dropped: %s", key, exc)
            return
        client = self._client(message.client_id)
        if client not in self._clients:
            served.counts["refused"] += len(message.items)
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
            if self._holder(served, mid, client) is not None:
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
            served.owners[mid] = client
            served.stale_since.pop(mid, None)
            served.held[mid] = Held(client, message.seq, command, message.sent_unix_ns, expires)

    async def _tick(self, served: Served) -> None:
        assert self._lane is not None
        clock = self._lane.time
        async for _ in ticks(self.hz, spin_s=0.0):
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

    # ---- requests ----

    def _on_query(self, served: Served, query: zenoh.Query) -> None:
        assert self._group is not None
        self._group.start_soon(self._answer, served, query)

    async def _answer(self, served: Served, query: zenoh.Query) -> None:
        try:
            schema, result = await self._outcome(served, query)
        except BaseException:  # cancelled (the bridge is closing): answered nothing, at once
            _finish(query)
            raise
        await _reply(query, str(query.key_expr), wire.encode_result(schema, result))

    async def _outcome(self, served: Served, query: zenoh.Query) -> tuple[wire.Schema, wire.Result]:
        """The result of a query on ``request`` or ``read``, and the schema to encode it with."""
        schema = next(iter(served.schemas.values()))  # (for an error before the motor is known)
        try:
            try:
                bus, mid, leaf = self.keys.parse_motor(str(query.key_expr))
            except ValueError as exc:  # a client's key (servobus/N/B/x/request): malformed, not a bug
                raise wire.WireError(str(exc)) from None
            motor = served.motors.get(mid)
            if bus != served.name or motor is None:  # (servobus/N/*/3/request: one motor per request)
                raise wire.WireError(f"no motor {mid} on bus {served.name}")
            schema = served.schemas[mid]
            payload = query.payload
            request = wire.decode_request(schema, payload.to_bytes() if payload is not None else b"")
            return schema, await self._run(served, motor, leaf, request)
        except wire.WireError as exc:
            served.counts["malformed"] += 1
            return schema, wire.Result(error=ValueError(f"malformed request: {exc}"))
        except PermissionError as exc:
            served.counts["refused"] += 1
            return schema, wire.Result(error=exc)
        except Exception as exc:  # a bug must not leave the client waiting; it is logged here
            logger.exception("%s: request failed", query.key_expr)
            return schema, wire.Result(error=exc)

    async def _run(self, served: Served, motor: Motor, leaf: str, request: wire.Request) -> wire.Result:
        """Run one request through the Bus; the Bus's error as a value.

        Raises:
            PermissionError: a command through ``read``, a client without a token, a motor another
                live client holds.
        """
        command, mid = request.command, motor.motor_id
        if leaf == "read":
            served.counts["reads"] += 1
            if not type(command).READ:
                raise PermissionError(f"{type(command).__name__} is not a read: send it as a request")
        else:
            served.counts["requests"] += 1
            client = self._client(request.client_id)
            if client not in self._clients:
                raise PermissionError("this client has no liveliness token: it may only read")
            holder = self._holder(served, mid, client)
            if holder is not None:
                raise PermissionError(f"motor {mid} on {served.name} is held by another client ({holder})")
            if command in served.safe_commands[mid]:
                # The client makes the motor safe itself (stop, off, brake): leaving must not undo it.
                served.release(mid)
            elif not type(command).READ:
                served.owners[mid] = client
        try:
            return wire.Result(reply=await served.bus.request(motor, command, timeout_s=request.timeout_s))
        except ServobusError as exc:
            return wire.Result(error=exc)

    def _on_info(self, served: Served, query: zenoh.Query) -> None:
        assert self._group is not None
        limits = {
            "hz": self.hz,
            "state_hz": self.state_hz,
            "stop_after_s": self.stop_after_s,
            "max_valid_s": self.max_valid_s,
        }
        body = json.dumps(served.info(self.node, limits)).encode()
        # (on the bus's own key: the answers to a wildcard query, servobus/N/*/info, stay apart)
        self._group.start_soon(_reply, query, self.keys.bus(served.name, "info"), body)

    def _on_metrics(self, served: Served, query: zenoh.Query) -> None:
        assert self._group is not None
        body = json.dumps(served.metrics()).encode()
        self._group.start_soon(_reply, query, self.keys.bus(served.name, "metrics"), body)

    # ---- states ----

    def _on_status(self, served: Served, status: MotorStatus) -> None:
        mid = status.motor.motor_id
        if mid in served.publishers:
            self._publish(served, mid)

    def _publish(self, served: Served, mid: int) -> None:
        motor = served.motors[mid]
        fault = motor.fault.flags if motor.fault is not None else None
        state = wire.State(mid, time.time_ns(), motor.online is not False, motor.state, fault)
        try:
            served.publishers[mid].put(wire.encode_state(served.schemas[mid], state))
        except wire.WireError as exc:
            logger.debug("state of motor %s not encodable: %s", mid, exc)
            return
        served.counts["states"] += 1
        served.dirty.discard(mid)
        assert self._lane is not None
        served.published[mid] = self._lane.time()

    async def _publish_states(self, served: Served) -> None:
        assert self._lane is not None
        period = 1.0 / self.state_hz
        while True:
            await anyio.sleep(period / 2)
            now = self._lane.time()
            for mid in list(served.dirty):
                if now - served.published.get(mid, -period) >= period:
                    self._publish(served, mid)

    # ---- numbers ----

    def metrics(self) -> dict[str, dict[str, Any]]:
        """Each served bus's metrics: the Bus's, the bridge's counters, set-point-to-wire latency."""
        return {name: served.metrics() for name, served in self.served.items()}


def _finish(query: Any) -> None:
    """No more answers to ``query``: the client's get ends now (not at its timeout)."""
    query.drop()


async def _reply(query: Any, key: str, payload: bytes) -> None:
    """Answer ``query`` and end it, on a worker thread: Zenoh's reply follows the congestion control
    the querier chose, and one that blocks (a client that reads no more) must not block the loop."""

    def reply() -> None:
        try:
            query.reply(key, payload)
        except Exception:  # the client went away meanwhile
            logger.debug("reply to %s failed", key, exc_info=True)
        finally:
            query.drop()

    with anyio.CancelScope(shield=True):  # (answered once it is begun: a cancelled task still ends it)
        await anyio.to_thread.run_sync(reply)


def _payload(sample: zenoh.Sample) -> tuple[str, bytes]:
    return str(sample.key_expr), sample.payload.to_bytes()


def _older(seq: int, than: int) -> bool:
    """Whether sequence number ``seq`` came before ``than`` (32-bit, wrapping)."""
    return seq != than and ((than - seq) & 0xFFFFFFFF) < 0x80000000

"""The bridge: local Buses served to other computers over a Zenoh session.

The control loop stays next to its bus. Each bus gets its own tick task that sends, every tick, the
latest fresh set-point of each motor through ``Bus.cycle()``; clients only change what that loop
sends. A set-point carries the time after which it must not be applied: a stale one is dropped and
counted, and a motor whose set-point has been stale for ``stop_after_s``, or whose commanding client
is gone (its liveliness token vanished), gets the Bus's safe command. Requests run one command
through the Bus and answer with the typed reply or the error. States (latest reply, online flag,
fault) are published as they change, at most ``state_hz`` per motor.

Zenoh calls us on its own threads; every callback only hands its bytes to the event loop
(``runtime.call_soon_threadsafe``), where all the state lives.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

import anyio
import anyio.abc
import zenoh

from servobus import runtime
from servobus._version import __version__
from servobus.bus import Bus, Motor, MotorStatus
from servobus.errors import ServobusError
from servobus.protocols import Reply
from servobus.remote import wire
from servobus.remote._session import close_session, sample_kind
from servobus.remote.keys import Keys, check_name
from servobus.scheduler import Traffic
from servobus.ticks import ticks

__all__ = ["Bridge"]

logger = logging.getLogger(__name__)

_PENDING = 4096  # Zenoh callbacks waiting for the intake task; more are dropped and counted
_LATENCY_KEPT = 20_000  # set-point -> wire samples kept for the percentiles


@dataclass(slots=True)
class _Held:
    """A motor's latest set-point: who sent it, until when it may be applied, whether it went out."""

    client_id: str
    seq: int
    command: Any
    sent_unix_ns: int
    expires: float  # the loop's clock
    applied: bool = False


class _Served:
    """One bus as the bridge serves it: its motors, set-points, owners and counters."""

    def __init__(self, name: str, bus: Bus, motors: Sequence[Motor]) -> None:
        self.name = check_name("bus", name)
        self.bus = bus
        self.motors: dict[int, Motor] = {}
        for motor in motors:
            if motor.motor_id in self.motors:
                raise ValueError(f"bus {name}: two motors with id {motor.motor_id} (keys name motors by id)")
            self.motors[motor.motor_id] = motor
        self.schemas = {mid: wire.Schema.of(m.codec.family) for mid, m in self.motors.items()}
        self.safe_commands = {mid: _safe_commands(m) for mid, m in self.motors.items()}
        self.held: dict[int, _Held] = {}
        self.stale_since: dict[int, float] = {}  # motor -> when its set-point expired (loop clock)
        self.owners: dict[int, str] = {}
        self.dirty: set[int] = set()
        self.published: dict[int, float] = {}
        self.publishers: dict[int, Any] = {}
        self.to_wire_ns: deque[int] = deque(maxlen=_LATENCY_KEPT)
        self.counts = dict.fromkeys(
            (
                "setpoints",  # set-points received, well-formed
                "applied",  # set-points that went out at least once
                "stale",  # arrived past their deadline
                "expired",  # went stale while held (not renewed in time)
                "reordered",  # older than the one held from the same client
                "refused",  # a motor another live client holds, or a client with no token
                "malformed",  # messages that did not parse or were not a motor's command
                "requests",
                "reads",
                "stops",  # safe stops sent because a client vanished or went stale
                "states",  # states published
            ),
            0,
        )

    def changed(self, motor: Motor, traffic: Traffic, reply: Reply) -> None:
        """(The Bus's subscriber) the motor's state is to be published."""
        self.dirty.add(motor.motor_id)

    def info(self, node: str, bridge: Bridge) -> dict[str, Any]:
        return {
            "node": node,
            "bus": self.name,
            "servobus": __version__,
            "wire": wire.VERSION,
            "hz": bridge.hz,
            "state_hz": bridge.state_hz,
            "stop_after_s": bridge.stop_after_s,
            "safe": self.bus.safe,
            "motors": [
                {
                    "id": mid,
                    "family": m.codec.family,
                    "revision": m.codec.revision.name,
                    "link": m.codec.link,
                    "schema": self.schemas[mid].digest,
                }
                for mid, m in sorted(self.motors.items())
            ],
        }

    def metrics(self) -> dict[str, Any]:
        samples = sorted(self.to_wire_ns)

        def pct(q: float) -> float | None:
            return samples[min(len(samples) - 1, int(q * len(samples)))] / 1e6 if samples else None

        return {
            "bus": dataclasses.asdict(self.bus.metrics()),
            "bridge": dict(self.counts),
            "setpoint_to_wire_ms": {"p50": pct(0.5), "p99": pct(0.99), "n": len(samples)},
            "owners": {str(mid): owner for mid, owner in sorted(self.owners.items())},
        }


class Bridge:
    """Serve local buses over Zenoh as ``servobus/<node>/<bus>/<motor>/...``.

    Use ``async with Bridge(node, {"can0": (bus, motors)}, config=...) as bridge:`` inside the blocks
    of the Buses it serves (the Buses' own safe stop still runs when they are left). The session
    configuration comes from :func:`servobus.remote.security.bridge_config` (loopback only unless
    authenticated).

    Args:
        node: this bridge's name, the second key segment (a host name, ``arm``).
        buses: ``{bus name: (Bus, motors)}``; the motors are those served (ids unique per bus).
        config: the ``zenoh.Config`` (default: ``bridge_config(node)``, loopback, no auth).
        hz: the tick rate of each bus's set-point loop.
        state_hz: the most states published per motor per second.
        stop_after_s: how long a motor's set-point may be stale before the motor is stopped.
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
        allow_takeover: bool = False,
    ) -> None:
        for name, value in (("hz", hz), ("state_hz", state_hz)):
            if not value > 0:
                raise ValueError(f"{name}={value!r} must be > 0")
        if not stop_after_s >= 0:
            raise ValueError(f"stop_after_s={stop_after_s!r} must be >= 0")
        self.keys = Keys(node)
        self.node = node
        self.hz = float(hz)
        self.state_hz = float(state_hz)
        self.stop_after_s = float(stop_after_s)
        self.allow_takeover = allow_takeover
        self.served = {name: _Served(name, bus, motors) for name, (bus, motors) in buses.items()}
        if not self.served:
            raise ValueError("a bridge needs at least one bus")
        self._config = config
        self._session: Any = None
        self._declared: list[Any] = []
        self._clients: set[str] = set()
        self._group: anyio.abc.TaskGroup | None = None
        self._events, self._events_in = anyio.create_memory_object_stream[tuple[Any, tuple[Any, ...]]](
            _PENDING
        )
        self.dropped_events = 0  # Zenoh callbacks dropped because _PENDING were waiting
        self._lane: runtime.Runtime | None = None
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
            session.liveliness().declare_subscriber(
                keys.clients,
                self._handed(self._on_client, lambda s: (str(s.key_expr), sample_kind(s))),
                history=True,
            )
        )
        self._declared.append(session.liveliness().declare_token(keys.alive))
        as_bytes = lambda s: (str(s.key_expr), s.payload.to_bytes())  # noqa: E731
        for served in self.served.values():
            name = served.name
            self._declared += [
                session.declare_subscriber(
                    keys.bus(name, "setpoints"), self._handed(self._on_setpoints, as_bytes, served)
                ),
                session.declare_subscriber(
                    keys.motor(name, "*", "setpoint"), self._handed(self._on_setpoints, as_bytes, served)
                ),
                session.declare_queryable(
                    keys.motor(name, "*", "request"), self._handed(self._on_query, None, served)
                ),
                session.declare_queryable(
                    keys.motor(name, "*", "read"), self._handed(self._on_query, None, served)
                ),
                session.declare_queryable(keys.bus(name, "info"), self._handed(self._on_info, None, served)),
                session.declare_queryable(
                    keys.bus(name, "metrics"), self._handed(self._on_metrics, None, served)
                ),
            ]
            for mid in served.motors:
                served.publishers[mid] = session.declare_publisher(keys.motor(name, mid, "state"))
                self._declared.append(served.publishers[mid])
            served.bus.subscribe(served.changed)
            served.bus.subscribe_status(functools.partial(self._on_status, served))

    def _handed(self, handler: Any, extract: Any, *bound: Any) -> Any:
        """A Zenoh callback that hands ``extract(item)`` (or the item) to ``handler``, which runs
        in the bridge's intake task (so it may start tasks), in the order Zenoh called."""
        lane = self._lane
        assert lane is not None
        put = self._put_event

        def callback(item: Any) -> None:
            try:
                lane.call_soon_threadsafe(put, handler, (*bound, extract(item) if extract else item))
            except RuntimeError:  # the loop is closed: we are shutting down
                logger.debug("a zenoh callback after the loop closed was dropped")

        return callback

    def _put_event(self, handler: Any, args: tuple[Any, ...]) -> None:
        try:
            self._events.send_nowait((handler, args))
        except (anyio.WouldBlock, anyio.BrokenResourceError, anyio.ClosedResourceError):
            self.dropped_events += 1
            query = args[-1]
            if hasattr(query, "drop"):  # a dropped query is answered "no reply" at once
                query.drop()

    async def _take_events(self) -> None:
        async with self._events_in:
            async for handler, args in self._events_in:
                try:
                    handler(*args)
                except Exception:  # one bad event must not end the bridge's intake
                    logger.exception("%s: handling a message failed", self.node)

    # ---- clients ----

    def _on_client(self, item: tuple[str, str]) -> None:
        key, kind = item
        client_id = key.rsplit("/", 1)[-1]
        if kind == "PUT":
            self._clients.add(client_id)
            return
        self._clients.discard(client_id)
        for served in self.served.values():
            self._stop(
                served, [mid for mid, owner in served.owners.items() if owner == client_id], "client left"
            )

    def _stop(self, served: _Served, motor_ids: Iterable[int], why: str) -> None:
        """Drop the motors' set-points and ownership, and send them the Bus's safe command."""
        motors = []
        for mid in motor_ids:
            served.held.pop(mid, None)
            served.stale_since.pop(mid, None)
            served.owners.pop(mid, None)
            motors.append(served.motors[mid])
        if not motors:
            return
        served.counts["stops"] += len(motors)
        now = time.time_ns()
        self.stop_log.extend((now, served.name, m.motor_id, why) for m in motors)
        logger.warning(
            "%s/%s: stopping motors %s (%s)", self.node, served.name, [m.motor_id for m in motors], why
        )
        if served.bus.safe is not None and self._group is not None:
            self._group.start_soon(self._send_stop, served, motors)

    async def _send_stop(self, served: _Served, motors: list[Motor]) -> None:
        kind = served.bus.safe or "stop"
        with anyio.CancelScope(shield=True), anyio.move_on_after(served.bus.safe_timeout_s):
            pending = motors
            while pending:
                results = await served.bus.cycle([(m, m.codec.safe_command(kind)) for m in pending])
                pending = [m for m, r in zip(pending, results, strict=True) if isinstance(r, BaseException)]
                if pending:
                    await anyio.sleep(0.005)

    # ---- set-points ----

    def _on_setpoints(self, served: _Served, item: tuple[str, bytes]) -> None:
        key, payload = item
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
        if message.client_id not in self._clients:
            served.counts["refused"] += len(message.items)
            return
        now_ns = time.time_ns()
        left_ns = min(message.deadline_unix_ns - now_ns, message.deadline_unix_ns - message.sent_unix_ns)
        if left_ns <= 0:
            served.counts["stale"] += len(message.items)
            return
        assert self._lane is not None
        expires = self._lane.time() + left_ns / 1e9
        for mid, command in message.items:
            if self._holder(served, mid, message.client_id) is not None:
                served.counts["refused"] += 1
                continue
            try:  # what the motor's codec refuses (a command its revision lacks) never reaches a tick
                served.motors[mid].codec.encode(command)
            except ValueError as exc:
                served.counts["malformed"] += 1
                logger.debug("%s: set-point for motor %s refused by its codec: %s", key, mid, exc)
                continue
            held = served.held.get(mid)
            if held is not None and held.client_id == message.client_id and _older(message.seq, held.seq):
                served.counts["reordered"] += 1
                continue
            served.counts["setpoints"] += 1
            served.owners[mid] = message.client_id
            served.stale_since.pop(mid, None)
            served.held[mid] = _Held(message.client_id, message.seq, command, message.sent_unix_ns, expires)

    async def _tick(self, served: _Served) -> None:
        assert self._lane is not None
        clock = self._lane.time
        async for _ in ticks(self.hz, spin_s=0.0):
            now = clock()
            items = []
            fresh: list[_Held] = []
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
                served.held.clear()

    # ---- requests ----

    def _on_query(self, served: _Served, query: Any) -> None:
        assert self._group is not None
        self._group.start_soon(self._answer, served, query)

    async def _answer(self, served: _Served, query: Any) -> None:
        schema = None
        try:
            key = str(query.key_expr)
            try:
                _, mid, leaf = self.keys.parse_motor(key)
            except ValueError as exc:  # a client's key (servobus/N/B/x/request): malformed, not a bug
                raise wire.WireError(str(exc)) from None
            motor = served.motors.get(mid)
            if motor is None:
                raise wire.WireError(f"no motor {mid} on bus {served.name}")
            schema = served.schemas[mid]
            payload = query.payload
            request = wire.decode_request(schema, payload.to_bytes() if payload is not None else b"")
            command = request.command
            if leaf == "read":
                served.counts["reads"] += 1
                if not type(command).READ:
                    raise PermissionError(f"{type(command).__name__} is not a read: send it as a request")
            else:
                served.counts["requests"] += 1
                self._may_command(served, mid, request.client_id, command)
            reply = await served.bus.request(motor, command, timeout_s=request.timeout_s)
            result = wire.Result(reply=reply)
            if leaf == "request" and command in served.safe_commands[mid]:
                # The client made the motor safe itself (stop, off, brake): leaving must not undo it.
                served.held.pop(mid, None)
                if served.owners.get(mid) == request.client_id:
                    del served.owners[mid]
        except wire.WireError as exc:
            served.counts["malformed"] += 1
            result = wire.Result(error=ValueError(f"malformed request: {exc}"))
        except PermissionError as exc:
            served.counts["refused"] += 1
            result = wire.Result(error=exc)
        except ServobusError as exc:
            result = wire.Result(error=exc)
        except Exception as exc:  # a bug must not leave the client waiting; it is logged here
            logger.exception("%s: request failed", query.key_expr)
            result = wire.Result(error=exc)
        try:
            query.reply(
                query.key_expr, wire.encode_result(schema or next(iter(served.schemas.values())), result)
            )
        except Exception:  # the client went away meanwhile
            logger.debug("reply to %s failed", query.key_expr, exc_info=True)
        finally:
            query.drop()

    def _may_command(self, served: _Served, mid: int, client_id: str, command: Any) -> None:
        if client_id not in self._clients:
            raise PermissionError(f"client {client_id} has no liveliness token: it may only read")
        holder = self._holder(served, mid, client_id)
        if holder is not None:
            raise PermissionError(f"motor {mid} on {served.name} is held by another client ({holder})")
        if not type(command).READ:
            served.owners[mid] = client_id

    def _holder(self, served: _Served, mid: int, client_id: str) -> str | None:
        """The live client other than ``client_id`` that holds motor ``mid``; None: free to command."""
        owner = served.owners.get(mid)
        if owner is None or owner == client_id or owner not in self._clients or self.allow_takeover:
            return None
        return owner

    def _on_info(self, served: _Served, query: Any) -> None:
        self._reply_json(query, self.keys.bus(served.name, "info"), served.info(self.node, self))

    def _on_metrics(self, served: _Served, query: Any) -> None:
        self._reply_json(query, self.keys.bus(served.name, "metrics"), served.metrics())

    def _reply_json(self, query: Any, key: str, body: dict[str, Any]) -> None:
        try:  # on the bus's own key: answers to a wildcard query (servobus/N/*/info) stay apart
            query.reply(key, json.dumps(body).encode())
        finally:
            query.drop()

    # ---- states ----

    def _on_status(self, served: _Served, status: MotorStatus) -> None:
        mid = status.motor.motor_id
        if mid in served.publishers:
            self._publish(served, mid)

    def _publish(self, served: _Served, mid: int) -> None:
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

    async def _publish_states(self, served: _Served) -> None:
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


def _safe_commands(motor: Motor) -> frozenset[Any]:
    """The commands that make ``motor`` safe (each kind its family has)."""
    found = set()
    for kind in ("stop", "shutdown", "brake"):
        try:
            found.add(motor.codec.safe_command(kind))
        except ValueError:  # a kind this family or revision has no command for
            continue
    return frozenset(found)


def _older(seq: int, than: int) -> bool:
    """Whether sequence number ``seq`` came before ``than`` (32-bit, wrapping)."""
    return seq != than and ((than - seq) & 0xFFFFFFFF) < 0x80000000

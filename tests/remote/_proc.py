"""The processes of the multi-process remote tests (tests/remote/test_procs.py), run as a script:

    python tests/remote/_proc.py bridge --port P [--motors 32] [--users FILE --commander cmd --reader ro]
    python tests/remote/_proc.py client --port P [--backend trio]

Each reads one JSON command a line on stdin and answers each with one line ``@@ {json}`` on stdout
(anything else on stdout is not an answer). The bridge first says ``@@ {"ready": ...}`` once it
serves.

The bridge serves a Bus on simulated MyActuator motors (one SimTransport) whose every frame sent is
counted by arbitration id and first data byte, with the wall-clock time of its first and last
sending: that is "what reached the motors". Its commands: ``report`` (those counts since the last
``reset``, the bridge's counters and stop log, each simulated motor's control, and the instruments:
the set-point -> wire latency since the last ``reset``, the event loop's worst lag, the process's
resident memory; the frames sent after their motor's first stop since ``reset``, the Bus's pending
requests), ``reset``, ``quit``.

The client holds at most one connection (``servobus.remote.connect``) and a raw Zenoh session for
sending what a client never would. Its commands: ``connect``, ``hold`` (a task that sends a batch of
set-points per tick until ``release``), ``release``, ``cycle``, ``request``, ``counts``, ``close``,
``raw_put``, ``raw_get``, ``pipeline`` (requests kept in flight in the background), ``pipelined``
(their counts; ``stop`` ends them), ``flood`` (queries sent in the background at a rate, their
answers not awaited, until ``flood_stop``), ``flood_stop``, ``quit``; each answer says ``ok`` or the
error's type and message, and how long the call took.

A hostile client (tests/remote/test_hostile_peers.py) opens a raw Zenoh session of its own, in
``client`` or ``peer`` mode: ``spy`` (watch everything under ``servobus/**``), ``spied`` (what it saw,
with the secret and token ids found there), ``impersonate`` (act with every id it found: copies of
the tokens, set-points and requests in those names, at a speed nobody else sends), ``impersonated``.
The bridge counts its speed frames by value (``speed_frames`` in ``report``) to tell them apart.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import functools
import json
import os
import random
import re
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import anyio

import servobus
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.sim.canbus import CanBusModel
from servobus.transports.sim import SimTransport

_STOP = 0x81  # MyActuator's stop command (its first byte)


def emit(body: dict[str, Any]) -> None:
    sys.stdout.write("@@ " + json.dumps(body) + "\n")
    sys.stdout.flush()


async def commands() -> Any:
    """The JSON commands on stdin, until it closes."""
    while True:
        line = await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True)
        if not line:
            return
        if line.strip():
            yield json.loads(line)


# ---- the bridge ----


class Frames:
    """Every frame sent to the motors: ``(arbitration id, byte 0) -> [count, first ns, last ns]``;
    of the speed frames (0xA2), also by speed: ``(arbitration id, 0.01 dps) -> [count, first, last]``;
    and of them all, those sent after the first stop (0x81) of their arbitration id (``after_stop``)."""

    def __init__(self) -> None:
        self.seen: dict[tuple[int, int], list[int]] = {}
        self.speeds: dict[tuple[int, int], list[int]] = {}
        self.after_stop: dict[tuple[int, int], int] = {}

    def add(self, arbitration_id: int, data: bytes) -> None:
        now = time.time_ns()
        key = (arbitration_id, data[0] if data else -1)
        if (arbitration_id, _STOP) in self.seen:  # (counted in the order the frames were sent)
            self.after_stop[key] = self.after_stop.get(key, 0) + 1
        entry = self.seen.get(key)
        if entry is None:
            self.seen[key] = [1, now, now]
        else:
            entry[0] += 1
            entry[2] = now
        if key[1] == 0xA2 and len(data) >= 8:  # (a speed: DATA[4:8], 0.01 dps)
            value = (arbitration_id, int.from_bytes(data[4:8], "little", signed=True))
            entry = self.speeds.get(value)
            if entry is None:
                self.speeds[value] = [1, now, now]
            else:
                entry[0] += 1
                entry[2] = now

    def listed(self) -> list[list[int]]:
        return [[aid, b0, *entry] for (aid, b0), entry in sorted(self.seen.items())]

    def speeds_listed(self) -> list[list[Any]]:
        """``[arbitration id, speed dps, count, first ns, last ns]`` of every speed sent."""
        return [[aid, raw / 100, *entry] for (aid, raw), entry in sorted(self.speeds.items())]

    def clear(self) -> None:
        self.seen.clear()
        self.speeds.clear()
        self.after_stop.clear()


def logged_transport(
    frames: Frames, devices: list[MyActuatorMotor], bitrate: float | None = None
) -> SimTransport:
    class Logged(SimTransport):
        def _put(self, frame: Any, handle: Any, now: float) -> None:
            frames.add(frame.arbitration_id, bytes(frame.data))
            super()._put(frame, handle, now)

    return Logged(devices=devices, bus=None if bitrate is None else CanBusModel(bitrate=bitrate))


def _control(device: MyActuatorMotor) -> dict[str, Any]:
    control = device.control
    out: dict[str, Any] = {"kind": type(control).__name__}
    for name in ("speed_dps", "position_deg"):
        value = getattr(control, name, None)
        if isinstance(value, float | int):
            out[name] = value
    return out


class LoopLag:
    """The event loop's worst lag since the last reset: how late a 1 ms sleep woke, at most. A
    bridge whose loop is busy decoding or sorting is late here by as long as it was busy."""

    def __init__(self) -> None:
        self.worst_s = 0.0

    async def run(self) -> None:
        while True:
            started = time.perf_counter()
            await anyio.sleep(0.001)
            self.worst_s = max(self.worst_s, time.perf_counter() - started - 0.001)


def rss_mb() -> float:
    """This process's resident memory (MB), from /proc."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def percentiles_ms(samples_ns: Any) -> dict[str, Any]:
    ordered = sorted(samples_ns)
    if not ordered:
        return {"n": 0, "p50": None, "p99": None, "max": None}

    def at(q: float) -> float:
        return ordered[min(len(ordered) - 1, int(q * len(ordered)))] / 1e6

    return {"n": len(ordered), "p50": at(0.5), "p99": at(0.99), "max": ordered[-1] / 1e6}


async def bridge_main(args: argparse.Namespace) -> None:
    from servobus.remote import Bridge, wire
    from servobus.remote.security import Access, bridge_config

    endpoint = f"tcp/127.0.0.1:{args.port}"
    access = None
    if args.users:
        access = Access(
            users_file=args.users, commanders=frozenset(args.commander), readers=frozenset(args.reader)
        )
    devices = [MyActuatorMotor(i) for i in range(1, args.motors + 1)]
    frames = Frames()
    async with servobus.Bus(logged_transport(frames, devices, args.bitrate)) as bus:
        motors = [bus.motor(ma.FAMILY, d.motor_id) for d in devices]
        config = bridge_config(args.node, [endpoint], access)
        async with Bridge(
            args.node, {args.bus: (bus, motors)}, config=config, hz=args.hz, stop_after_s=args.stop_after
        ) as bridge:
            lag = LoopLag()
            group = anyio.create_task_group()
            await group.__aenter__()
            group.start_soon(lag.run)
            emit({"ready": True, "pid": os.getpid(), "endpoint": endpoint})
            async for command in commands():
                op = command["op"]
                if op == "report":
                    served = bridge.served[args.bus]
                    emit(
                        {
                            "ok": True,
                            "now_ns": time.time_ns(),
                            "frames": frames.listed(),
                            "bridge": dict(served.counts),
                            "owners": {str(k): wire.shown_id(v) for k, v in served.owners.items()},
                            "clients": len(bridge.clients.live),
                            "dropped_events": bridge.dropped_events,
                            "stop_log": [list(entry) for entry in bridge.stop_log],
                            "controls": {str(d.motor_id): _control(d) for d in devices},
                            "to_wire_ms": percentiles_ms(served.to_wire_ns),
                            "loop_lag_ms": lag.worst_s * 1e3,
                            "rss_mb": rss_mb(),
                            "speed_frames": frames.speeds_listed(),
                            "after_stop": [[*k, n] for k, n in sorted(frames.after_stop.items())],
                            "pending": served.bus.scheduler.pending,
                        }
                    )
                elif op == "reset":
                    frames.clear()
                    bridge.stop_log.clear()
                    for served in bridge.served.values():
                        served.to_wire_ns.clear()
                    lag.worst_s = 0.0
                    emit({"ok": True})
                elif op == "quit":
                    emit({"ok": True})
                    break
                else:
                    emit({"ok": False, "error": "ValueError", "message": f"unknown op {op!r}"})
            group.cancel_scope.cancel()
            await group.__aexit__(None, None, None)


# ---- the client ----


def _command(name: str, fields: dict[str, Any]) -> Any:
    return getattr(ma, name)(**fields)


def _reply(value: Any) -> Any:
    if value is None:
        return None
    out: dict[str, Any] = {"type": type(value).__name__}
    for name in ("speed_dps", "angle_deg", "temperature_c"):
        if hasattr(value, name):
            out[name] = getattr(value, name)
    return out


class Client:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.endpoint = f"tcp/127.0.0.1:{args.port}"
        self.stack: contextlib.AsyncExitStack | None = None
        self.bus: Any = None
        self.raw: Any = None
        self.hold_scope: anyio.CancelScope | None = None
        self.held = {"cycles": 0, "error": None, "message": None}
        self.flooding: list[Flood] = []

    async def connect(self, c: dict[str, Any]) -> dict[str, Any]:
        from servobus.remote import connect

        stack = contextlib.AsyncExitStack()
        self.bus = await stack.enter_async_context(
            connect(
                f"{self.args.node}/{self.args.bus}",
                endpoints=[c.get("endpoint", self.endpoint)],
                user=c.get("user"),
                password=c.get("password"),
                read_only=c.get("read_only", False),
                valid_for_s=c.get("valid_for_s", 0.1),
                timeout_s=c.get("timeout_s", 2.0),
            )
        )
        self.stack = stack
        return {
            "shown_id": self.bus.shown_id,
            "motors": sorted(self.bus.motors),
            # (what a hostile peer must never learn: tests/remote/test_hostile_peers.py)
            "client_id": self.bus.client_id,
            "token_id": self.bus.token_id,
        }

    async def close(self, _: dict[str, Any]) -> dict[str, Any]:
        """Leave the connection (a hold running is released first); its counts as they were."""
        held = self.release_hold()
        counts = None if self.bus is None else dict(self.bus.counts)
        stack, self.stack, self.bus = self.stack, None, None
        if stack is not None:
            await stack.aclose()
        return {"counts": counts, "held": held}

    async def hold(self, c: dict[str, Any], group: Any) -> dict[str, Any]:
        """Send ``command`` to ``motors`` at ``hz`` until released (or an error, which is kept)."""
        self.release_hold()
        bus = self.bus
        items = [(bus.motor(mid), _command(c["command"], c.get("fields", {}))) for mid in c["motors"]]
        period = 1.0 / c.get("hz", 200.0)
        valid = c.get("valid_for_s")
        self.held = {"cycles": 0, "error": None, "message": None}
        held = self.held
        scope = anyio.CancelScope()
        self.hold_scope = scope

        async def run() -> None:
            with scope:
                try:
                    while True:
                        await bus.cycle(items, valid_for_s=valid)
                        held["cycles"] += 1
                        await anyio.sleep(period)
                except Exception as exc:
                    held["error"], held["message"] = type(exc).__name__, str(exc)

        group.start_soon(run)
        return {}

    def release_hold(self) -> dict[str, Any]:
        if self.hold_scope is not None:
            self.hold_scope.cancel()
            self.hold_scope = None
        return dict(self.held)

    async def request(self, c: dict[str, Any]) -> dict[str, Any]:
        motor = self.bus.motor(c["motor"])
        reply = await motor.request(_command(c["command"], c.get("fields", {})), timeout_s=c.get("timeout_s"))
        return {"reply": _reply(reply)}

    async def cycle(self, c: dict[str, Any]) -> dict[str, Any]:
        bus = self.bus
        items = [(bus.motor(mid), _command(c["command"], c.get("fields", {}))) for mid in c["motors"]]
        await bus.cycle(items, valid_for_s=c.get("valid_for_s"))
        return {}

    def counts(self, _: dict[str, Any]) -> dict[str, Any]:
        bus = self.bus
        return {
            "counts": dict(bus.counts),
            "lost": None if bus.lost is None else str(bus.lost),
            "held": dict(self.held),
            "states": {str(mid): _reply(m.state) for mid, m in bus.motors.items()},
        }

    async def raw_session(self) -> Any:
        if self.raw is None:
            import zenoh

            from servobus.remote.security import client_config

            config = client_config([self.endpoint], connect_timeout_s=2.0)
            self.raw = await anyio.to_thread.run_sync(zenoh.open, config)
        return self.raw

    async def raw_put(self, c: dict[str, Any]) -> dict[str, Any]:
        session = await self.raw_session()
        for key, payload in c["items"]:
            session.put(key, bytes.fromhex(payload))
        return {"sent": len(c["items"])}

    async def raw_get(self, c: dict[str, Any]) -> dict[str, Any]:
        """Each query's answers (hex) and errors (text); a payload None sends none."""
        session = await self.raw_session()
        out = []
        for key, payload in c["items"]:

            def get(key: str = key, payload: str | None = payload) -> tuple[list[str], list[str]]:
                ok, err = [], []
                replies = session.get(
                    key,
                    payload=None if payload is None else bytes.fromhex(payload),
                    timeout=c.get("timeout_s", 2.0),
                )
                for reply in replies:
                    if reply.ok is not None:
                        ok.append(reply.ok.payload.to_bytes().hex())
                    else:
                        err.append(reply.err.payload.to_bytes().decode(errors="replace"))
                return ok, err

            ok, err = await anyio.to_thread.run_sync(get)
            out.append({"ok": ok, "err": err})
        return {"answers": out}


# ---- a hostile client (tests/remote/test_hostile_peers.py) ----

_ID_TEXT = re.compile(r"\b[0-9a-f]{32}\b")  # a secret or token id, as text (an error message)


class Hostile:
    """The raw Zenoh session of a program that wants to act in another client's name: it watches
    all it is routed, then uses every secret and token id it found (and every one an error names)."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.endpoint = f"tcp/127.0.0.1:{args.port}"
        self.session: Any = None
        self.kept: list[Any] = []  # declarations (subscribers, tokens) kept until quit
        self.samples: list[tuple[str, str, str]] = []  # (what, key, payload hex)
        self.tokens: list[tuple[str, str]] = []  # (key, kind)
        self.queries: list[tuple[str, str]] = []  # (key, payload hex) routed to our queryable
        self.newest_seq: dict[str, int] = {}  # secret id -> newest sequence number seen
        self.scope: anyio.CancelScope | None = None
        self.group: Any = None  # the client's task group, for the impersonation's task
        self.sent = {"puts": 0, "requests": 0, "answers": 0}
        self.answers: list[str] = []  # each request answer: the error's type, or "ok"

    def calls(self) -> dict[str, Callable[[dict[str, Any]], Any]]:
        return {
            "spy": self.spy,
            "spied": self.spied,
            "impersonate": self.impersonate,
            "impersonated": self.impersonated,
        }

    async def spy(self, c: dict[str, Any]) -> dict[str, Any]:
        """Open a session in ``mode`` (``client`` or ``peer``) and watch ``servobus/**`` every way:
        samples, liveliness with history, and a queryable (it answers nothing)."""
        import zenoh

        from servobus.remote.security import client_config

        config = client_config([self.endpoint], connect_timeout_s=2.0)
        config.insert_json5("mode", json.dumps(c["mode"]))
        self.session = session = await anyio.to_thread.run_sync(zenoh.open, config)
        node = self.args.node

        def on_sample(what: str) -> Callable[[Any], None]:
            return lambda s: self._sample(what, str(s.key_expr), s.payload.to_bytes())

        def on_query(query: Any) -> None:
            payload = b"" if query.payload is None else query.payload.to_bytes()
            self.queries.append((str(query.key_expr), payload.hex()))
            self._found(payload)

        def on_token(sample: Any) -> None:
            self.tokens.append((str(sample.key_expr), str(sample.kind)))

        self.kept += [
            session.declare_subscriber("servobus/**", on_sample("all")),
            # (what any client may see: it shows this session is connected and served)
            session.declare_subscriber(f"servobus/{node}/*/*/state", on_sample("state")),
            session.liveliness().declare_subscriber("servobus/**", on_token, history=True),
            session.liveliness().declare_subscriber(f"servobus/{node}/_alive", on_token, history=True),
            session.declare_queryable("servobus/**", on_query),
        ]
        return {"zid": str(session.info.zid())}

    def _sample(self, what: str, key: str, payload: bytes) -> None:
        # (a state is public: it reaches a session that subscribes to states by every subscriber)
        self.samples.append(("state" if key.endswith("/state") else what, key, payload.hex()))
        self._found(payload)

    def _found(self, payload: bytes) -> None:
        """The secret id (and sequence number) in a set-point or request message, if it is one."""
        from servobus.remote import wire

        head = 2 + wire.CLIENT_ID_BYTES  # version, kind, the secret id; then a set-point's seq
        if (
            len(payload) >= head
            and payload[0] == wire.VERSION
            and payload[1] in (wire.SETPOINTS, wire.REQUEST)
        ):
            secret = payload[2:head].hex()
            seq = int.from_bytes(payload[head : head + 4], "little") if payload[1] == wire.SETPOINTS else 0
            self.newest_seq[secret] = max(seq, self.newest_seq.get(secret, 0))

    async def spied(self, _: dict[str, Any]) -> dict[str, Any]:
        """All it saw, a liveliness query and a query on ``servobus/**`` besides."""
        session = self.session

        def ask() -> tuple[list[str], list[list[str]]]:
            alive = [str(r.ok.key_expr) for r in session.liveliness().get("servobus/**", timeout=1.0) if r.ok]
            replies = [
                [str(r.ok.key_expr), r.ok.payload.to_bytes().hex()]
                for r in session.get("servobus/**", timeout=1.0)
                if r.ok is not None
            ]
            return alive, replies

        alive, replies = await anyio.to_thread.run_sync(ask)
        for _key, payload in replies:
            self._found(bytes.fromhex(payload))
        tokens = sorted({key for key, _ in self.tokens} | set(alive))
        return {
            "samples": [s for s in self.samples if s[0] != "state"],
            "states": sum(1 for s in self.samples if s[0] == "state"),
            "tokens": tokens,
            "liveliness_get": alive,
            "replies": replies,
            "queries": [q for q in self.queries if q[1]],  # (ours, without payload, left out)
            "secrets": sorted(self.newest_seq),
            "token_ids": sorted({key.rsplit("/", 1)[-1] for key in tokens if "/_clients/" in key}),
        }

    async def impersonate(self, c: dict[str, Any]) -> dict[str, Any]:
        """Act in every name found: a token of its own (so it may ask), a request for each motor in
        it (the refusal names the holder), copies of every token found and named, then set-points
        and requests of ``command`` to ``motors`` in every secret's name found, and of ``own`` in
        its own name, at ``hz``, until quit."""
        from servobus.remote import wire

        session = self.session
        schema = wire.Schema.of(ma.FAMILY.name)
        command = _command(c["command"], c.get("fields", {}))
        own = _command(c["command"], c.get("own_fields", c.get("fields", {})))
        mine = os.urandom(wire.CLIENT_ID_BYTES).hex()
        node, bus = self.args.node, self.args.bus
        self.kept.append(
            session.liveliness().declare_token(f"servobus/{node}/_clients/{wire.public_id(mine)}")
        )
        await anyio.sleep(0.2)  # (its token reaches the bridge before its requests)
        named: set[str] = set()
        for mid in c["motors"]:
            for text in await self._request(f"servobus/{node}/{bus}/{mid}/request", schema, mine, own):
                named.update(_ID_TEXT.findall(text))
        token_ids = set(c.get("token_ids", [])) | {
            key.rsplit("/", 1)[-1] for key, _ in self.tokens if "/_clients/" in key
        }
        copies = sorted((token_ids | named) - {wire.public_id(mine)})
        for token_id in copies:
            self.kept.append(session.liveliness().declare_token(f"servobus/{node}/_clients/{token_id}"))
        secrets = sorted((set(self.newest_seq) | named) - {mine})  # (its own probe too was seen)
        commands = {secret: command for secret in secrets} | {mine: own}
        period = 1.0 / c.get("hz", 200.0)
        scope = self.scope = anyio.CancelScope()

        async def run() -> None:
            seq = {secret: self.newest_seq.get(secret, 0) + 100_000 for secret in commands}
            with scope:
                while True:
                    now = time.time_ns()
                    for secret, sent in commands.items():
                        seq[secret] = (seq[secret] + 1) & 0xFFFFFFFF
                        items = tuple((mid, sent) for mid in c["motors"])
                        message = wire.Setpoints(secret, seq[secret], now, now + 1_000_000_000, items)
                        session.put(
                            f"servobus/{node}/{bus}/setpoints",
                            wire.encode_setpoints(lambda _: schema, message),
                        )
                        for mid in c["motors"]:
                            one = wire.Setpoints(
                                secret, seq[secret], now, now + 1_000_000_000, ((mid, sent),)
                            )
                            session.put(
                                f"servobus/{node}/{bus}/{mid}/setpoint",
                                wire.encode_setpoints(lambda _: schema, one),
                            )
                        self.sent["puts"] += 1 + len(c["motors"])
                    for secret, sent in commands.items():
                        for mid in c["motors"]:
                            key = f"servobus/{node}/{bus}/{mid}/request"
                            self._ask(
                                key, wire.encode_request(schema, wire.Request(secret, sent, None)), schema
                            )
                    await anyio.sleep(period)

        self.group.start_soon(run)
        return {"mine": mine, "named": sorted(named), "token_copies": copies, "secrets": secrets}

    async def _request(self, key: str, schema: Any, secret: str, command: Any) -> list[str]:
        """Each answer to one request in ``secret``'s name: the error's type and message, or "ok"."""
        from servobus.remote import wire

        payload = wire.encode_request(schema, wire.Request(secret, command, None))

        def get() -> list[str]:
            out = []
            for reply in self.session.get(key, payload=payload, timeout=1.0):
                if reply.ok is None:
                    out.append("err " + reply.err.payload.to_bytes().decode(errors="replace"))
                    continue
                result = wire.decode_result(schema, reply.ok.payload.to_bytes())
                error = result.error
                out.append("ok" if error is None else f"{type(error).__name__}: {error}")
            return out

        found = await anyio.to_thread.run_sync(get)
        self.answers += found
        return found

    def _ask(self, key: str, payload: bytes, schema: Any) -> None:
        """A request sent without waiting (Zenoh's thread counts its answer)."""
        import zenoh

        from servobus.remote import wire

        def on_reply(reply: Any) -> None:
            self.sent["answers"] += 1
            if reply.ok is not None:
                error = wire.decode_result(schema, reply.ok.payload.to_bytes()).error
                self.answers.append("ok" if error is None else type(error).__name__)

        self.session.get(key, zenoh.handlers.Callback(on_reply, lambda: None), payload=payload, timeout=1.0)
        self.sent["requests"] += 1

    async def impersonated(self, _: dict[str, Any]) -> dict[str, Any]:
        kinds: dict[str, int] = {}
        for answer in self.answers:
            kind = answer.split(":", 1)[0]
            kinds[kind] = kinds.get(kind, 0) + 1
        return {"sent": dict(self.sent), "answers": kinds, "running": self.scope is not None}

    def close(self) -> None:
        if self.scope is not None:
            self.scope.cancel()
        if self.session is not None:
            for item in reversed(self.kept):
                with contextlib.suppress(Exception):
                    item.undeclare()
            self.session.close()
            self.session = None


# ---- the client: pipelined requests (tests/remote/test_hostile_pipeline.py) ----


class Pipeline:
    """Requests kept in flight in the background: ``depth`` tasks per motor, each sending its next
    request as soon as its last one ended (faster than a motor answers: they queue on the bridge's
    Bus). What became of them is counted: replies, and errors by type (the first message of each)."""

    def __init__(self) -> None:
        self.scope: anyio.CancelScope | None = None
        self.counts: dict[str, Any] = {"sent": 0, "ok": 0, "errors": {}, "messages": {}}

    def start(self, bus: Any, c: dict[str, Any], group: Any) -> dict[str, Any]:
        self.stop()
        command = _command(c["command"], c.get("fields", {}))
        motors = [bus.motor(mid) for mid in c["motors"]]
        pause_s = c.get("pause_s", 0.001)  # after an error: a refused client does not spin
        counts = self.counts = {"sent": 0, "ok": 0, "errors": {}, "messages": {}}
        scope = self.scope = anyio.CancelScope()

        async def run(motor: Any) -> None:
            while True:
                counts["sent"] += 1
                try:
                    await motor.request(command, timeout_s=c.get("timeout_s"))
                except Exception as exc:
                    name = type(exc).__name__
                    counts["errors"][name] = counts["errors"].get(name, 0) + 1
                    counts["messages"].setdefault(name, str(exc))
                    await anyio.sleep(pause_s)
                else:
                    counts["ok"] += 1

        async def run_all() -> None:
            with scope:
                async with anyio.create_task_group() as tasks:
                    for motor in motors:
                        for _ in range(c.get("depth", 4)):
                            tasks.start_soon(run, motor)

        group.start_soon(run_all)
        return {}

    def stop(self) -> dict[str, Any]:
        if self.scope is not None:
            self.scope.cancel()
            self.scope = None
        return dict(self.counts)


# ---- the client: a hostile peer's flood of queries ----


class Flood:
    """Queries sent from a thread at ``hz`` for ``duration_s`` (or until stopped), each answered
    by Zenoh's callback, never awaited: what a peer that wants the bridge busy would send."""

    def __init__(self, session: Any, c: dict[str, Any]) -> None:
        self.session = session
        self.keys: list[str] = c["keys"]
        self.payload = None if c.get("payload") is None else bytes.fromhex(c["payload"])
        self.fresh_id = c.get("fresh_id", False)  # a random client id in each query
        self.hz = float(c["hz"])
        self.duration_s = float(c.get("duration_s", 60.0))
        self.counts = {"sent": 0, "answers": 0, "errors": 0, "ended": 0}
        self.stopping = False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        import zenoh

        def on_reply(reply: Any) -> None:
            self.counts["answers" if reply.ok is not None else "errors"] += 1

        def on_done() -> None:
            self.counts["ended"] += 1

        started = time.monotonic()
        rng = random.Random(self.hz)
        while not self.stopping and time.monotonic() - started < self.duration_s:
            due = int((time.monotonic() - started) * self.hz) + 1
            while self.counts["sent"] < due and not self.stopping:
                payload = self.payload
                if payload is not None and self.fresh_id:
                    payload = payload[:2] + rng.randbytes(16) + payload[18:]
                key = self.keys[self.counts["sent"] % len(self.keys)]
                try:
                    self.session.get(
                        key, zenoh.handlers.Callback(on_reply, on_done), payload=payload, timeout=2.0
                    )
                except Exception:  # (a session closing under us: the flood ends)
                    return
                self.counts["sent"] += 1
            time.sleep(0.002)

    def stop(self) -> dict[str, Any]:
        self.stopping = True
        self.thread.join(timeout=10)
        return dict(self.counts)


async def flood(client: Client, c: dict[str, Any]) -> dict[str, Any]:
    """One more flood, beside those running."""
    client.flooding.append(Flood(await client.raw_session(), c))
    return {}


def flood_stop(client: Client, _: dict[str, Any]) -> dict[str, Any]:
    """Stop every flood; the counts of each (sent, answers, errors, ended), in order."""
    flooding, client.flooding = client.flooding, []
    return {"counts": [each.stop() for each in flooding]}


# ---- the client: hostile background load (test_hostile_churn.py) ----


class Background:
    """One hostile load run on a thread of its own over the client's raw Zenoh session, until
    stopped: ``churn`` declares and undeclares ``_clients/<random>`` liveliness tokens (each a
    token's coming and going), ``forge`` puts set-points of fresh random client ids (no token).
    ``hz`` 0: as fast as the session takes them."""

    def __init__(self, step: Callable[[], None], hz: float) -> None:
        self._step = step
        self._period_s = 1.0 / hz if hz > 0 else 0.0
        self._stopping = threading.Event()
        self.count = 0
        self.error: str | None = None
        self.started = time.perf_counter()
        self.ended: float | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_at = time.perf_counter()
        try:
            while not self._stopping.is_set():
                self._step()
                self.count += 1
                if self._period_s:
                    next_at += self._period_s
                    delay = next_at - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
        except Exception as exc:  # reported by *_stop
            self.error = f"{type(exc).__name__}: {exc}"
        self.ended = time.perf_counter()

    def stop(self) -> dict[str, Any]:
        self._stopping.set()
        self._thread.join(timeout=10)
        ended = self.ended if self.ended is not None else time.perf_counter()
        elapsed = ended - self.started
        return {"count": self.count, "ran_s": elapsed, "per_s": self.count / elapsed, "error": self.error}


def churn_step(session: Any, prefix: str, alive: int) -> Callable[[], None]:
    """One token declared under ``prefix/_clients/`` (a random public id each), and the oldest
    undeclared once ``alive`` live (1: each goes at once)."""
    tokens: collections.deque[Any] = collections.deque()

    def step() -> None:
        tokens.append(session.liveliness().declare_token(f"{prefix}/_clients/{os.urandom(16).hex()}"))
        while len(tokens) >= alive:
            tokens.popleft().undeclare()

    return step


def forge_step(session: Any, key: str, motors: list[int], command: Any) -> Callable[[], None]:
    """One batch of set-points for ``motors`` on ``key`` under a fresh random client id."""
    from servobus.remote import wire

    schema = wire.Schema.of(ma.FAMILY.name)
    publisher = session.declare_publisher(key)

    def step() -> None:
        now = time.time_ns()
        message = wire.Setpoints(
            os.urandom(wire.CLIENT_ID_BYTES).hex(),
            1,
            now,
            now + 100_000_000,
            tuple((m, command) for m in motors),
        )
        publisher.put(wire.encode_setpoints(lambda _: schema, message))

    return step


class Loads:
    """The client's ops of hostile background load: ``churn``/``forge`` (``hz``; ``forge`` also
    ``motors``, ``command``, ``fields``, and ``key``: the bus's ``setpoints`` by default) start one,
    ``alive``: how many of its tokens live at once), ``churn_stop``/``forge_stop`` end it and say
    how many it did (``count``, ``ran_s``, ``per_s``, ``error``)."""

    def __init__(self, client: Client) -> None:
        self.client = client
        self.running: dict[str, Background] = {}

    def calls(self) -> dict[str, Callable[[dict[str, Any]], Any]]:
        return {"churn": self.churn, "forge": self.forge, "churn_stop": self.stop, "forge_stop": self.stop}

    async def churn(self, c: dict[str, Any]) -> dict[str, Any]:
        session = await self.client.raw_session()
        prefix = f"servobus/{self.client.args.node}"
        return self.start("churn", churn_step(session, prefix, c.get("alive", 1)), c)

    async def forge(self, c: dict[str, Any]) -> dict[str, Any]:
        session = await self.client.raw_session()
        args = self.client.args
        key = c.get("key", f"servobus/{args.node}/{args.bus}/setpoints")
        command = _command(c.get("command", "SpeedControl"), c.get("fields", {"speed_dps": 5.0}))
        return self.start("forge", forge_step(session, key, c["motors"], command), c)

    def start(self, name: str, step: Callable[[], None], c: dict[str, Any]) -> dict[str, Any]:
        if name in self.running:
            raise ValueError(f"{name} runs already")
        self.running[name] = Background(step, c.get("hz", 0.0))
        return {}

    async def stop(self, c: dict[str, Any]) -> dict[str, Any]:
        return await anyio.to_thread.run_sync(self.running.pop(c["op"].removesuffix("_stop")).stop)


async def client_main(args: argparse.Namespace) -> None:
    client = Client(args)
    pipeline = Pipeline()
    calls: dict[str, Callable[[dict[str, Any]], Any]] = {
        "connect": client.connect,
        "close": client.close,
        "request": client.request,
        "cycle": client.cycle,
        "raw_put": client.raw_put,
        "raw_get": client.raw_get,
        "flood": functools.partial(flood, client),
    }
    hostile = Hostile(args)
    calls.update(hostile.calls())
    calls.update(Loads(client).calls())
    emit({"ready": True, "pid": os.getpid()})
    async with anyio.create_task_group() as group:
        hostile.group = group
        async for command in commands():
            op = command["op"]
            started = time.perf_counter()
            try:
                if op == "quit":
                    await client.close(command)
                    emit({"ok": True})
                    break
                if op == "hold":
                    body = await client.hold(command, group)
                elif op == "release":
                    body = client.release_hold()
                elif op == "counts":
                    body = client.counts(command)
                elif op == "pipeline":  # (pipelined: its counts, "stop": true ends it)
                    body = pipeline.start(client.bus, command, group)
                elif op == "pipelined":
                    body = pipeline.stop() if command.get("stop") else dict(pipeline.counts)
                elif op == "flood_stop":
                    body = flood_stop(client, command)
                else:
                    body = await calls[op](command)
                answer = {"ok": True, **body}
            except Exception as exc:
                answer = {
                    "ok": False,
                    "error": type(exc).__name__,
                    "errors": [cls.__name__ for cls in type(exc).__mro__],
                    "message": str(exc),
                    "trace": traceback.format_exc(limit=3),
                }
            answer["elapsed_s"] = time.perf_counter() - started
            emit(answer)
        group.cancel_scope.cancel()
    hostile.close()
    for each in client.flooding:
        each.stop()
    if client.raw is not None:
        client.raw.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("role", choices=["bridge", "client"])
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--node", default="n")
    parser.add_argument("--bus", default="b")
    parser.add_argument("--backend", default="asyncio", choices=["asyncio", "trio"])
    parser.add_argument("--motors", type=int, default=32)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--stop-after", type=float, default=0.05)
    parser.add_argument("--bitrate", type=float)  # the simulated CAN bus's (default: 1 Mbit/s)
    parser.add_argument("--users")
    parser.add_argument("--commander", action="append", default=[])
    parser.add_argument("--reader", action="append", default=[])
    args = parser.parse_args()
    run = bridge_main if args.role == "bridge" else client_main
    anyio.run(run, args, backend=args.backend)


if __name__ == "__main__":
    main()

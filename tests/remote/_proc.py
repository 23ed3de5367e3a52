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
resident memory), ``reset``, ``quit``.

The client holds at most one connection (``servobus.remote.connect``) and a raw Zenoh session for
sending what a client never would. Its commands: ``connect``, ``hold`` (a task that sends a batch of
set-points per tick until ``release``), ``release``, ``cycle``, ``request``, ``counts``, ``close``,
``raw_put``, ``raw_get``, ``flood`` (queries sent in the background at a rate, their answers not
awaited, until ``flood_stop``), ``flood_stop``, ``quit``; each answer says ``ok`` or the error's
type and message, and how long the call took.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import random
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
from servobus.transports.sim import SimTransport


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
    """Every frame sent to the motors: ``(arbitration id, byte 0) -> [count, first ns, last ns]``."""

    def __init__(self) -> None:
        self.seen: dict[tuple[int, int], list[int]] = {}

    def add(self, arbitration_id: int, data: bytes) -> None:
        now = time.time_ns()
        key = (arbitration_id, data[0] if data else -1)
        entry = self.seen.get(key)
        if entry is None:
            self.seen[key] = [1, now, now]
        else:
            entry[0] += 1
            entry[2] = now

    def listed(self) -> list[list[int]]:
        return [[aid, b0, *entry] for (aid, b0), entry in sorted(self.seen.items())]


def logged_transport(frames: Frames, devices: list[MyActuatorMotor]) -> SimTransport:
    class Logged(SimTransport):
        def _put(self, frame: Any, handle: Any, now: float) -> None:
            frames.add(frame.arbitration_id, bytes(frame.data))
            super()._put(frame, handle, now)

    return Logged(devices=devices)


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
    async with servobus.Bus(logged_transport(frames, devices)) as bus:
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
                        }
                    )
                elif op == "reset":
                    frames.seen.clear()
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
        return {"shown_id": self.bus.shown_id, "motors": sorted(self.bus.motors)}

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


async def client_main(args: argparse.Namespace) -> None:
    client = Client(args)
    calls: dict[str, Callable[[dict[str, Any]], Any]] = {
        "connect": client.connect,
        "close": client.close,
        "request": client.request,
        "cycle": client.cycle,
        "raw_put": client.raw_put,
        "raw_get": client.raw_get,
        "flood": functools.partial(flood, client),
    }
    emit({"ready": True, "pid": os.getpid()})
    async with anyio.create_task_group() as group:
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
    parser.add_argument("--users")
    parser.add_argument("--commander", action="append", default=[])
    parser.add_argument("--reader", action="append", default=[])
    args = parser.parse_args()
    run = bridge_main if args.role == "bridge" else client_main
    anyio.run(run, args, backend=args.backend)


if __name__ == "__main__":
    main()

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
``raw_put``, ``raw_get``, ``quit``; each answer says ``ok`` or the error's type and message, and how
long the call took.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import os
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


class Hostile:
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
    calls: dict[str, Callable[[dict[str, Any]], Any]] = {
        "connect": client.connect,
        "close": client.close,
        "request": client.request,
        "cycle": client.cycle,
        "raw_put": client.raw_put,
        "raw_get": client.raw_get,
    }
    calls.update(Hostile(client).calls())
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

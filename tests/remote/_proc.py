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
(their counts; ``stop`` ends them), ``quit``; each answer says ``ok`` or the error's type and
message, and how long the call took.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
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
    and of them, those sent after the first stop (0x81) of their arbitration id (``after_stop``)."""

    def __init__(self) -> None:
        self.seen: dict[tuple[int, int], list[int]] = {}
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

    def listed(self) -> list[list[int]]:
        return [[aid, b0, *entry] for (aid, b0), entry in sorted(self.seen.items())]

    def clear(self) -> None:
        self.seen.clear()
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
                elif op == "pipeline":  # (pipelined: its counts, "stop": true ends it)
                    body = pipeline.start(client.bus, command, group)
                elif op == "pipelined":
                    body = pipeline.stop() if command.get("stop") else dict(pipeline.counts)
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
    parser.add_argument("--bitrate", type=float)  # the simulated CAN bus's (default: 1 Mbit/s)
    parser.add_argument("--users")
    parser.add_argument("--commander", action="append", default=[])
    parser.add_argument("--reader", action="append", default=[])
    args = parser.parse_args()
    run = bridge_main if args.role == "bridge" else client_main
    anyio.run(run, args, backend=args.backend)


if __name__ == "__main__":
    main()

"""A bridge and its clients as separate processes on the loopback interface (Zenoh peer mode, endpoints
on 127.0.0.1 only, no router, no scouting): the process boundaries the remote layer exists for.

Each process is tests/remote/_proc.py (one JSON command a line in, one ``@@`` line out per command).
The bridge's Bus sits on 32 simulated MyActuator motors behind a SimTransport that counts every frame
sent by arbitration id and first byte: what reached a motor is read there, and from each simulated
motor's control. Every wait is bounded (no call waits more than its timeout, and teardown kills
every process group), so a broken bridge fails a test instead of hanging CI.
"""

from __future__ import annotations

import contextlib
import ipaddress
import json
import math
import os
import queue
import random
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import servobus
from _ports import free_port
from servobus.protocols import myactuator as ma
from servobus.remote import wire

PROC = Path(__file__).with_name("_proc.py")
SRC = Path(servobus.__file__).resolve().parent.parent
NODE, BUS = "n", "b"
MOTORS = range(1, 33)
REQUEST_ID = 0x140  # + motor id: the requests a MyActuator motor takes (its control commands among them)
STOP, SPEED, STATUS2 = 0x81, 0xA2, 0x9C


class Proc:
    """One process of the test: its answers are read by a thread, so every wait has a timeout."""

    def __init__(self, role: str, port: int, *args: str, backend: str = "asyncio") -> None:
        self.role = role
        self.err = tempfile.TemporaryFile()  # noqa: SIM115 - closed by close(), at teardown
        env = dict(
            os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
        )
        self.process = subprocess.Popen(
            [sys.executable, str(PROC), role, "--port", str(port), "--backend", backend, *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.err,
            text=True,
            bufsize=1,
            start_new_session=True,
            env=env,
        )
        self.pid = self.process.pid
        self.answers: queue.Queue[dict[str, Any] | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            if line.startswith("@@ "):
                self.answers.put(json.loads(line[3:]))
        self.answers.put(None)

    def stderr(self) -> str:
        self.err.seek(0)
        return self.err.read().decode(errors="replace")[-3000:]

    def answer(self, timeout_s: float) -> dict[str, Any]:
        try:
            found = self.answers.get(timeout=timeout_s)
        except queue.Empty:
            raise AssertionError(
                f"{self.role} {self.pid}: no answer within {timeout_s} s\n{self.stderr()}"
            ) from None
        if found is None:
            raise AssertionError(
                f"{self.role} {self.pid} ended (code {self.process.poll()})\n{self.stderr()}"
            )
        return found

    def call(self, op: str, wait_s: float = 10.0, **fields: Any) -> dict[str, Any]:
        """Send command ``op`` with ``fields``; its answer (AssertionError after ``wait_s``)."""
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps({"op": op, **fields}) + "\n")
        self.process.stdin.flush()
        return self.answer(wait_s)

    def ok(self, op: str, wait_s: float = 10.0, **fields: Any) -> dict[str, Any]:
        found = self.call(op, wait_s, **fields)
        assert found.get("ok"), f"{self.role} {op}: {found}\n{self.stderr()}"
        return found

    def kill(self) -> None:
        if self.process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):  # (SIGKILL ends it: only a bound)
            self.process.wait(timeout=10)

    def close(self) -> None:
        self.kill()
        for stream in (self.process.stdin, self.process.stdout):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
        self.err.close()


@pytest.fixture
def spawn() -> Iterator[Callable[..., Proc]]:
    """``spawn(role, port, *args, backend=...)``: a process, killed (its whole group) at teardown."""
    started: list[Proc] = []

    def start(role: str, port: int, *args: str, backend: str = "asyncio") -> Proc:
        proc = Proc(role, port, *args, backend=backend)
        started.append(proc)
        ready = proc.answer(timeout_s=30)
        assert ready.get("ready"), ready
        return proc

    yield start
    for proc in started:
        proc.close()


def bridge(spawn: Callable[..., Proc], *args: str, backend: str = "asyncio") -> tuple[Proc, int]:
    port = free_port()
    return spawn("bridge", port, "--motors", str(len(MOTORS)), *args, backend=backend), port


# ---- what reached the motors ----


def frames_of(report: dict[str, Any]) -> dict[int, dict[int, list[int]]]:
    """``{motor id: {first byte: [count, first ns, last ns]}}`` of the request frames sent."""
    out: dict[int, dict[int, list[int]]] = {}
    for arbitration_id, byte0, count, first, last in report["frames"]:
        out.setdefault(arbitration_id - REQUEST_ID, {})[byte0] = [count, first, last]
    return out


def until(check: Callable[[], Any], timeout_s: float, what: str, interval_s: float = 0.05) -> Any:
    """``check()``'s first truthy value, polled; AssertionError naming ``what`` after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while True:
        found = check()
        if found:
            return found
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout_s} s: {what}")
        time.sleep(interval_s)


def report_when(
    bridge: Proc, condition: Callable[[dict[str, Any]], bool], timeout_s: float, what: str
) -> dict[str, Any]:
    last: dict[str, Any] = {}

    def check() -> dict[str, Any] | None:
        nonlocal last
        last = bridge.ok("report")
        return last if condition(last) else None

    try:
        return until(check, timeout_s, what)
    except AssertionError as exc:
        brief = {k: v for k, v in last.items() if k not in ("frames", "controls")}
        raise AssertionError(f"{exc}\nlast report: {brief}\n{bridge.stderr()}") from None


def speeds(report: dict[str, Any], motors: Any = MOTORS) -> dict[int, float | None]:
    controls = report["controls"]
    return {
        m: controls[str(m)].get("speed_dps") if controls[str(m)]["kind"] == "SpeedControl" else None
        for m in motors
    }


def stopped(report: dict[str, Any], motors: Any = MOTORS) -> bool:
    """Whether ``motors`` were each sent a stop (0x81) and hold their position (the stop took)."""
    frames = frames_of(report)
    controls = report["controls"]
    return all(STOP in frames.get(m, {}) and controls[str(m)]["kind"] == "PositionControl" for m in motors)


# ---- the sockets of a process ----


def _address(text: str) -> tuple[ipaddress.IPv4Address | ipaddress.IPv6Address, int]:
    host, port = text.split(":")
    raw = bytes.fromhex(host)
    # /proc/net/tcp{,6} prints each 32-bit word of the address in host (little-endian) order
    words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
    address = ipaddress.ip_address(words)
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address, int(port, 16)


def inet_sockets(pid: int) -> list[tuple[str, str, str, str]]:
    """``(protocol, local, remote, state)`` of every TCP/UDP socket process ``pid`` holds."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:[") : -1])
    found = []
    for protocol in ("tcp", "tcp6", "udp", "udp6"):
        with open(f"/proc/{pid}/net/{protocol}") as table:
            next(table)
            for line in table:
                parts = line.split()
                if parts[9] in inodes:
                    (lhost, lport), (rhost, rport) = _address(parts[1]), _address(parts[2])
                    state = "LISTEN" if parts[3] == "0A" else parts[3]
                    found.append((protocol, f"{lhost}:{lport}", f"{rhost}:{rport}", state))
    return found


def assert_loopback_only(pid: int, listen_port: int | None) -> list[tuple[str, str, str, str]]:
    """Every socket of ``pid`` is TCP on 127.0.0.1 (no UDP, so no scouting); it listens on
    ``127.0.0.1:listen_port`` alone (None: on nothing)."""
    found = inet_sockets(pid)
    assert found, f"process {pid} has no socket"
    for protocol, local, remote, state in found:
        assert protocol.startswith("tcp"), (protocol, local, remote, state)
        assert local.startswith("127.0.0.1:"), (protocol, local, remote, state)
        assert remote.startswith(("127.0.0.1:", "0.0.0.0:")), (protocol, local, remote, state)
    listening = sorted(local for _, local, _, state in found if state == "LISTEN")
    assert listening == ([] if listen_port is None else [f"127.0.0.1:{listen_port}"]), found
    return found


# ---- 1. a client drives 32 motors ----


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_client_drives_32_motors_and_its_clean_exit_stops_them(
    spawn: Callable[..., Proc], backend: str
) -> None:
    server, port = bridge(spawn, backend=backend)
    client = spawn("client", port, backend=backend)
    # (valid 0.5 s, not the default 0.1: a bridge whose loop lags 0.1 s on a loaded CI host rightly
    # drops set-points as stale and stops the motors; that is tested elsewhere, not here)
    me = client.ok("connect", valid_for_s=0.5)["shown_id"]
    client.ok("hold", motors=list(MOTORS), command="SpeedControl", fields={"speed_dps": 30.0}, hz=200.0)
    report_when(server, lambda r: set(speeds(r).values()) == {30.0}, 10, "all 32 motors at 30 dps")
    time.sleep(1.0)
    for motor in (1, 16, 32):
        found = client.ok("request", motor=motor, command="ReadStatus2")
        assert found["reply"]["type"] == "StatusReply"
        assert found["reply"]["speed_dps"] == pytest.approx(30.0, abs=1.0), found
    state = client.ok("counts")
    assert state["held"]["error"] is None, state
    assert all(
        s is not None and s["speed_dps"] == pytest.approx(30.0, abs=1.0) for s in state["states"].values()
    ), state

    # the processes talk over 127.0.0.1 only, the bridge listens on its endpoint alone, no UDP
    print("bridge sockets", assert_loopback_only(server.pid, port))
    print("client sockets", assert_loopback_only(client.pid, None))

    running = server.ok("report")
    frames = frames_of(running)
    assert all(frames[m][SPEED][0] > 0 and STOP not in frames[m] for m in MOTORS), frames
    assert all(frames[m][STATUS2][0] >= 1 for m in (1, 16, 32)), frames
    assert running["bridge"]["applied"] >= len(MOTORS) and running["bridge"]["malformed"] == 0
    assert running["owners"] == {str(m): me for m in MOTORS}

    # a clean exit while commanding: the client's token goes, the bridge stops its 32 motors
    closed = client.ok("close")
    done = report_when(server, stopped, 5, "stop frames to all 32 motors")
    reasons = {why for _, _, _, why in done["stop_log"]}
    print("clean exit: stops", sorted(reasons), "held cycles", closed)
    assert sorted(m for _, _, m, _ in done["stop_log"]) == list(MOTORS)
    assert all(c["kind"] == "PositionControl" for c in done["controls"].values()), done["controls"]
    assert done["owners"] == {} and done["clients"] == 0
    # the set-points sent: taken, dropped as stale or reordered, or refused (after the token went);
    # never more. Zenoh may drop some on the way (its congestion control drops rather than blocks a
    # put, and a session closing does not flush its last ones): most arrive.
    sent = closed["counts"]["setpoints_sent"]
    accounted = ("setpoints", "stale", "reordered", "refused")
    counts = server.ok("report")["bridge"]
    arrived = sum(counts[k] for k in accounted)
    print(f"{backend}: {sent} set-points sent, {sent - arrived} lost on the way")
    assert sent / 2 <= arrived <= sent, (counts, sent)
    print(
        f"{backend}: {counts['setpoints']} set-points taken, {counts['applied']} applied, "
        f"{counts['stale']} stale"
    )


# ---- 2. the client is killed: the bridge stops its motors ----


def test_a_killed_client_has_its_32_motors_stopped_at_once(spawn: Callable[..., Proc]) -> None:
    server, port = bridge(spawn)
    client = spawn("client", port)
    # set-points valid for 5 s: only the client's vanished token can stop the motors within 1 s
    client.ok("connect", valid_for_s=5.0)
    client.ok("hold", motors=list(MOTORS), command="SpeedControl", fields={"speed_dps": 45.0})
    report_when(server, lambda r: set(speeds(r).values()) == {45.0}, 10, "all 32 motors at 45 dps")
    server.ok("reset")
    killed_ns = time.time_ns()
    client.kill()
    done = report_when(server, stopped, 5, "stop frames to all 32 motors after the client was killed")
    frames = frames_of(done)
    first = [frames[m][STOP][1] - killed_ns for m in MOTORS]
    decided = [when - killed_ns for when, _, _, _ in done["stop_log"]]
    print(
        f"kill -> stop decided {min(decided) / 1e6:.1f} ms, stop frames "
        f"{min(first) / 1e6:.1f}..{max(first) / 1e6:.1f} ms"
    )
    assert {why for _, _, _, why in done["stop_log"]} == {"client left"}, done["stop_log"]
    assert sorted(m for _, _, m, _ in done["stop_log"]) == list(MOTORS)
    assert max(first) < 1e9, first
    # no set-point went out after the stop
    assert all(SPEED not in frames[m] or frames[m][SPEED][2] <= frames[m][STOP][1] for m in MOTORS), frames
    assert all(c["kind"] == "PositionControl" for c in done["controls"].values()), done["controls"]
    assert done["clients"] == 0 and done["owners"] == {}


def test_a_frozen_client_loses_its_motors_to_the_lease(spawn: Callable[..., Proc]) -> None:
    """A client process suspended (SIGSTOP: its link neither closes nor answers) that commanded a
    motor by a request only (no set-point to go stale) has it stopped when its 1 s lease ends."""
    server, port = bridge(spawn)
    client = spawn("client", port)
    client.ok("connect")
    client.ok("request", motor=5, command="SpeedControl", fields={"speed_dps": 20.0})
    report_when(server, lambda r: speeds(r, [5]) == {5: 20.0}, 10, "motor 5 at 20 dps")
    server.ok("reset")
    frozen_ns = time.time_ns()
    os.killpg(client.pid, signal.SIGSTOP)
    try:
        done = report_when(server, lambda r: stopped(r, [5]), 5, "motor 5 stopped after SIGSTOP")
    finally:
        os.killpg(client.pid, signal.SIGCONT)
    after_ms = (done["stop_log"][0][0] - frozen_ns) / 1e6
    print(f"SIGSTOP -> stop decided {after_ms:.0f} ms")
    assert [(m, why) for _, _, m, why in done["stop_log"]] == [(5, "client left")]
    assert 500 < after_ms < 3000, after_ms  # the lease (1 s), not the TCP close of a killed process


# ---- 3. the bridge is killed: the client's calls fail at once ----


def test_a_killed_bridge_fails_the_clients_calls_instead_of_hanging(spawn: Callable[..., Proc]) -> None:
    server, port = bridge(spawn, backend="trio")
    client = spawn("client", port)
    client.ok("connect", timeout_s=1.0)
    client.ok("hold", motors=[1, 2], command="SpeedControl", fields={"speed_dps": 10.0})
    assert client.ok("request", motor=1, command="ReadStatus2")["reply"]["type"] == "StatusReply"
    server.kill()
    killed = time.monotonic()
    failed = client.call("request", motor=1, command="ReadStatus2")
    waited = time.monotonic() - killed
    print(f"request after the bridge was killed: {failed.get('error')} after {waited * 1e3:.0f} ms: {failed}")
    assert not failed["ok"] and "RemoteError" in failed["errors"], failed
    assert waited < 3.0
    # the hold's set-points fail too (BridgeLost once the token's loss is seen), and a later request
    held = until(lambda: client.ok("counts")["held"]["error"], 3, "the hold's cycle to fail")
    assert held == "BridgeLost"
    again = client.call("request", motor=2, command="ReadStatus2")
    assert again["error"] == "BridgeLost" and again["elapsed_s"] < 0.5, again
    assert client.ok("close")["elapsed_s"] < 3
    # nobody listens there any more: connecting fails within its timeout, clearly
    refused = client.call("connect", timeout_s=1.0)
    print(f"connect to a dead endpoint: {refused['error']} after {refused['elapsed_s'] * 1e3:.0f} ms")
    assert not refused["ok"] and "RemoteError" in refused["errors"] and refused["elapsed_s"] < 3.0, refused
    assert "no bridge reachable" in refused["message"], refused


# ---- 4. two clients contend for a motor ----


def test_two_clients_contend_for_a_motor(spawn: Callable[..., Proc]) -> None:
    server, port = bridge(spawn)
    a = spawn("client", port)
    b = spawn("client", port, backend="trio")
    a_id = a.ok("connect")["shown_id"]
    b_id = b.ok("connect")["shown_id"]
    a.ok("hold", motors=[3], command="SpeedControl", fields={"speed_dps": 30.0})
    report_when(server, lambda r: speeds(r, [3]) == {3: 30.0}, 10, "motor 3 at A's 30 dps")
    before = server.ok("report")["bridge"]["refused"]
    b.ok("hold", motors=[3], command="SpeedControl", fields={"speed_dps": -50.0})
    contended = report_when(
        server, lambda r: r["bridge"]["refused"] >= before + 20, 10, "B's set-points refused"
    )
    time.sleep(0.3)
    contended = server.ok("report")
    assert speeds(contended, [3]) == {3: 30.0}, contended["controls"]["3"]
    assert contended["owners"] == {"3": a_id}
    assert contended["bridge"]["refused"] >= before + 20
    # B's command through a request is refused; its read is answered
    refused = b.call("request", motor=3, command="SpeedControl", fields={"speed_dps": -50.0})
    assert not refused["ok"] and refused["error"] == "PermissionError", refused
    assert "held by another client" in refused["message"]
    read = b.ok("request", motor=3, command="ReadStatus2")
    assert read["reply"]["speed_dps"] == pytest.approx(30.0, abs=1.0), read
    assert frames_of(server.ok("report"))[3].keys() <= {SPEED, STATUS2}
    # A leaves: its motor is stopped, then B (still sending) has it
    a.ok("close")
    taken = report_when(
        server, lambda r: speeds(r, [3]) == {3: -50.0} and r["owners"] == {"3": b_id}, 5, "motor 3 at B's -50"
    )
    assert [(m, why) for _, _, m, why in taken["stop_log"]] == [(3, "client left")]
    assert b.ok("request", motor=3, command="SpeedControl", fields={"speed_dps": -50.0})["reply"]
    assert b.ok("counts")["held"]["error"] is None


# ---- 5. malformed payloads to every key ----

SCHEMA = wire.Schema.of(ma.FAMILY.name)
NOBODY = "00" * wire.CLIENT_ID_BYTES  # a client id with no liveliness token
F64_30 = struct.pack("<d", 30.0)


def key(*parts: object) -> str:
    return "/".join(["servobus", NODE, BUS, *map(str, parts)])


def setpoints(items: list[tuple[int, Any]], client_id: str = NOBODY) -> bytes:
    now = time.time_ns()
    return wire.encode_setpoints(
        lambda _: SCHEMA, wire.Setpoints(client_id, 1, now, now + 5_000_000_000, tuple(items))
    )


def request(command: Any, client_id: str = NOBODY, timeout_s: float | None = None) -> bytes:
    return wire.encode_request(SCHEMA, wire.Request(client_id, command, timeout_s))


def edited(message: bytes, old: bytes, new: bytes) -> bytes:
    """``message`` with its one occurrence of ``old`` replaced (a value past what its type allows)."""
    assert message.count(old) == 1, (message, old)
    return message.replace(old, new)


def malformed_setpoints() -> list[tuple[str, str, bytes]]:
    """``(what, key, payload)``: each is one malformed message to the bridge."""
    speed = ma.SpeedControl(speed_dps=30.0)
    good = setpoints([(3, speed)])
    head = good[: 2 + wire.CLIENT_ID_BYTES + 4 + 8 + 8]  # version, kind, client, seq, sent, deadline
    reply = ma.StatusReply(
        temperature_c=25, current_a=0.0, speed_dps=0.0, angle_deg=0.0, command=ma.StatusCommand.READ_STATUS_2
    )
    nested = b"\x07\x01" * 12 + b"\x00"  # a tuple of a tuple of ... deeper than the wire allows
    rng = random.Random(29)
    bulk = key("setpoints")
    return [
        ("empty", bulk, b""),
        ("one byte", bulk, b"\x01"),
        ("truncated", bulk, good[:-3]),
        ("a byte left over", bulk, good + b"\x00"),
        ("wrong version", bulk, bytes([wire.VERSION + 1]) + good[1:]),
        ("wrong kind", bulk, good[:1] + bytes([wire.REQUEST]) + good[2:]),
        ("speed past its range", bulk, edited(good, F64_30, struct.pack("<d", 1e12))),
        ("speed NaN", bulk, edited(good, F64_30, struct.pack("<d", math.nan))),
        ("speed a string", bulk, edited(good, b"\x04" + F64_30, b"\x05\x02\x0030")),
        ("speed True", bulk, edited(good, b"\x04" + F64_30, b"\x02")),
        ("no motor 99 on the bus", bulk, setpoints([(99, speed)])),
        ("a reply, not a command", bulk, setpoints([(3, reply)])),
        ("an int, not a command", bulk, head + struct.pack("<HH", 1, 3) + b"\x03" + struct.pack("<q", 7)),
        ("a type past the schema", bulk, head + struct.pack("<HH", 1, 3) + b"\x09\xff\xff\x00"),
        ("nested too deep", bulk, head + struct.pack("<HH", 1, 3) + nested),
        ("300 set-points", bulk, head + struct.pack("<H", 300) + b"\x00" * 600),
        ("random bytes", bulk, rng.randbytes(64)),
        ("2 MB", bulk, good[:2] + rng.randbytes(2_000_000)),
        ("motor 4's set-point on motor 3's key", key(3, "setpoint"), setpoints([(4, speed)])),
        ("motors 3 and 4 on motor 3's key", key(3, "setpoint"), setpoints([(3, speed), (4, speed)])),
        ("motor 99's key", key(99, "setpoint"), setpoints([(99, speed)])),
        ("a motor key that is not a number", key("x", "setpoint"), good),
        ("random bytes on a motor's key", key(3, "setpoint"), rng.randbytes(40)),
    ]


def malformed_requests() -> list[tuple[str, str, bytes | None]]:
    speed = ma.SpeedControl(speed_dps=30.0)
    good = request(speed)
    read = request(ma.ReadStatus2())
    return [
        ("no payload", key(3, "request"), None),
        ("random bytes", key(3, "request"), random.Random(3).randbytes(50)),
        ("a set-point message", key(3, "request"), setpoints([(3, speed)])),
        ("wrong version", key(3, "request"), bytes([9]) + good[1:]),
        ("timeout -1", key(3, "request"), request(speed, timeout_s=-1.0)),
        ("timeout inf", key(3, "request"), request(speed, timeout_s=math.inf)),
        ("timeout 1e9", key(3, "request"), request(speed, timeout_s=1e9)),
        ("speed past its range", key(3, "request"), edited(good, F64_30, struct.pack("<d", -1e12))),
        ("truncated", key(3, "request"), good[:-1]),
        ("no motor 99", key(99, "request"), good),
        ("a motor key that is not a number", key("x", "request"), good),
        ("a motor key with a sign", key("+3", "request"), good),
        ("read: no payload", key(3, "read"), None),
        ("read: truncated", key(3, "read"), read[:-2]),
        ("read: no motor 99", key(99, "read"), read),
    ]


def test_malformed_payloads_to_every_key_reach_no_motor(spawn: Callable[..., Proc]) -> None:
    server, port = bridge(spawn)
    watcher = spawn("client", port)
    raw = spawn("client", port)
    watcher.ok("connect")
    server.ok("reset")
    puts = malformed_setpoints()
    queries = malformed_requests()
    raw.ok("raw_put", items=[(k, p.hex()) for _, k, p in puts])
    answered = raw.ok("raw_get", items=[(k, None if p is None else p.hex()) for _, k, p in queries])[
        "answers"
    ]
    for (what, _, _), found in zip(queries, answered, strict=True):
        # each query is answered once, with the error, never left waiting
        assert len(found["ok"]) == 1 and not found["err"], (what, found)
        result = wire.decode_result(SCHEMA, bytes.fromhex(found["ok"][0]))
        assert isinstance(result.error, ValueError) and "malformed" in str(result.error), (what, result)
    expected = len(puts) + len(queries)

    def taken(r: dict[str, Any]) -> int:
        # each bad message is malformed, or was replaced on its key by the next one of the same
        # (garbage) client id before the bridge read it, or too long to be read at all (2 MB):
        # never applied, never lost track of
        return int(r["bridge"]["malformed"] + r["bridge"]["overwritten"] + r["bridge"]["oversized"])

    done = report_when(server, lambda r: taken(r) >= expected, 10, f"{expected} malformed or overwritten")
    assert taken(done) == expected, done["bridge"]
    expected = done["bridge"]["malformed"]
    # well formed, but not allowed: a set-point or a command from a client with no token, a command
    # sent as a read
    raw.ok("raw_put", items=[(key("setpoints"), setpoints([(3, ma.SpeedControl(speed_dps=30.0))]).hex())])
    refused = raw.ok(
        "raw_get",
        items=[
            (key(3, "request"), request(ma.SpeedControl(speed_dps=30.0)).hex()),
            (key(3, "read"), request(ma.MotorStop()).hex()),
            (key(3, "request"), request(ma.MotorStop(), client_id="ab" * 16).hex()),
        ],
    )["answers"]
    errors = [wire.decode_result(SCHEMA, bytes.fromhex(found["ok"][0])).error for found in refused]
    assert all(isinstance(e, PermissionError) for e in errors), errors
    print("refused:", *errors, sep="\n  ")
    # info and metrics ignore a payload
    for leaf in ("info", "metrics"):
        found = raw.ok("raw_get", items=[(key(leaf), b"\xff\x00garbage".hex())])["answers"][0]
        assert isinstance(json.loads(bytes.fromhex(found["ok"][0])), dict), found
    # state puts by a client: the bridge subscribes to no state (and, a peer, forwards nothing)
    raw.ok("raw_put", items=[(key(3, "state"), b"\x01\x04garbage".hex()), (key(3, "state"), b"".hex())])
    after = report_when(server, lambda r: r["bridge"]["refused"] >= 4, 5, "4 refusals")
    assert after["bridge"]["malformed"] == expected and after["bridge"]["refused"] == 4, after["bridge"]
    assert after["bridge"]["setpoints"] == 0 and after["bridge"]["applied"] == 0, after["bridge"]
    # nothing reached a motor; the bridge is alive and serves
    assert after["frames"] == [], after["frames"]
    assert all(c["kind"] == "Off" for c in after["controls"].values()), after["controls"]
    assert after["dropped_events"] == 0 and after["stop_log"] == []
    assert "Traceback" not in server.stderr(), server.stderr()  # bad input is not a bug of the bridge
    assert watcher.ok("request", motor=3, command="ReadStatus2")["reply"]["type"] == "StatusReply"
    watcher.ok("hold", motors=[3], command="SpeedControl", fields={"speed_dps": 30.0})
    report_when(server, lambda r: speeds(r, [3]) == {3: 30.0}, 5, "motor 3 commanded after it all")
    print("watcher:", watcher.ok("counts")["counts"])


# ---- 6. credentials: wrong ones refused, a reader reaches no motor ----


def test_wrong_credentials_and_a_reader_reach_no_motor(spawn: Callable[..., Proc], tmp_path: Path) -> None:
    users = tmp_path / "users.txt"
    users.write_text("cmd:cmd-secret\nro:ro-secret\n")
    server, port = bridge(spawn, "--users", str(users), "--commander", "cmd", "--reader", "ro")
    client = spawn("client", port)
    for what, user, password in [
        ("wrong password", "cmd", "guess"),
        ("unknown user", "mallory", "cmd-secret"),
        ("a reader's name, the commander's password", "ro", "cmd-secret"),
        ("no credentials", None, None),
    ]:
        refused = client.call("connect", user=user, password=password, timeout_s=1.0)
        print(f"{what}: {refused.get('error')} after {refused['elapsed_s'] * 1e3:.0f} ms")
        assert not refused["ok"] and "RemoteError" in refused["errors"], (what, refused)
        assert refused["elapsed_s"] < 3.0, (what, refused)
    assert server.ok("report")["clients"] == 0

    # the commander commands (the access rules let it through), and its leaving stops its motors
    client.ok("connect", user="cmd", password="cmd-secret")
    client.ok("hold", motors=[1, 2], command="SpeedControl", fields={"speed_dps": 30.0})
    report_when(server, lambda r: speeds(r, [1, 2]) == {1: 30.0, 2: 30.0}, 5, "the commander's set-points")
    client.ok("close")
    report_when(server, lambda r: stopped(r, [1, 2]), 5, "motors 1, 2 stopped after the commander left")

    server.ok("reset")
    before = server.ok("report")
    reader = spawn("client", port, backend="trio")
    for read_only in (True, False):  # a reader that says so, and one that tries to command anyway
        reader.ok("connect", user="ro", password="ro-secret", read_only=read_only, timeout_s=1.0)
        assert server.ok("report")["clients"] == 0  # a reader's token is denied: it commands nothing
        read = reader.ok("request", motor=1, command="ReadStatus2")
        assert read["reply"]["type"] == "StatusReply", read
        until(lambda: reader.ok("counts")["counts"]["states"] > 0, 5, "a state reaching the reader")
        command = reader.call("request", motor=1, command="SpeedControl", fields={"speed_dps": 90.0})
        print(f"reader (read_only={read_only}) commanding: {command.get('error')}: {command.get('message')}")
        assert not command["ok"], command
        if read_only:
            assert command["error"] == "PermissionError", command
            cycle = reader.call("cycle", motors=[1], command="SpeedControl", fields={"speed_dps": 90.0})
            assert cycle["error"] == "PermissionError", cycle
        else:  # its query is denied by the bridge's access control: it gets no answer, said clearly
            assert "RemoteError" in command["errors"] and "access control" in command["message"], command
            reader.ok("hold", motors=[1, 2, 3], command="SpeedControl", fields={"speed_dps": 90.0})
            time.sleep(0.5)
            assert reader.ok("release")["error"] is None
        reader.ok("close")
    after = server.ok("report")
    # only reads reached the motors; no set-point or request reached the bridge
    assert {b for frames in frames_of(after).values() for b in frames} == {STATUS2}, after["frames"]
    for name in ("setpoints", "applied", "requests", "refused", "malformed", "stops"):
        assert after["bridge"][name] == before["bridge"][name], (name, before["bridge"], after["bridge"])
    assert after["bridge"]["reads"] == before["bridge"]["reads"] + 2
    assert after["clients"] == 0 and after["owners"] == {}
    assert all(c["kind"] != "SpeedControl" for c in after["controls"].values()), after["controls"]

"""A reader attacks the bridge with queries (issue 37, attacks 1 and 4's queries): one 10 MB read,
64 KB reads at 200/s, a flood of reads and metrics at 1,100/s (some with a client id forged afresh
for each). Under each, at once: a commander holds 16 motors at 200 Hz and must keep its set-point ->
wire latency (p99 within 2x the quiet value, both medians of windows in turn, or 4 ms) and its
set-points; a second commander is SIGKILLed and must have its 16 motors stopped within 250 ms; the
bridge must not grow by more than 50 MB; the first commander's own reads are answered.

Processes as in test_procs.py (tests/remote/_proc.py, loopback only, every wait bounded).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

from servobus.protocols import myactuator as ma
from servobus.remote import wire

from .test_procs import NODE, SCHEMA, STOP, Proc, bridge, frames_of, report_when, spawn, speeds, stopped

__all__ = ["spawn"]  # (the fixture, from test_procs)

HELD = list(range(1, 17))  # the commander that stays: set-points at 200 Hz
KILLED = list(range(17, 33))  # the commander that is SIGKILLed: speed requests, valid until it leaves
ROUNDS, WINDOW_S = 5, 0.7  # quiet and attacked windows in turn, each this long
READS_PER_S, READ_BURST = 100.0, 10  # (what docs/remote.md says of readers: _limits')
P99_FLOOR_MS = 4.0  # (the p99 limit is 2x the quiet p99, never below this: noise on a loaded host)


def key(*parts: object) -> str:
    return "/".join(["servobus", NODE, "b", *map(str, parts)])


def read_of(value: bytes, client_id: str = "5e" * wire.CLIENT_ID_BYTES) -> bytes:
    """A ``read`` request whose command is the encoded ``value`` (not a command: only decoding tells)."""
    head = wire.encode_request(SCHEMA, wire.Request(client_id, ma.ReadStatus2()))
    return head[: 2 + wire.CLIENT_ID_BYTES + 8] + value


def nested(counts: list[int]) -> bytes:
    """Tuples of tuples (``counts`` items at each depth) of None: within the depth limit, any size."""
    body = b"\x00"
    for count in reversed(counts):
        body = b"\x07" + bytes([count]) + body * count
    return body


def attacked(spawn: Callable[..., Proc], attack: Callable[[Proc], None]) -> dict[str, Any]:
    """Run ``attack(reader)`` against a bridge serving two commanders; what was measured."""
    server, port = bridge(spawn)
    held, killed, reader = spawn("client", port), spawn("client", port), spawn("client", port)
    held.ok("connect", valid_for_s=0.5)
    held.ok("hold", motors=HELD, command="SpeedControl", fields={"speed_dps": 30.0}, hz=200.0)
    killed.ok("connect")
    for motor in KILLED:
        killed.ok("request", motor=motor, command="SpeedControl", fields={"speed_dps": 45.0})
    reader.ok("raw_get", items=[(key("info"), None)])  # (its session open before the clock starts)
    report_when(
        server,
        lambda r: set(speeds(r, HELD).values()) == {30.0} and set(speeds(r, KILLED).values()) == {45.0},
        10,
        "the two commanders' motors at 30 and 45 dps",
    )
    # quiet and attacked windows in turn: the figures are each kind's median, so that other work
    # on the host starting or ending meanwhile is not blamed on (nor hidden by) the attack
    quiet: list[dict[str, Any]] = []
    during: list[dict[str, Any]] = []
    floods: list[dict[str, int]] = []
    attack_s = 0.0
    for turn in range(ROUNDS):
        server.ok("reset")
        time.sleep(WINDOW_S)
        quiet.append(server.ok("report"))
        server.ok("reset")
        began = time.monotonic()
        attack(reader)
        if turn == ROUNDS // 2:  # the second commander is killed under attack
            time.sleep(WINDOW_S / 3)
            killed_ns = time.time_ns()
            killed.kill()
            done = report_when(
                server, lambda r: stopped(r, KILLED), 5, "the killed commander's motors stopped"
            )
            first = [frames_of(done)[m][STOP][1] - killed_ns for m in KILLED]
            asked = time.monotonic()
            own = held.ok("request", motor=1, command="ReadStatus2", timeout_s=1.0)
            own_ms = (time.monotonic() - asked) * 1e3
        time.sleep(max(0.0, WINDOW_S - (time.monotonic() - began)))
        during.append(server.ok("report"))
        floods += reader.ok("flood_stop")["counts"]
        attack_s += time.monotonic() - began
    sent = held.ok("release")["cycles"] * len(HELD)
    time.sleep(0.3)  # (the last set-points on their way)
    after = server.ok("report")

    def median(reports: list[dict[str, Any]], figure: Callable[[dict[str, Any]], float]) -> float:
        return float(statistics.median(figure(r) for r in reports))

    def p99(report: dict[str, Any]) -> float:
        return float(report["to_wire_ms"]["p99"])

    def lag(report: dict[str, Any]) -> float:
        return float(report["loop_lag_ms"])

    found = {
        "quiet_p99_ms": median(quiet, p99),
        "attack_p99_ms": median(during, p99),
        "quiet_lag_ms": median(quiet, lag),  # (each window's worst lag; their median)
        "attack_lag_ms": median(during, lag),
        "stop_ms": max(first) / 1e6,
        "own_read_ms": own_ms,
        "rss_growth_mb": max(r["rss_mb"] for r in during) - quiet[0]["rss_mb"],
        "sent": sent,
        "counts": after["bridge"],
        "dropped_events": after["dropped_events"],
        "floods": floods,
        "attack_s": attack_s,
    }
    print(
        f"quiet p99 {[p99(r) for r in quiet]} ms, worst loop lag {[lag(r) for r in quiet]} ms; under "
        f"attack: p99 {[p99(r) for r in during]} ms, worst loop lag {[lag(r) for r in during]} ms, "
        f"kill -> last stop frame {found['stop_ms']:.1f} ms, own read "
        f"{own_ms:.1f} ms, RSS {quiet[0]['rss_mb']:.0f} MB + {found['rss_growth_mb']:.1f} MB; "
        f"floods {floods}; set-points sent {sent}, bridge {after['bridge']}, "
        f"dropped events {after['dropped_events']}"
    )
    assert own["reply"]["type"] == "StatusReply", own
    # (a host that stalls every process past valid_for_s may stop the other's too, as stale: not this)
    assert sorted(m for _, _, m, why in done["stop_log"] if why == "client left") == KILLED, done["stop_log"]
    return found


def assert_unharmed(found: dict[str, Any]) -> None:
    """What no reader may take from the commanders, whatever it sends."""
    limit_ms = max(2 * found["quiet_p99_ms"], P99_FLOOR_MS)
    assert found["attack_p99_ms"] <= limit_ms, found
    assert found["stop_ms"] <= 250, found
    assert found["rss_growth_mb"] <= 50, found
    counts = found["counts"]
    # every set-point the commander sent that reached the bridge was taken, or replaced by its next
    # before the loop took it (``overwritten``: the bridge applies the newer): none stale, none
    # dropped on the way in. (Zenoh itself may drop some before the bridge sees them: the client's
    # publisher drops rather than blocks when its link is not drained. None were lost on a host at
    # load 2-4; at load 5-6, up to 1.4 % under the flood and 0.5 % in a control run whose flood went
    # to a key nobody serves; main lost 12 %.)
    assert counts["stale"] == 0 and found["dropped_events"] == 0, found
    lost = found["sent"] - counts["setpoints"] - counts["overwritten"] * len(HELD)
    # (-16: the hold's last batch, published as it was released, before it was counted)
    assert -len(HELD) <= lost <= found["sent"] * 0.03, found


# ---- attack 1: big queries ----


def test_a_readers_10_mb_and_64_kb_reads_neither_stall_the_bridge_nor_delay_a_stop(
    spawn: Callable[..., Proc],
) -> None:
    big = read_of(nested([255, 255, 160]))  # 10.5 MB, 10.4 million values, 3 deep
    medium = read_of(nested([255, 255]))  # 65 KB
    assert len(big) > 10_000_000 and len(medium) > 65_000

    def attack(reader: Proc) -> None:
        reader.ok("flood", keys=[key(1, "read")], payload=big.hex(), hz=0.5, duration_s=1.0)
        reader.ok("flood", keys=[key(2, "read")], payload=medium.hex(), hz=200.0, duration_s=60.0)

    found = attacked(spawn, attack)
    assert_unharmed(found)
    assert found["attack_lag_ms"] < 200, found  # (main: the 10 MB read alone held the loop 2.9 s)
    # (the reader tries 200/s; Zenoh slows its gets by backpressure: 100-175/s were seen, and on a
    # loaded host less, so the floor here only says that the attack took place)
    sent = sum(flood["sent"] for flood in found["floods"])
    assert found["counts"]["oversized"] == sent >= 50 * found["attack_s"], found
    assert found["counts"]["malformed"] == 0, found  # dropped unread: nothing of them was decoded


# ---- attack 4, queries: a flood of reads and metrics ----


def test_a_reader_flood_of_reads_and_metrics_at_1100_per_s_starves_no_commander(
    spawn: Callable[..., Proc],
) -> None:
    read = wire.encode_request(SCHEMA, wire.Request("5e" * wire.CLIENT_ID_BYTES, ma.ReadStatus2()))
    reads = [key(m, "read") for m in range(1, 33)]

    def attack(reader: Proc) -> None:
        reader.ok("flood", keys=reads, payload=read.hex(), hz=600.0, duration_s=60.0)
        reader.ok("flood", keys=reads, payload=read.hex(), hz=300.0, duration_s=60.0, fresh_id=True)
        reader.ok("flood", keys=[key("metrics")], payload=None, hz=200.0, duration_s=60.0)

    found = attacked(spawn, attack)
    sent = sum(flood["sent"] for flood in found["floods"])
    answered = sum(flood["answers"] for flood in found["floods"])
    # (the reader tries 1,100/s, and reaches it on a host at load 4; on a loaded host less: the floor
    # only says that the flood took place)
    assert sent >= 700 * found["attack_s"], found
    # the readers together are served at their rate (100/s, in bursts of 10: _limits), not starved,
    # not more (main: about half of them), the rest shed on arrival
    most = READS_PER_S * found["attack_s"] + ROUNDS * READ_BURST
    assert 0.3 * most <= answered <= 1.2 * most, found
    assert_unharmed(found)
    assert found["attack_lag_ms"] < 200, found  # (main: 550 ms)
    assert found["counts"]["shed"] >= 0.8 * (sent - answered), found  # (the rest: waiting at the end)


def test_the_readers_rate_is_the_documented_one() -> None:
    from servobus.remote import _limits

    assert (_limits.READS_PER_S, _limits.READ_BURST) == (READS_PER_S, READ_BURST)


# ---- the queues themselves (remote/_queries.py), without processes ----


class _ZBytes(bytes):
    def to_bytes(self) -> bytes:
        return bytes(self)


class _Query:
    """What the bridge reads of a ``zenoh.Query`` on Zenoh's thread."""

    def __init__(self, key: str, payload: bytes | None) -> None:
        self.key_expr, self.payload = key, None if payload is None else _ZBytes(payload)


class _Lane:
    def __init__(self) -> None:
        self.now, self.woken = 0.0, 0

    def time(self) -> float:
        return self.now

    def call_soon_threadsafe(self, fn: Callable[..., object], *args: Any) -> None:
        self.woken += 1


def test_queries_queue_per_client_and_kind_and_a_forged_id_buys_no_more_than_the_cap() -> None:
    from servobus.remote import _limits, _queries

    commander, reader = "c0" * wire.CLIENT_ID_BYTES, "5e" * wire.CLIENT_ID_BYTES
    live = {wire.public_id(commander)}
    lane = _Lane()
    queries = _queries.Queries(lane, live.__contains__)  # type: ignore[arg-type]
    served = type("Served", (), {"counts": {"oversized": 0, "shed": 0}})()

    async def handler(served: Any, query: Any) -> None: ...

    take = queries.callback(handler, served)
    read = wire.encode_request(SCHEMA, wire.Request(reader, ma.ReadStatus2()))
    forged = [read[:2] + bytes([i % 256, i // 256]) * 8 + read[18:] for i in range(2000)]
    for i in range(2000):  # a reader's flood: its own id, a fresh id each time, metrics
        take(_Query(key(1 + i % 32, "read"), read))
        take(_Query(key(1 + i % 32, "read"), forged[i]))
        take(_Query(key("metrics"), None))
    take(_Query(key(1, "read"), read[:2] + b"\x00" * _limits.REQUEST_BYTES))  # one byte too long
    readers, commanders = queries._readers, queries._commanders
    assert readers.waiting == _limits.READERS_WAITING  # (every lane and the class full: no more)
    assert all(len(q) <= _limits.READER_WAITING for q in readers.lanes.values())
    assert served.counts == {"oversized": 1, "shed": 6000 - _limits.READERS_WAITING}
    # a client's connect (its info query) is still taken and begun: info is a class of its own
    take(_Query(key("info"), None))
    assert queries._infos.waiting == 1 and served.counts["shed"] == 6000 - _limits.READERS_WAITING
    began: list[Any] = []
    assert queries._infos.take(lane.now, began) is None and len(began) == 1
    # a commander's queries (its id has a live token) wait apart: the readers' full queues take none
    mine = wire.encode_request(SCHEMA, wire.Request(commander, ma.ReadStatus2()))
    for motor in HELD:
        take(_Query(key(motor, "read"), mine))
    assert commanders.waiting == len(HELD) and list(commanders.lanes) == [bytes.fromhex(commander)]
    # begun: all the commander's at once; of the readers', their cap, round-robin, at most two a lane
    out: list[Any] = []
    assert commanders.take(lane.now, out) is None and len(out) == len(HELD)
    out.clear()
    readers.take(lane.now, out)
    assert len(out) == _limits.READERS_RUNNING and len({lane for _, lane, _ in out}) == len(out)
    # and no more than READS_PER_S a second, however many finish
    begun = len(out)
    for second in range(1, 4):
        lane.now = float(second)
        while True:
            for kind, done, _ in out:
                kind.done(done)
            out.clear()
            wait_s = readers.take(lane.now, out)
            begun += len(out)
            if not out:
                break
        assert wait_s is not None and 0 < wait_s <= 1 / _limits.READS_PER_S
    assert begun <= _limits.READ_BURST + 3 * _limits.READS_PER_S

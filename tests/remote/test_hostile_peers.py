"""Hostile peers on the default bridge (no users, loopback only): another local program that opens a
Zenoh session of its own, in ``client`` mode (which a Zenoh peer routes for) or in ``peer`` mode,
watches everything under ``servobus/**`` and then acts with every id it found, cannot learn a
commanding client's secret or token, cannot command its motors, and cannot keep its token alive
when it dies.

The processes are those of tests/remote/test_procs.py (tests/remote/_proc.py): a bridge on 32
simulated MyActuator motors that counts every frame sent (its speed frames by value), a victim
client, and two hostile clients. Every wait is bounded.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from remote.test_procs import NODE, REQUEST_ID, STOP, Proc, bridge, frames_of, report_when, spawn, speeds

__all__ = ["spawn"]  # (the fixture, imported for pytest)

VICTIM_MOTORS = [1, 2, 3, 4]
VICTIM_DPS = 30.0
HOSTILE_DPS = 333.0  # what a hostile sends in another's name: a speed nobody else sends
OWN_DPS = 444.0  # what a hostile sends in its own name
STOP_WITHIN_MS = 250.0


def frames_at(report: dict[str, Any], dps: float) -> dict[int, list[int]]:
    """``{motor id: [count, first ns, last ns]}`` of the speed frames at ``dps``."""
    return {aid - REQUEST_ID: entry for aid, at, *entry in report["speed_frames"] if at == dps}


def test_a_local_program_cannot_act_in_a_clients_name(spawn: Callable[..., Proc]) -> None:
    server, port = bridge(spawn)
    victim = spawn("client", port)
    # valid 1 s (the bridge's max_valid_s): within 250 ms of its death only its vanished token can
    # stop its motors, not the staleness of its set-points
    me = victim.ok("connect", valid_for_s=1.0)
    victim.ok(
        "hold", motors=VICTIM_MOTORS, command="SpeedControl", fields={"speed_dps": VICTIM_DPS}, hz=200.0
    )
    report_when(
        server,
        lambda r: speeds(r, VICTIM_MOTORS) == dict.fromkeys(VICTIM_MOTORS, VICTIM_DPS),
        10,
        "the victim's motors at its speed",
    )
    hostiles = {mode: spawn("client", port) for mode in ("client", "peer")}
    for mode, hostile in hostiles.items():
        hostile.ok("spy", mode=mode)
    time.sleep(1.0)  # (the victim sends ~200 batches meanwhile)

    # what each saw: the public part only (the bridge's token, states), nothing of the victim
    secret, token = me["client_id"], me["token_id"]
    for mode, hostile in hostiles.items():
        seen = hostile.ok("spied")
        brief = {k: v if not isinstance(v, list) else v[:5] for k, v in seen.items()}
        print(f"{mode}-mode spy: {len(seen['samples'])} samples, {seen['states']} states, {seen['tokens']}")
        assert f"servobus/{NODE}/_alive" in seen["tokens"], (mode, brief)  # connected, and served
        assert seen["states"] > 0, (mode, brief)
        everything = repr(seen)
        assert secret not in everything, (mode, "the victim's secret id", brief)
        assert token not in everything, (mode, "the victim's token id", brief)
        assert seen["samples"] == [] and seen["queries"] == [] and seen["token_ids"] == [], (mode, brief)

    # they act with every id they found or were told (a refusal's message among them)
    server.ok("reset")
    before = server.ok("report")["bridge"]
    for mode, hostile in hostiles.items():
        tried = hostile.ok(
            "impersonate",
            motors=VICTIM_MOTORS,
            command="SpeedControl",
            fields={"speed_dps": HOSTILE_DPS},
            own_fields={"speed_dps": OWN_DPS},
            hz=200.0,
        )
        print(f"{mode}-mode hostile tries: {tried}")
        assert secret not in tried["secrets"] and token not in tried["token_copies"], (mode, tried)
    time.sleep(1.0)
    acting = server.ok("report")
    # nothing in the victim's name, nor in its own (the victim holds the motors)
    assert frames_at(acting, HOSTILE_DPS) == {} and frames_at(acting, OWN_DPS) == {}, acting["speed_frames"]
    assert speeds(acting, VICTIM_MOTORS) == dict.fromkeys(VICTIM_MOTORS, VICTIM_DPS), acting["controls"]
    assert acting["owners"] == {str(m): me["shown_id"] for m in VICTIM_MOTORS}, acting["owners"]
    # the hostile's messages did reach the bridge, and were refused there
    assert acting["bridge"]["refused"] > before["refused"], (before, acting["bridge"])
    for mode, hostile in hostiles.items():
        done = hostile.ok("impersonated")
        print(f"{mode}-mode hostile: {done}")
        assert done["sent"]["puts"] > 0 and done["answers"].get("PermissionError", 0) > 0, (mode, done)
        assert done["answers"].get("ok", 0) == 0, (mode, done)

    # the victim dies while the hostile sessions run on: its motors stop at once
    server.ok("reset")
    killed_ns = time.time_ns()
    victim.kill()
    done = report_when(
        server,
        lambda r: all(STOP in frames_of(r).get(m, {}) for m in VICTIM_MOTORS),
        5,
        "stop frames to the victim's motors",
    )
    frames = frames_of(done)
    after_ms = [(frames[m][STOP][1] - killed_ns) / 1e6 for m in VICTIM_MOTORS]
    print(f"kill -> stop frames {min(after_ms):.1f}..{max(after_ms):.1f} ms, stop log {done['stop_log']}")
    assert max(after_ms) <= STOP_WITHIN_MS, after_ms
    assert {why for _, _, _, why in done["stop_log"]} == {"client left"}, done["stop_log"]
    time.sleep(0.5)
    final = server.ok("report")
    assert frames_at(final, HOSTILE_DPS) == {}, final["speed_frames"]
    # (a motor set free is anyone's on the default bridge: the hostile may take it in its own name)
    print(f"taken after the victim's stop, in the hostile's own name: {sorted(frames_at(final, OWN_DPS))}")
    for mode, hostile in hostiles.items():
        assert hostile.ok("impersonated")["running"], mode  # (still there, still trying)

"""A commander that pipelines requests (more in flight than its motors answer, so they queue on the
bridge's Bus) and then loses its motors: killed, or its set-points gone stale. Its commands still
queued must not follow the bridge's stop (the stop has another reply key and would overtake them),
and its requests still on their way must not take the stopped motors back. Multi-process, on
loopback (tests/remote/_proc.py); what reached each motor is read from the bridge's simulated bus,
which counts the frames sent after each motor's first stop frame."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from remote.test_procs import (
    REQUEST_ID,
    SPEED,
    STOP,
    Proc,
    bridge,
    frames_of,
    report_when,
    spawn,
    speeds,
)

__all__ = ["spawn"]  # (the fixture, found here by pytest)

MOTORS_HELD = range(1, 5)  # the motors the client holds and pipelines requests to
DEPTH = 8  # requests to each of them the client keeps in flight
BITRATE = 125_000  # the simulated CAN bus's: a motor answers more slowly than the requests come
VALID_S = 0.3  # the stale case's set-points (a client's loop starved by its own pipeline: not stale)
QUEUED = 16  # requests pending on the bridge's Bus once they queue there (8 at most in flight)


def after_stop(report: dict[str, Any], byte0: int = SPEED) -> dict[int, int]:
    """``{motor id: frames with first byte byte0 sent after that motor's first stop frame}``."""
    return {aid - REQUEST_ID: n for aid, b0, n in report["after_stop"] if b0 == byte0}


def stop_sent(report: dict[str, Any]) -> bool:
    """Whether motors 1-4 were each sent a stop frame (what follows it is checked after)."""
    frames = frames_of(report)
    return all(STOP in frames.get(m, {}) for m in MOTORS_HELD)


def pipelining(spawn: Callable[..., Proc], valid_for_s: float) -> tuple[Proc, Proc]:
    """A bridge, and a client that holds motors 1-4 at 45 dps (set-points valid ``valid_for_s``)
    and keeps DEPTH speed requests of 778 dps in flight to each, once they queue on the Bus."""
    server, port = bridge(spawn, "--bitrate", str(BITRATE))
    client = spawn("client", port)
    client.ok("connect", valid_for_s=valid_for_s)
    held = list(MOTORS_HELD)
    client.ok("hold", motors=held, command="SpeedControl", fields={"speed_dps": 45.0}, hz=200.0)
    report_when(server, lambda r: speeds(r, held) == dict.fromkeys(held, 45.0), 10, "motors 1-4 at 45 dps")
    client.ok("pipeline", motors=held, command="SpeedControl", fields={"speed_dps": 778.0}, depth=DEPTH)
    report_when(server, lambda r: r["pending"] > QUEUED, 10, "the client's requests queued on the Bus")
    return server, client


def test_a_killed_pipelining_commander_s_queued_requests_do_not_follow_its_stop(
    spawn: Callable[..., Proc],
) -> None:
    # set-points valid for 5 s: only the client's vanished token stops the motors
    server, client = pipelining(spawn, valid_for_s=5.0)
    server.ok("reset")
    killed_ns = time.time_ns()
    client.kill()
    report_when(server, stop_sent, 5, "stop frames to motors 1-4 after the client was killed")
    time.sleep(0.5)  # (what was queued had time to go out, if it still could)
    done = server.ok("report")
    frames = frames_of(done)
    first_ms = [(frames[m][STOP][1] - killed_ns) / 1e6 for m in MOTORS_HELD]
    late = after_stop(done)
    decided_ms = [(when - killed_ns) / 1e6 for when, _, _, _ in done["stop_log"]]
    print(
        f"kill -> stop decided {min(decided_ms):.1f} ms, stop frames {min(first_ms):.1f}.."
        f"{max(first_ms):.1f} ms; speed frames after the stop {sum(late.values())} ({late}); withdrawn "
        f"{done['bridge'].get('withdrawn')}; refused after the kill (its queries still in the bridge's "
        f"intake) {done['bridge']['refused']}"
    )
    assert late == {}, f"{sum(late.values())} speed frames of the dead client after its stop: {late}"
    assert max(first_ms) <= 250, first_ms
    assert {why for _, _, _, why in done["stop_log"]} == {"client left"}, done["stop_log"]
    assert all(done["controls"][str(m)]["kind"] == "PositionControl" for m in MOTORS_HELD), done["controls"]
    assert done["owners"] == {} and done["clients"] == 0
    assert done["bridge"]["withdrawn"] > 0, done["bridge"]  # (there was something to withdraw)
    assert done["pending"] == 0, done["pending"]


def test_a_pipelining_commander_whose_set_points_go_stale_does_not_take_its_motors_back(
    spawn: Callable[..., Proc],
) -> None:
    """The client's set-point loop stops (its process lives, and its requests keep coming): the
    bridge stops its motors after ``valid_for_s + stop_after_s``; nothing of its requests reaches a
    motor after that stop, and they are answered PermissionError; a fresh set-point takes a motor
    back."""
    server, client = pipelining(spawn, valid_for_s=VALID_S)
    server.ok("reset")
    released_ns = time.time_ns()
    client.ok("release")  # its last batch expires VALID_S after it was sent, the stop 0.05 s later
    report_when(server, stop_sent, 5, "stop frames to motors 1-4 after the set-points went stale")
    time.sleep(0.5)  # (the pipeline keeps sending meanwhile)
    done = server.ok("report")
    counts = client.ok("pipelined", stop=True)
    frames = frames_of(done)
    first_ms = [(frames[m][STOP][1] - released_ns) / 1e6 for m in MOTORS_HELD]
    late = after_stop(done)
    decided_ms = [(when - released_ns) / 1e6 for when, _, _, _ in done["stop_log"]]
    print(f"set-points released -> stop decided {min(decided_ms):.1f}..{max(decided_ms):.1f} ms")
    print(
        f"set-points released -> stop frames {min(first_ms):.1f}..{max(first_ms):.1f} ms; speed frames "
        f"after the stop {sum(late.values())} ({late}); withdrawn {done['bridge'].get('withdrawn')}; "
        f"client's pipeline {counts}"
    )
    assert late == {}, f"{sum(late.values())} speed frames of the stale client after its stop: {late}"
    # the stop leaves within 250 ms of the bridge's decision, which came valid_for_s + stop_after_s
    # after the client's last batch (bounded loosely: the client's loop shares a loaded host)
    assert max(first_ms) - min(decided_ms) <= 250, (decided_ms, first_ms)
    assert min(decided_ms) <= VALID_S * 1e3 + 50 + 1000, decided_ms
    assert {why for _, _, _, why in done["stop_log"]} == {"set-points stale for 50 ms"}, done["stop_log"]
    assert sorted(m for _, _, m, _ in done["stop_log"]) == list(MOTORS_HELD), done["stop_log"]
    assert all(done["controls"][str(m)]["kind"] == "PositionControl" for m in MOTORS_HELD), done["controls"]
    assert done["owners"] == {}, done["owners"]
    # the client was told, clearly: its queued requests were withdrawn, the later ones refused
    assert counts["errors"].get("PermissionError", 0) > 0, counts
    assert "stale" in counts["messages"]["PermissionError"], counts  # (withdrawn, or refused)
    # a fresh set-point takes a motor back (the rule refuses only requests)
    client.ok("cycle", motors=[2], command="SpeedControl", fields={"speed_dps": 30.0}, valid_for_s=5.0)
    back = report_when(server, lambda r: speeds(r, [2]) == {2: 30.0}, 5, "motor 2 at the fresh set-point")
    assert back["owners"].keys() == {"2"}, back["owners"]

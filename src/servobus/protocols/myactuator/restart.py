"""What proves that a MyActuator motor restarted: its system run time (0xB1) went back.

0xB1 counts milliseconds since power-up (§4.31). A motor that kept running since the host first
saw it (or since it last came back from a restart) reads at least the time since then, and at least
its last reading plus the time since that one; one that reads less was powered up in between (or
is another motor: what it was told is lost either way).
Clocks: the motor's and the host's may differ by :data:`DRIFT`, and a reading is late by its
reply's latency and rounded to the millisecond (:data:`SLACK_S`). A restart within about
``SLACK_S`` of the host first seeing the motor cannot be told from its power-up. The count wraps
after 49.7 days: a reading that may have wrapped since the last one proves nothing, and before the
first reading (the first return) a motor up for 49.7 days would read as restarted.
"""

from __future__ import annotations

from servobus.protocols._restart import RestartEvidence, Sightings
from servobus.protocols.myactuator.commands import ReadRunTime
from servobus.protocols.myactuator.replies import RunTimeReply

__all__ = ["DRIFT", "RESTART", "SLACK_S"]

#: the motor's clock against the host's: a crystal is better than 0.01 %; 1 % also covers a loaded
#: host's stamps
DRIFT = 0.01
#: a reading's latency (request to reply, the host's loop) and its 1 ms resolution
SLACK_S = 0.02
_WRAP_S = 2**32 / 1000  # 0xB1 is a uint32 of ms: it wraps after 49.7 days


def _judge(before: Sightings, after: Sightings, known_since_s: float) -> str | None:
    now = after.get(RunTimeReply)
    if now is None:
        return None
    run_time_ms: int = now.reply.run_time_ms  # type: ignore[attr-defined]
    least_s = (now.at - known_since_s) * (1 - DRIFT)
    earlier = before.get(RunTimeReply)
    if earlier is not None and earlier.at >= known_since_s:
        last_s = earlier.reply.run_time_ms / 1000  # type: ignore[attr-defined]
        if last_s + (now.at - earlier.at) * (1 + DRIFT) + SLACK_S >= _WRAP_S:
            return None  # it may have wrapped meanwhile: no proof either way
        least_s = max(least_s, last_s + (now.at - earlier.at) * (1 - DRIFT))
    least_s -= SLACK_S
    if least_s >= _WRAP_S or run_time_ms / 1000 >= least_s:
        return None
    return (
        f"its run time (0xB1) went back: {run_time_ms} ms, where a motor running on would read "
        f"at least {least_s * 1000:.0f} ms"
    )


# Nothing to remember from the traffic: the last reading is the probe's, on the last return.
RESTART = RestartEvidence(probes=(ReadRunTime,), remembers=frozenset(), judge=_judge)

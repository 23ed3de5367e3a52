"""What proves that a hollow motor restarted: its position folded to one turn.

A hollow motor has no run-time read, and every reply carries its position. At power-up it loses its
multi-turn count and reports the single-turn angle from the console zero, in [-180°, 180°) (spec
§13; the simulator's reboot). A motor last seen outside that turn whose first reply on its return is
inside it, half a turn or more away, was powered up in between (a motor only silent keeps its count).
A motor that works within one turn gives no such evidence.
"""

from __future__ import annotations

from servobus.protocols._restart import RestartEvidence, Seen, Sightings

__all__ = ["RESTART"]


def _latest(seen: Sightings) -> Seen | None:
    return max(seen.values(), key=lambda s: s.at, default=None)


def _judge(before: Sightings, after: Sightings, known_since_s: float) -> str | None:
    was, now = _latest(before), _latest(after)
    if was is None or now is None:
        return None
    a: float = was.reply.position_deg  # type: ignore[attr-defined]
    b: float = now.reply.position_deg  # type: ignore[attr-defined]
    if abs(a) >= 180.0 and -180.0 <= b < 180.0 and abs(b - a) >= 180.0:
        return f"its position folded to one turn: {a:.1f}° -> {b:.1f}°"
    return None


# No probe, nothing to remember: its last reply before the silence and the one that brought it back
# carry its position.
RESTART = RestartEvidence(probes=(), remembers=frozenset(), judge=_judge)

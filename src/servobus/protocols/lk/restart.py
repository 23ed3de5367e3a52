"""What proves that an LK motor restarted: its multi-turn angle (0x92) folded to one turn.

An LK motor has no run-time read. At power-up it loses its turn count: 0x92 reads the encoder's angle
within one turn, [0°, 360°) (spec §4.24, §4.5). A motor last read outside that turn that now reads
inside it, half a turn or more away, was powered up in between (a motor only silent keeps its count).
The evidence is as fresh as the last 0x92 the host saw while the motor answered: a loop that reads
the angle has it; a motor last read within its first turn gives none.
"""

from __future__ import annotations

from servobus.protocols._restart import RestartEvidence, Sightings
from servobus.protocols.lk.commands import ReadMultiTurnAngle
from servobus.protocols.lk.replies_position import MultiTurnAngleReply

__all__ = ["RESTART"]


def _judge(before: Sightings, after: Sightings, known_since_s: float) -> str | None:
    was, now = before.get(MultiTurnAngleReply), after.get(MultiTurnAngleReply)
    if was is None or now is None:
        return None
    a: float = was.reply.angle_deg  # type: ignore[attr-defined]
    b: float = now.reply.angle_deg  # type: ignore[attr-defined]
    if abs(a) >= 360.0 and 0.0 <= b < 360.0 and abs(b - a) >= 180.0:
        return f"its multi-turn angle (0x92) folded to one turn: {a:.2f}° -> {b:.2f}°"
    return None


RESTART = RestartEvidence(
    probes=(ReadMultiTurnAngle,), remembers=frozenset((MultiTurnAngleReply,)), judge=_judge
)

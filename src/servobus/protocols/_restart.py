"""How a family proves that a motor restarted: :class:`RestartEvidence`, declared once per family.

A motor whose supply sagged comes back in its power-on state (set-points lost, the output off, the
turn count folded to one turn). To the host it was only silent for a while, like a motor whose cable
was pulled and put back, which keeps what it held. When a motor comes back online the Bus reads the
family's ``probes`` and hands :meth:`RestartEvidence.judge` what it saw before the silence and what
it sees now (servobus.bus.restarts); the family says whether that proves a restart.

Each family declares its evidence as its bound codec's ``RESTART`` (None: a family that has none);
nothing else names a family. Sans-IO: replies and clock values in, a verdict out.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from servobus.protocols._message import Command, Reply

__all__ = ["RestartEvidence", "Seen", "Sightings"]


@dataclass(frozen=True, slots=True)
class Seen:
    """A reply of a motor and when it came (the loop's clock)."""

    reply: Reply
    at: float


#: the last reply of each remembered type, by type
Sightings = Mapping[type[Reply], Seen]


@dataclass(frozen=True, slots=True)
class RestartEvidence:
    """What proves a restart of a family's motor.

    Attributes:
        probes: reads (command classes without fields) the Bus sends when the motor comes back
            online; their replies are in ``after``. None where the reply that brought it back says
            enough.
        remembers: reply types whose last one the Bus's intake remembers while the motor answers,
            for evidence that neither the motor's last reply before its silence nor the probes'
            earlier replies give (each costs a look-up per reply: keep it empty where they do).
        judge: ``judge(before, after, known_since_s)``: the evidence in words when ``before`` (when
            the motor went silent: its last reply, the probes' last replies, what was remembered)
            and ``after`` (the reply that brought it back, the probes' replies) prove a restart,
            else None. ``known_since_s``: since when
            the host has known the motor to be running without a restart (when it was first seen,
            or came back from its last reported restart).
    """

    probes: tuple[Callable[[], Command], ...]
    remembers: frozenset[type[Reply]]
    judge: Callable[[Sightings, Sightings, float], str | None]

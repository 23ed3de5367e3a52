"""Episodes of the host's own CAN controller: a full send queue, and bus-off (sans-IO, seeded).

What a host's adapter does to its sends, over time, as python-can reports it:

* **queue_full**: the controller's transmit queue is full; a send is refused with ENOBUFS
  (``can.CanOperationError``, errno ``ENOBUFS``), each with probability ``refuse`` (a seeded draw:
  a queue that drains at the wire's rate takes a frame now and then), for ``duration_s``.
* **bus_off**: the controller went bus-off: a BUS_OFF error frame (SocketCAN's ``CAN_ERR_BUSOFF``,
  0x040 in the identifier) at the start, every send refused with ENETDOWN and nothing received
  while it lasts, then a RESTARTED error frame (``CAN_ERR_RESTARTED``, 0x100) when the controller
  restarts (SocketCAN's ``restart-ms``), and sends work again.

:class:`ControllerEpisodes` answers, for a time given by its caller, whether a send is refused and
which error frames are due; the in-process bus (:class:`~servobus.transports.sim.SimTransport`,
``episodes=``) and the python-can wrapper (:class:`~servobus.sim.canfaults.FaultyCanBus`) apply it,
each on its own clock. The same episodes and seed give the same refusals for the same sends.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

__all__ = ["BUS_OFF", "RESTARTED", "ControllerEpisodes", "Episode"]

#: SocketCAN error classes (``linux/can/error.h``), carried in an error frame's identifier
BUS_OFF = 0x040
RESTARTED = 0x100

Kind = Literal["queue_full", "bus_off"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Episode:
    """One episode: ``kind`` from ``start_s`` for ``duration_s`` (on the applier's clock);
    ``refuse``: the share of sends refused (queue_full only; bus-off refuses every one)."""

    kind: Kind
    start_s: float
    duration_s: float
    refuse: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in ("queue_full", "bus_off"):
            raise ValueError(f"kind={self.kind!r} must be 'queue_full' or 'bus_off'")
        if self.duration_s <= 0:
            raise ValueError(f"duration_s={self.duration_s} must be positive")
        if not 0.0 <= self.refuse <= 1.0:
            raise ValueError(f"refuse={self.refuse} is outside [0.0, 1.0]")

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def covers(self, at_s: float) -> bool:
        return self.start_s <= at_s < self.end_s


class ControllerEpisodes:
    """The episodes of one host controller, and what it has reported of them.

    Args:
        episodes: the episodes, in any order (they may not overlap).
        seed: the seed of the queue_full draws.

    Attributes:
        counts: sends refused (``"queue_full"``, ``"bus_off"``) and error frames given out
            (``"BUS_OFF"``, ``"RESTARTED"``).

    Raises:
        ValueError: episodes that overlap.
    """

    def __init__(self, episodes: Iterable[Episode], *, seed: int = 0) -> None:
        self.episodes = sorted(episodes, key=lambda e: e.start_s)
        for before, after in zip(self.episodes, self.episodes[1:], strict=False):
            if after.start_s < before.end_s:
                raise ValueError(f"episodes {before} and {after} overlap")
        self.seed = seed
        self.counts: Counter[str] = Counter()
        self._random = random.Random(seed)
        # (time, error class) of every error frame, in time order; _given of them were handed out
        marks = [(e.start_s, BUS_OFF) for e in self.episodes if e.kind == "bus_off"]
        marks += [(e.end_s, RESTARTED) for e in self.episodes if e.kind == "bus_off"]
        self._marks = sorted(marks)
        self._given = 0

    def _at(self, at_s: float) -> Episode | None:
        for episode in self.episodes:
            if episode.covers(at_s):
                return episode
        return None

    def refusal(self, at_s: float) -> Kind | None:
        """Whether a send at ``at_s`` is refused, and why (None: it goes through)."""
        episode = self._at(at_s)
        if episode is None:
            return None
        if episode.kind == "queue_full" and episode.refuse < 1.0 and self._random.random() >= episode.refuse:
            return None
        self.counts[episode.kind] += 1
        return episode.kind

    def receiving(self, at_s: float) -> bool:
        """False while bus-off: a controller that is off the bus receives nothing."""
        episode = self._at(at_s)
        return episode is None or episode.kind != "bus_off"

    def error_frames(self, until_s: float) -> list[tuple[float, int]]:
        """The error frames (time, SocketCAN error class) due by ``until_s`` not handed out yet."""
        due: list[tuple[float, int]] = []
        marks = self._marks
        while self._given < len(marks) and marks[self._given][0] <= until_s:
            at, classes = marks[self._given]
            due.append((at, classes))
            self.counts["BUS_OFF" if classes == BUS_OFF else "RESTARTED"] += 1
            self._given += 1
        return due

    def next_error_frame_s(self) -> float | None:
        """When the next error frame is due (None: no more)."""
        return self._marks[self._given][0] if self._given < len(self._marks) else None

"""Seeded, reproducible faults on the path between host and simulated devices.

A :class:`FaultInjector` sits on one direction of a link and decides, for each frame (CAN) or
byte string (serial), when and how it arrives: dropped, delayed, duplicated, corrupted or
reordered. The same plan and seed give the same decisions for the same traffic, so a failing
reliability test replays exactly.

Corruption depends on the medium, as on real wires: a serial frame gets one bit flipped (its CRC
then fails at the receiver, which must count it); a CAN frame with a flipped bit is caught by
every controller's CRC check, answered with an error frame and retransmitted by the sender, so
on CAN "corrupt" arrives late by one more frame time (``can_retransmit_s``), never altered.

Device faults (reboot, unresponsive motor, error flags) and adapter unplug belong to the device
models and attachments; this module is only the link.
"""

from __future__ import annotations

import random
from collections import Counter
from dataclasses import dataclass

from servobus.frame import Frame

__all__ = ["FaultInjector", "FaultPlan"]

Item = Frame | bytes


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultPlan:
    """Probability of each fault per item (0..1), and the delay and retransmission times.

    Faults are drawn in this order and at most one applies to an item: drop, corrupt, duplicate,
    reorder, delay.
    """

    drop: float = 0.0
    corrupt: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    delay: float = 0.0
    delay_s: tuple[float, float] = (0.001, 0.010)
    can_retransmit_s: float = 0.000135  # an error frame plus the retransmitted 8-byte frame at 1 Mbit/s

    def __post_init__(self) -> None:
        for name in ("drop", "corrupt", "duplicate", "reorder", "delay"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}={value!r} is outside [0.0, 1.0]")
        if self.drop + self.corrupt + self.duplicate + self.reorder + self.delay > 1.0:
            raise ValueError("the fault probabilities add up to more than 1")
        lo, hi = self.delay_s
        if not 0.0 <= lo <= hi:
            raise ValueError(f"delay_s={self.delay_s!r} must be 0 <= low <= high")


class FaultInjector:
    """Applies a :class:`FaultPlan` to a stream of items with its own seeded generator.

    Args:
        plan: what to inject.
        seed: the seed; the same seed and traffic give the same faults.

    Attributes:
        counts: how many items met each fault kind (``"drop"``, ``"corrupt"``, … and ``"pass"``).
    """

    def __init__(self, plan: FaultPlan, seed: int = 0) -> None:
        self.plan = plan
        self.seed = seed
        self.counts: Counter[str] = Counter()
        self._random = random.Random(seed)
        self._held: Item | None = None  # an item waiting to be delivered after the next one

    def apply(self, item: Item, now_s: float) -> list[tuple[float, Item]]:
        """Decide the fate of ``item`` sent at ``now_s``: the (arrival time, item) pairs to deliver.

        A reordered item is held and delivered right after the next item; :meth:`flush` releases
        it if no other item comes.
        """
        kind = self._draw()
        self.counts[kind] += 1
        out: list[tuple[float, Item]]
        if kind == "drop":
            out = []
        elif kind == "corrupt":
            out = [self._corrupt(item, now_s)]
        elif kind == "duplicate":
            out = [(now_s, item), (now_s, item)]
        elif kind == "delay":
            out = [(now_s + self._random.uniform(*self.plan.delay_s), item)]
        elif kind == "reorder" and self._held is None:
            self._held = item
            return []
        else:
            out = [(now_s, item)]
        if self._held is not None and kind != "reorder":
            out.append((now_s, self._held))
            self._held = None
        return out

    def flush(self, now_s: float) -> list[tuple[float, Item]]:
        """Release a held (reordered) item: the link went quiet."""
        held, self._held = self._held, None
        return [(now_s, held)] if held is not None else []

    def _draw(self) -> str:
        plan = self.plan
        x = self._random.random()
        for kind in ("drop", "corrupt", "duplicate", "reorder", "delay"):
            p = getattr(plan, kind)
            if x < p:
                return kind
            x -= p
        return "pass"

    def _corrupt(self, item: Item, now_s: float) -> tuple[float, Item]:
        if isinstance(item, Frame):
            return now_s + self.plan.can_retransmit_s, item
        if not item:
            return now_s, item
        damaged = bytearray(item)
        bit = self._random.randrange(8 * len(damaged))
        damaged[bit // 8] ^= 1 << (bit % 8)
        return now_s, bytes(damaged)

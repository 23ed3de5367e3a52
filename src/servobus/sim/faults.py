"""Seeded, reproducible faults on the path between host and simulated devices.

A :class:`FaultInjector` sits on one direction of a link and decides, for each frame (CAN) or
byte string (serial), when and how it arrives: dropped, delayed, duplicated, corrupted or
reordered. The same plan and seed give the same decisions for the same traffic, so a failing
reliability test replays exactly.

Corruption depends on the medium, as on real wires: a serial frame gets one bit flipped (its CRC
then fails at the receiver, which must count it); a CAN frame with a flipped bit is caught by
every controller's CRC check, answered with an error frame and retransmitted by the sender, so
on CAN "corrupt" arrives late by one more frame time (``can_retransmit_s``), never altered.

Latency (``latency_s``) is no fault of one item but a property of the path: every item arrives a
uniform draw in ``latency_s`` late, and never before the item sent ahead of it (FIFO), as through a
USB-CAN adapter polled every millisecond or a busy host: replies stay in order, each late, and a
late one holds back the next. The faults apply on top of that arrival time.

Device faults (reboot, unresponsive motor, error flags) and adapter unplug belong to the device
models and attachments; this module is only the link.
"""

from __future__ import annotations

import math
import random
from collections import Counter
from dataclasses import dataclass

from servobus.frame import Frame

__all__ = ["FaultInjector", "FaultPlan"]

Item = Frame | bytes


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultPlan:
    """Probability of each fault per item (0..1), the delay and retransmission times, and the latency.

    Faults are drawn in this order and at most one applies to an item: drop, corrupt, duplicate,
    reorder, delay.

    ``latency_s = (lo, hi)`` gives every item a latency drawn uniformly in [lo, hi] seconds; an item
    never arrives before the item the injector was given ahead of it, however small its own draw
    (FIFO: each arrives at ``max(sent + latency, previous arrival)``). A fault then applies from that
    time: a delay or a CAN retransmission adds to it, a duplicate arrives twice at it, a reordered
    item arrives right after the next item's (so those faults may still put an item behind later ones,
    as they do without latency; the next item waits only for the previous one's latency, not for its
    fault). The default ``(0.0, 0.0)`` is off: items arrive when sent, the generator is not drawn for
    latency, and a seed gives the decisions it gave before latency existed.

    ``latency_order`` says what stays in order: ``"link"``, every item (one queue, as in an
    adapter); ``"sender"``, the frames of each CAN identifier (each motor's replies in order, the
    motors' among each other not: with independent draws a single queue holds every item back to
    the slowest recent draw, so ``"sender"`` is the one whose latency is the drawn one).
    """

    drop: float = 0.0
    corrupt: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    delay: float = 0.0
    delay_s: tuple[float, float] = (0.001, 0.010)
    can_retransmit_s: float = 0.000135  # an error frame plus the retransmitted 8-byte frame at 1 Mbit/s
    latency_s: tuple[float, float] = (0.0, 0.0)
    latency_order: str = "link"

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
        if self.latency_order not in ("link", "sender"):
            raise ValueError(f"latency_order={self.latency_order!r} must be 'link' or 'sender'")
        lo, hi = _pair("latency_s", self.latency_s)
        if not (0.0 <= lo <= hi and math.isfinite(hi)):
            raise ValueError(f"latency_s={self.latency_s!r} must be 0 <= low <= high (finite seconds)")

    @property
    def has_latency(self) -> bool:
        """True when items get a latency (``latency_s``'s high end is above 0)."""
        return self.latency_s[1] > 0.0


def _pair(name: str, value: object) -> tuple[float, float]:
    """``value`` as a (low, high) pair of real numbers, or ValueError naming ``name``."""
    if not isinstance(value, tuple) or len(value) != 2:
        raise ValueError(f"{name}={value!r} is not a (low, high) pair of seconds")
    lo, hi = value
    for x in (lo, hi):
        if isinstance(x, bool) or not isinstance(x, int | float):
            raise ValueError(f"{name}={value!r} is not a (low, high) pair of seconds")
    return float(lo), float(hi)


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
        self._held_s = 0.0  # the held item's own (latency'd) arrival time
        # the latency'd arrival of the last item that arrives (FIFO), of the link or by sender
        self._last_s: dict[int | None, float] = {}

    def apply(self, item: Item, now_s: float) -> list[tuple[float, Item]]:
        """Decide the fate of ``item`` sent at ``now_s``: the (arrival time, item) pairs to deliver.

        A reordered item is held and delivered right after the next item; :meth:`flush` releases
        it if no other item comes.
        """
        kind = self._draw()
        self.counts[kind] += 1
        at = self._arrival(now_s, kind, item)
        out: list[tuple[float, Item]]
        if kind == "drop":
            out = []
        elif kind == "corrupt":
            out = [self._corrupt(item, at)]
        elif kind == "duplicate":
            out = [(at, item), (at, item)]
        elif kind == "delay":
            out = [(at + self._random.uniform(*self.plan.delay_s), item)]
        elif kind == "reorder" and self._held is None:
            self._held, self._held_s = item, at
            return []
        else:
            out = [(at, item)]
        if self._held is not None and kind != "reorder":
            out.append((at, self._held))
            self._held = None
        return out

    def flush(self, now_s: float) -> list[tuple[float, Item]]:
        """Release a held (reordered) item: the link went quiet (not before its own latency)."""
        held, self._held = self._held, None
        if held is None:
            return []
        return [(max(now_s, self._held_s) if self.plan.has_latency else now_s, held)]

    def _arrival(self, now_s: float, kind: str, item: Item) -> float:
        """When an item sent at ``now_s`` comes out of the latency: ``now_s`` without latency, else
        ``max(now_s + uniform(latency_s), the previous item's)``. A dropped item holds nothing back."""
        plan = self.plan
        if not plan.has_latency:
            return now_s
        at = now_s + self._random.uniform(*plan.latency_s)
        queue = item.arbitration_id if plan.latency_order == "sender" and isinstance(item, Frame) else None
        last = self._last_s.get(queue, -math.inf)
        if at < last:
            at = last
        if kind != "drop":
            self._last_s[queue] = at
        return at

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

"""The listening devices' deadlines on a :class:`~servobus.sim.network.SimCanNetwork`, in one heap.

A device's :meth:`~servobus.sim.device.Device.next_deadline_s` is asked again only after the network
has called it or it said it changed, so the network keeps the last answer of each device here: one
current entry per device, and a heap in which replaced entries stay until they come to the top and
are skipped (cheaper than removing them).
"""

from __future__ import annotations

import heapq
import itertools

__all__ = ["DeadlineHeap"]


class DeadlineHeap:
    """Device name -> its next deadline (seconds, virtual time), earliest first."""

    __slots__ = ("_current", "_heap", "_seq")

    def __init__(self) -> None:
        self._current: dict[str, tuple[float, int]] = {}  # device -> (deadline, seq)
        self._heap: list[tuple[float, int, str]] = []  # stale entries are skipped
        self._seq = itertools.count()

    def set(self, name: str, deadline_s: float | None) -> None:
        """``name``'s deadline is now ``deadline_s`` (None: it has none)."""
        current = self._current.get(name)
        if deadline_s is None:
            if current is not None:
                del self._current[name]
        elif current is None or current[0] != deadline_s:
            seq = next(self._seq)
            self._current[name] = (deadline_s, seq)
            heapq.heappush(self._heap, (deadline_s, seq, name))

    def discard(self, name: str) -> None:
        """Forget ``name`` (off the network)."""
        self._current.pop(name, None)

    def earliest(self) -> float | None:
        """The earliest deadline (None: no device has one)."""
        heap, current = self._heap, self._current
        while heap:
            deadline, seq, name = heap[0]
            entry = current.get(name)
            if entry is not None and entry[1] == seq:
                return deadline
            heapq.heappop(heap)
        return None

    def pop_due(self, t: float) -> list[str]:
        """The devices whose deadline has come by ``t``, earliest first; each is forgotten until its
        deadline is set again (the network asks it after calling it)."""
        due: list[str] = []
        heap, current = self._heap, self._current
        while heap and heap[0][0] <= t:
            _, seq, name = heapq.heappop(heap)
            entry = current.get(name)
            if entry is not None and entry[1] == seq:
                del current[name]
                due.append(name)
        return due

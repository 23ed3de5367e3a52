"""The listening devices' deadline heap of the reference network (servobus.sim.deadlines)."""

from __future__ import annotations

from servobus.sim.deadlines import DeadlineHeap


def test_the_earliest_deadline_and_the_due_devices_come_in_time_order() -> None:
    heap = DeadlineHeap()
    heap.set("b", 0.3)
    heap.set("a", 0.1)
    heap.set("c", 0.2)
    assert heap.earliest() == 0.1
    assert heap.pop_due(0.25) == ["a", "c"]
    assert heap.earliest() == 0.3
    assert heap.pop_due(0.25) == []


def test_a_new_deadline_replaces_the_old_one_and_none_or_discard_drops_it() -> None:
    heap = DeadlineHeap()
    heap.set("a", 0.1)
    heap.set("a", 0.5)  # the stale 0.1 entry stays in the heap and is skipped
    heap.set("b", 0.2)
    heap.set("b", None)
    assert heap.earliest() == 0.5
    assert heap.pop_due(1.0) == ["a"]
    heap.set("c", 0.4)
    heap.discard("c")
    assert heap.earliest() is None
    assert heap.pop_due(1.0) == []


def test_a_due_device_is_forgotten_until_its_deadline_is_set_again() -> None:
    heap = DeadlineHeap()
    heap.set("a", 0.1)
    assert heap.pop_due(0.1) == ["a"]
    heap.set("a", 0.1)  # asked again after its poll: the same time is a new entry
    assert heap.earliest() == 0.1
    assert heap.pop_due(0.1) == ["a"]


def test_equal_deadlines_come_in_the_order_they_were_set() -> None:
    heap = DeadlineHeap()
    for name in ("z", "y", "x"):
        heap.set(name, 0.2)
    assert heap.pop_due(0.2) == ["z", "y", "x"]

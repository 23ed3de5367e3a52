"""Arbitration and wire time on the simulated CAN bus (servobus.sim.canbus)."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel, arbitration_priority
from servobus.timing import CLASSIC_8_BYTE_STANDARD_BITS, frame_time_s


def _frame(ident: int, *, extended: bool = False) -> Frame:
    return Frame(arbitration_id=ident, data=bytes(8), is_extended_id=extended)


def test_contending_frames_leave_in_identifier_order() -> None:
    bus = CanBusModel()
    for motor_id in (7, 3, 32, 1, 12):
        bus.submit(_frame(0x240 + motor_id), 0.0, source=motor_id)
    done = bus.advance(1.0)
    assert [t.frame.arbitration_id - 0x240 for t in done] == [1, 3, 7, 12, 32]
    # back to back: each starts when the previous one ends
    assert done[0].start_s == 0.0
    assert all(b.start_s == a.end_s for a, b in itertools.pairwise(done))


def test_a_node_sends_its_own_queue_in_order() -> None:
    bus = CanBusModel()
    for motor_id in (5, 1, 3):
        bus.submit(_frame(0x140 + motor_id), 0.0, source="host")
    assert [t.frame.arbitration_id for t in bus.advance(1.0)] == [0x145, 0x141, 0x143]


def test_a_frame_ready_later_waits_but_wins_the_next_arbitration() -> None:
    bus = CanBusModel()
    bus.submit(_frame(0x300), 0.0, source="a")
    bus.submit(_frame(0x200), 0.0, source="b")
    first = frame_time_s(_frame(0x200))
    bus.submit(_frame(0x100), first / 2, source="c")  # arrives while 0x200 is on the wire
    order = [t.frame.arbitration_id for t in bus.advance(1.0)]
    assert order == [0x200, 0x100, 0x300]


def test_started_transmissions_are_decided_and_later_ones_stay_open() -> None:
    bus = CanBusModel()
    bus.submit(_frame(0x300), 0.0, source="a")
    end = bus.next_event_s()
    assert end == pytest.approx(frame_time_s(_frame(0x300)))
    assert bus.advance(end / 2) == []  # on the wire, not finished
    bus.submit(_frame(0x001), end / 2, source="b")  # cannot pre-empt the frame on the wire
    assert [t.frame.arbitration_id for t in bus.advance(1.0)] == [0x300, 0x001]
    bus.submit(_frame(0x400), 2.0, source="a")
    assert bus.advance(1.5) == []  # not ready yet: a lower id submitted for 2.0 may still join
    bus.submit(_frame(0x002), 2.0, source="b")
    assert [t.frame.arbitration_id for t in bus.advance(3.0)] == [0x002, 0x400]
    with pytest.raises(ValueError, match="time runs forward"):
        bus.submit(_frame(1), 2.5)


def test_standard_beats_extended_at_the_same_base_id() -> None:
    assert arbitration_priority(_frame(0x123)) < arbitration_priority(_frame(0x123 << 18, extended=True))
    assert arbitration_priority(_frame(0x122 << 18 | 0x3FFFF, extended=True)) < arbitration_priority(
        _frame(0x123)
    )


@given(st.lists(st.binary(min_size=8, max_size=8), min_size=64, max_size=64))
def test_thirty_two_request_reply_pairs_occupy_the_bit_count_bound(payloads: list[bytes]) -> None:
    bus = CanBusModel(bitrate=1_000_000)
    for i, data in enumerate(payloads[:32]):
        bus.submit(Frame(arbitration_id=0x141 + i, data=data), 0.0, source="host")
    for i, data in enumerate(payloads[32:]):
        bus.submit(Frame(arbitration_id=0x241 + i, data=data), 0.0, source=i)
    done = bus.advance(1.0)
    assert len(done) == 64 and bus.frames == 64
    lo, hi = CLASSIC_8_BYTE_STANDARD_BITS
    assert 64 * lo / 1e6 <= bus.busy_s <= 64 * hi / 1e6
    assert done[-1].end_s == pytest.approx(bus.busy_s)  # no idle gap when everything is ready at 0

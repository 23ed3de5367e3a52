"""What the scheduler's split (issue 38) must not change, found by review: a request with two
deadlines in the heap times out once, a broadcast's expected request was not handed over by this
Bus, and the pacing the Scheduler reports is the table's."""

from __future__ import annotations

import pytest

from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.scheduler import RequestState, Scheduler


def _one() -> tuple[Scheduler, object]:
    codec = get_family("myactuator").bind(1)
    return Scheduler([codec], report_within_s=0.25), codec


def test_a_request_whose_deadline_was_set_twice_times_out_once() -> None:
    """The audit gives an unreported request a provisional deadline (0.75); its late send report
    times it again to the same instant: two heap entries, one timeout, no error."""
    scheduler, codec = _one()
    request = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.5)  # type: ignore[arg-type]
    scheduler.submit(request, 0.0)
    assert scheduler.poll(0.0)[0] == [request]
    assert scheduler.expire(0.25) == [] and request.deadline == 0.75
    scheduler.sent(request, 0.25)
    assert request.deadline == 0.75
    assert scheduler.expire(0.8) == [request]
    assert request.state is RequestState.TIMED_OUT
    assert scheduler.counts["timeouts"] == 1


def test_a_broadcast_s_expected_request_was_not_handed_over_by_the_bus() -> None:
    scheduler, codec = _one()
    request = scheduler.request(codec, ma.ReadStatus2())  # type: ignore[arg-type]
    scheduler.expect(request, 1.25)
    assert request.state is RequestState.SENT and request.sent_at == 1.25
    assert request.handed_at is None


def test_the_pacing_the_scheduler_reports_is_the_table_s_and_read_only() -> None:
    scheduler = Scheduler(max_in_flight=8, one_at_a_time=True)
    assert (scheduler.max_in_flight, scheduler.one_at_a_time) == (1, True)
    with pytest.raises(AttributeError):
        scheduler.max_in_flight = 4  # type: ignore[misc]

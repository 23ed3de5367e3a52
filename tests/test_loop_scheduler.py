"""The scheduler's rule for pipelined requests (servobus.scheduler: ``Request.pipelined``), sans-IO:
several with one key to one motor in flight at once, replies matched in order (the oldest first),
and what a lost, a late and a duplicated reply do to them."""

from __future__ import annotations

import struct

from servobus.frame import Frame
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.scheduler import Request, RequestState, Scheduler, Traffic

CODEC = get_family("myactuator").bind(1)
S = RequestState


def _scheduler() -> Scheduler:
    return Scheduler([CODEC], min_reply_s=0.0002, late_window_s=1.0)


def _send(scheduler: Scheduler, speed: float, now: float, pipelined: bool = True) -> Request:
    request = scheduler.request(CODEC, ma.SpeedControl(speed_dps=speed), timeout_s=0.003)
    request.pipelined = pipelined
    scheduler.submit(request, now)
    for out in scheduler.poll(now)[0]:
        scheduler.sent(out, now)
    return request


def _reply(speed: float, at: float) -> Frame:
    data = bytes([0xA2, 25, 0, 0]) + struct.pack("<hh", round(speed), 0)
    return Frame(arbitration_id=0x241, data=data, timestamp=at)


def test_pipelined_requests_with_one_key_leave_together_and_are_answered_in_order() -> None:
    scheduler = _scheduler()
    requests = [_send(scheduler, float(i), i * 0.001) for i in range(3)]
    assert [r.state for r in requests] == [S.SENT] * 3  # none waited for the one before
    for i in range(3):
        got = scheduler.receive(_reply(i, 0.0025 + i * 0.001), 0.0025 + i * 0.001)
        assert got.traffic is Traffic.REPLY and got.request is requests[i]


def test_an_ordinary_request_still_waits_for_its_key() -> None:
    scheduler = _scheduler()
    first = _send(scheduler, 1.0, 0.0)
    ordinary = _send(scheduler, 2.0, 0.001, pipelined=False)
    assert first.state is S.SENT and ordinary.state is S.QUEUED
    scheduler.receive(_reply(1, 0.002), 0.002)
    assert [r for r in scheduler.poll(0.002)[0]] == [ordinary]


def test_a_lost_reply_makes_the_next_reply_answer_the_older_request() -> None:
    # No sequence numbers: the reply to the second request answers the first (the oldest in flight
    # it could answer); the loop then reports the state as the older tick's: never younger.
    scheduler = _scheduler()
    first, second = _send(scheduler, 1.0, 0.0), _send(scheduler, 2.0, 0.001)
    got = scheduler.receive(_reply(2, 0.0025), 0.0025)
    assert got.request is first and first.reply is not None and first.reply.speed_dps == 2.0
    assert second.state is S.SENT
    assert scheduler.expire(0.0041) == [second]  # its own reply never comes


def test_a_reply_later_than_its_deadline_is_late_while_no_newer_request_could_take_it() -> None:
    scheduler = _scheduler()
    first = _send(scheduler, 1.0, 0.0)
    assert scheduler.expire(0.0031) == [first]
    got = scheduler.receive(_reply(1, 0.004), 0.004)
    assert got.traffic is Traffic.LATE and got.request is None
    # With a newer one in flight it answers that one (a reply cannot say which it answers): the
    # loop attributes it to the oldest command still outstanding (servobus.loop), the late one.
    second = _send(scheduler, 2.0, 0.005)
    assert scheduler.expire(0.0081) == [second]
    third = _send(scheduler, 3.0, 0.009)
    got = scheduler.receive(_reply(2, 0.0095), 0.0095)
    assert got.request is third


def test_the_same_reply_again_at_the_same_instant_is_a_duplicate_not_the_next_requests() -> None:
    scheduler = _scheduler()
    first, second = _send(scheduler, 1.0, 0.0), _send(scheduler, 2.0, 0.001)
    assert scheduler.receive(_reply(1, 0.002), 0.002).request is first
    again = scheduler.receive(_reply(1, 0.002), 0.002)
    assert again.traffic is Traffic.DUPLICATE and again.request is None and second.state is S.SENT
    assert scheduler.counts["duplicate"] == 1
    # The same bytes later are the next request's reply (a motor at rest says the same again).
    assert scheduler.receive(_reply(1, 0.003), 0.003).request is second

"""servobus.scheduler: matching, pacing, time-outs and frame classification, with plain calls and a
virtual clock (the sans-IO simulator network; no asyncio anywhere)."""

from __future__ import annotations

import dataclasses
import random

import pytest

from servobus import Frame
from servobus.errors import ProtocolError
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import TRANSITIONS, Request, RequestState, Scheduler, Traffic
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.sim.network import SimCanNetwork

MA = get_family("myactuator")
S = RequestState
STATUS = bytes.fromhex("9C 32 64 00 F4 01 2D 00")


def _reply(motor: int, data: bytes = STATUS, t: float = 0.0) -> Frame:
    return Frame(arbitration_id=0x240 + motor, data=data, timestamp=t)


def _send_all(scheduler: Scheduler, now: float) -> list[Request]:
    out, _ = scheduler.poll(now)
    for request in out:
        scheduler.sent(request, now)
    return list(out)


def test_equal_keys_go_one_exchange_at_a_time_so_a_duplicate_cannot_answer_the_second() -> None:
    codec = MA.bind(1)
    other = MA.bind(2)
    scheduler = Scheduler([codec, other])
    first, second = (scheduler.request(codec, ma.ReadStatus2()) for _ in range(2))
    third = scheduler.request(other, ma.ReadStatus2())
    for request in (first, second, third):
        scheduler.submit(request, 0.0)
    assert _send_all(scheduler, 0.0) == [first, third]  # the second waits; other keys go past it
    got = scheduler.receive(_reply(1, t=0.001), 0.001)
    assert (got.traffic, got.request) == (Traffic.REPLY, first) and first.state is S.REPLIED
    assert isinstance(first.reply, ma.StatusReply) and second.state is S.QUEUED
    assert scheduler.receive(_reply(1, t=0.001), 0.001).traffic is Traffic.DUPLICATE
    assert _send_all(scheduler, 0.002) == [second]
    scheduler.receive(_reply(1, t=0.003), 0.003)
    assert second.state is S.REPLIED and scheduler.counts["duplicate"] == 1


def test_a_frame_that_comes_sooner_than_the_wire_allows_is_not_the_reply() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0002)
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.010)
    assert scheduler.receive(_reply(1, t=0.0101), 0.0101).traffic is Traffic.UNSOLICITED
    assert request.state is S.SENT
    assert scheduler.receive(_reply(1, t=0.0103), 0.0103).request is request


def _echo(motor: int, command: ma.MyActuatorCommand, t: float) -> Frame:
    return _reply(motor, command.encode(), t)


def test_a_stray_echo_never_answers_a_write_of_another_value() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    one, two = ma.WriteEncoderZero(offset_counts=-1), ma.WriteEncoderZero(offset_counts=-2)
    first, second = scheduler.request(codec, one), scheduler.request(codec, two)
    assert first.key != second.key  # an echo's key holds the value written: both may be in flight
    for request in (first, second):
        scheduler.submit(request, 0.0)
    assert _send_all(scheduler, 0.0) == [first, second]
    assert scheduler.receive(_echo(1, one, 0.001), 0.001).request is first
    got = scheduler.receive(_echo(1, one, 0.002), 0.002)  # the first write, answered twice
    assert got.traffic is Traffic.DUPLICATE and second.state is S.SENT
    assert scheduler.receive(_echo(1, two, 0.003), 0.003).request is second
    assert second.reply == ma.Echo(command=two)


def test_the_late_and_duplicate_windows_forget_expired_keys() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], late_window_s=0.01)
    for k in range(1000):  # a write of a new value every ms: a new key each time
        now = k * 0.001
        command = ma.WriteEncoderZero(offset_counts=k)
        request = scheduler.request(codec, command)
        scheduler.submit(request, 0.0)
        _send_all(scheduler, now)
        assert scheduler.receive(_echo(1, command, now), now).request is request
    assert len(scheduler.keys.replied) <= 64  # ~10 live in the window, pruned past 64


def test_a_reply_stamped_at_a_virtual_clocks_first_instant_is_not_taken_for_an_unstamped_one() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0002)
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)  # sent at t = 0.0, as on a loop started at 0 (looptime)
    assert scheduler.receive(_reply(1, t=0.0), 0.0).traffic is Traffic.UNSOLICITED
    assert scheduler.receive(_reply(1, t=0.0003), 0.0003).request is request


def test_replies_of_other_commands_or_motors_never_resolve_the_wrong_request() -> None:
    one, two = MA.bind(1), MA.bind(2)
    scheduler = Scheduler([one, two])
    status = scheduler.request(one, ma.ReadStatus2())
    angle = scheduler.request(two, ma.ReadMultiTurnAngle())
    for request in (status, angle):
        scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.receive(_reply(2, STATUS), 0.001).traffic is Traffic.UNSOLICITED  # motor 2, wrong code
    assert scheduler.receive(Frame(arbitration_id=0x7FF, data=b"\x01"), 0.001).traffic is Traffic.FOREIGN
    assert (status.state, angle.state) == (S.SENT, S.SENT)
    assert scheduler.counts["unsolicited"] == 1 and scheduler.counts["foreign"] == 1


def test_a_malformed_reply_fails_its_request_with_the_codecs_error_not_a_timeout() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    got = scheduler.receive(_reply(1, STATUS[:5]), 0.001)  # truncated: keyed 0x9C, does not decode
    assert got.traffic is Traffic.MALFORMED and got.request is request and request.state is S.FAILED
    assert isinstance(request.error, ProtocolError) and request.error.motor_id == 1
    assert scheduler.counts["malformed"] == 1 and scheduler.counts["failed"] == 1
    assert scheduler.receive(_reply(1), 0.002).traffic is Traffic.DUPLICATE  # never the next request's


def test_a_malformed_frame_with_no_request_waiting_fails_nothing() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    got = scheduler.receive(_reply(1, STATUS[:5]), 0.001)
    assert got.traffic is Traffic.MALFORMED and got.request is None and scheduler.counts["failed"] == 0


def test_a_request_times_out_at_its_deadline_from_when_it_left_and_its_reply_is_late() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(request, 0.0)
    list(scheduler.poll(0.0)[0])
    assert scheduler.next_deadline() is None  # not left yet: no deadline
    scheduler.sent(request, 0.005)
    assert scheduler.next_deadline() == pytest.approx(0.015)
    assert scheduler.expire(0.0149) == []
    assert scheduler.expire(0.015) == [request] and request.state is S.TIMED_OUT
    assert scheduler.receive(_reply(1), 0.02).traffic is Traffic.LATE
    assert scheduler.receive(_reply(1), 0.021).traffic is Traffic.UNSOLICITED  # one late reply per request


def test_a_cancelled_requests_reply_is_late_and_never_reaches_a_later_request() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0002)
    old = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(old, 0.0)
    _send_all(scheduler, 0.0)
    scheduler.cancel(old, 0.001)
    assert scheduler.pending == 0 and old.state is S.CANCELLED
    new = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(new, 0.0)
    _send_all(scheduler, 0.002)
    assert new.state is S.QUEUED  # held: the old request's reply may still come
    assert scheduler.receive(_reply(1, t=0.0021), 0.0021).traffic is Traffic.LATE
    _send_all(scheduler, 0.0022)  # it came: the key is free again
    assert new.state is S.SENT
    scheduler.receive(_reply(1, t=0.0025), 0.0025)
    assert new.state is S.REPLIED and scheduler.pending == 0


def test_a_request_given_up_on_before_its_send_report_holds_its_key_until_the_report_times_it() -> None:
    """Cancelled while its frame waits in the link's queue: that frame may still leave, later than
    the request's own timeout, and its reply must not answer the next request with its key. The key
    is held until the report could come; the report (the Engine passes it on) re-times the hold
    from when the frame left, and the late reply, when it comes, is counted late and frees it."""
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001, report_within_s=0.6)
    old = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(old, 0.0)
    out, _ = scheduler.poll(0.0)
    assert out == [old]
    scheduler.cancel(old, 0.001)  # no send report yet
    new = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(new, 0.04)
    out, _ = scheduler.poll(0.04)
    assert out == [] and new.state is S.QUEUED  # past the old one's timeout, still held
    scheduler.sent_after_all(old, 0.05)  # its frame left after all
    out, _ = scheduler.poll(0.0502)
    assert out == []
    assert scheduler.receive(_reply(1, t=0.0507), 0.0507).traffic is Traffic.LATE
    out, _ = scheduler.poll(0.0508)  # the late reply came: the key is free again
    assert out == [new]
    scheduler.sent(new, 0.0508)
    scheduler.receive(_reply(1, t=0.0511), 0.0511)
    assert new.state is S.REPLIED and scheduler.pending == 0


def test_after_a_timeout_the_key_is_held_for_the_late_reply_then_released_by_time() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], late_hold_s=0.05)
    old = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(old, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.expire(0.01) == [old]
    new = scheduler.request(codec, ma.ReadStatus2())
    other = scheduler.request(codec, ma.ReadStatus1())  # another key is not held
    scheduler.submit(new, 0.0)
    scheduler.submit(other, 0.0)
    assert list(scheduler.poll(0.02)[0]) == [other]
    assert scheduler.next_deadline() == pytest.approx(0.06)
    assert not scheduler.poll(0.0599)[0] and list(scheduler.poll(0.0601)[0]) == [new]


def test_a_broadcast_reply_waits_for_its_keys_and_then_goes_past_the_queue() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    timed_out = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(timed_out, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.blocking([timed_out.key], 0.005) == (None, [timed_out])  # in flight
    scheduler.expire(0.01)
    # held for its late reply: twice the codec's 20 ms (no round trip measured yet to say otherwise)
    assert scheduler.blocking([timed_out.key], 0.015) == (0.04, [])
    assert scheduler.blocking([timed_out.key], 0.04) == (None, [])
    queued = scheduler.request(codec, ma.ReadMultiTurnAngle())
    scheduler.submit(queued, 0.0)  # the queue does not hold a broadcast's expectation back
    expected = dataclasses.replace(
        scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.02), frame=Frame(arbitration_id=0)
    )
    scheduler.expect(expected, 0.04)
    assert expected.state is S.SENT and expected.deadline == 0.06 and queued.state is S.QUEUED
    got = scheduler.receive(_reply(1, t=0.041), 0.041)
    assert got.request is expected and expected.state is S.REPLIED and scheduler.counts["requests"] == 3
    with pytest.raises(RuntimeError, match="submitted once"):
        scheduler.expect(expected, 0.03)


def test_a_reply_that_beats_its_send_report_answers_its_request() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0002)
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    assert list(scheduler.poll(0.0)[0]) == [request] and request.state is S.SENDING
    assert scheduler.receive(_reply(1, t=0.0004), 0.0004).traffic is Traffic.EARLY
    got = scheduler.sent(request, 0.0001)  # the report comes after: now the reply can be judged
    assert got is not None and got.traffic is Traffic.REPLY and got.request is request
    assert request.state is S.REPLIED and scheduler.pending == 0 and scheduler.counts["replies"] == 1


def test_an_early_frame_too_soon_after_its_send_time_is_not_the_reply() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0002)
    first = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(first, 0.0)
    _send_all(scheduler, 0.0)
    scheduler.receive(_reply(1, t=0.0003), 0.0003)
    second = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(second, 0.0)
    assert list(scheduler.poll(0.0004)[0]) == [second]
    # The first reply's duplicate, stamped before the second request could have been answered:
    assert scheduler.receive(_reply(1, t=0.0005), 0.0005).traffic is Traffic.EARLY
    got = scheduler.sent(second, 0.0004)
    assert got is not None and got.traffic is Traffic.DUPLICATE and got.request is None
    assert second.state is S.SENT


def test_retry_safe_reads_go_again_and_writes_are_never_retried() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    read = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01, retries=1)
    scheduler.submit(read, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.expire(0.01) == [] and read.state is S.QUEUED
    # The retry waits for the first attempt's late reply, as the next request would (it comes: the
    # retry goes at once), so that reply never answers the retry.
    assert _send_all(scheduler, 0.011) == []
    assert scheduler.receive(_reply(1, t=0.012), 0.012).traffic is Traffic.LATE
    assert _send_all(scheduler, 0.012) == [read]
    assert scheduler.expire(0.023) == [read] and read.attempts == 2
    with pytest.raises(ValueError, match="never retried"):
        scheduler.request(codec, ma.SpeedControl(speed_dps=10.0), retries=1)


def test_pacing_keeps_the_in_flight_limit_and_a_half_duplex_line_rests_between_exchanges() -> None:
    codecs = [MA.bind(m, link="rs485") for m in (1, 2, 3)]
    scheduler = Scheduler(codecs, one_at_a_time=True, gap_s=0.001)
    requests = [scheduler.request(c, ma.ReadStatus2()) for c in codecs]
    for request in requests:
        scheduler.submit(request, 0.0)
    assert _send_all(scheduler, 0.0) == requests[:1] and _send_all(scheduler, 0.0) == []
    reply = Frame(arbitration_id=1, data=STATUS, is_serial=True)
    scheduler.receive(reply, 0.002)
    assert _send_all(scheduler, 0.0025) == [] and scheduler.next_deadline() == pytest.approx(0.003)
    assert _send_all(scheduler, 0.003) == requests[1:2]
    limited = Scheduler([MA.bind(1)], max_in_flight=2)
    for read in (ma.ReadStatus1(), ma.ReadStatus2(), ma.ReadStatus3()):
        limited.submit(limited.request(limited.codecs[0], read), 0.0)
    assert len(_send_all(limited, 0.0)) == 2


def test_commands_without_a_reply_are_done_when_they_leave() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    reset = scheduler.request(codec, ma.SystemReset())
    scheduler.submit(reset, 0.0)
    _send_all(scheduler, 0.0)
    assert reset.state is S.REPLIED and reset.reply is None and scheduler.pending == 0


def test_a_streamed_read_is_answered_by_the_next_stream_frame_after_it_left() -> None:
    codec = MA.bind(1)
    codec.note_sent(ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10))
    scheduler = Scheduler([codec])
    read = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(read, 0.0)
    _send_all(scheduler, 0.010)
    assert scheduler.receive(_reply(1, t=0.009), 0.0101).traffic is Traffic.STREAM  # older than the request
    assert read.state is S.SENT
    got = scheduler.receive(_reply(1, t=0.019), 0.019)
    assert (got.traffic, got.request, read.state) == (Traffic.STREAM, read, S.REPLIED)


def test_a_lost_transport_fails_everything_pending() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], max_in_flight=1)
    requests = [scheduler.request(codec, ma.ReadStatus2()) for _ in range(3)]
    for request in requests:
        scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    error = OSError("unplugged")
    assert scheduler.fail(error, 0.001) == requests
    assert all(r.state is S.FAILED and r.error is error for r in requests) and scheduler.pending == 0


def test_motors_that_collide_are_refused_when_added() -> None:
    with pytest.raises(ValueError, match="cannot share a bus"):
        Scheduler([MA.bind(1), get_family("lk").bind(1, revision="V2_35")])


def test_illegal_moves_name_the_request() -> None:
    assert TRANSITIONS[S.REPLIED] == frozenset()
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    with pytest.raises(RuntimeError, match="myactuator motor 1 ReadStatus2 is already queued"):
        scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    scheduler.receive(_reply(1), 0.001)
    with pytest.raises(RuntimeError, match="is replied: a request is submitted once"):
        scheduler.submit(request, 0.0)


# ---- a seeded run over the simulated bus, with faults (issue 15's reliability figure, sans-IO) ----

READS = (ma.ReadStatus1, ma.ReadStatus2, ma.ReadStatus3, ma.ReadMultiTurnAngle, ma.ReadEncoderPosition)


def _run(n_requests: int, seed: int) -> tuple[Scheduler, list[Request], list[tuple[float, int]]]:
    rng = random.Random(seed)
    motors = [MyActuatorMotor(m) for m in range(1, 33)]
    # Replies delayed 25-40 ms arrive after their 20 ms time-out: they must come back as LATE.
    plan = FaultPlan(drop=0.05, duplicate=0.01, corrupt=0.01, delay=0.01, delay_s=(0.025, 0.04))
    network = SimCanNetwork(motors, to_host=FaultInjector(plan, seed=seed))
    codecs = [MA.bind(m) for m in range(1, 33)]
    # 8 exchanges fit the bus well inside a time-out; a reply needs two 8-byte frames' wire time.
    scheduler = Scheduler(codecs, max_in_flight=8, min_reply_s=2 * 111e-6)
    requests: list[Request] = []
    trace: list[tuple[float, int]] = []
    now = 0.0
    while len(requests) < n_requests or scheduler.pending:
        while len(requests) < n_requests and scheduler.pending < 64:
            codec = rng.choice(codecs)
            request = scheduler.request(codec, rng.choice(READS)(), timeout_s=0.02)
            scheduler.submit(request, 0.0)
            requests.append(request)
        for request in list(scheduler.poll(now)[0]):
            network.send(request.frame, now)
            scheduler.sent(request, now)
        times = [t for t in (network.next_event_s(), scheduler.next_deadline()) if t is not None]
        now = max(now, min(times)) if times else now
        for at, frame in network.advance(now):
            got = scheduler.receive(dataclasses.replace(frame, timestamp=at), at)
            trace.append((at, frame.arbitration_id))
            if got.request is not None:
                _check_answer(got.request, frame)
        scheduler.expire(now)
    return scheduler, requests, trace


def _check_answer(request: Request, frame: Frame) -> None:
    """The frame that resolved ``request`` is its motor's reply to its own command byte."""
    assert frame.arbitration_id == 0x240 + request.codec.motor_id
    assert frame.data[0] == request.frame.data[0]


def _verify(scheduler: Scheduler, requests: list[Request]) -> None:
    assert scheduler.pending == 0
    for request in requests:
        assert request.state in (S.REPLIED, S.TIMED_OUT), request
        if request.state is S.TIMED_OUT:
            assert request.deadline is not None and request.sent_at is not None
            assert request.deadline == pytest.approx(request.sent_at + request.timeout_s)
    counts = scheduler.counts
    assert counts["replies"] + counts["timeouts"] == len(requests)
    assert counts["timeouts"] > 0 and counts["late"] > 0 and counts["duplicate"] > 0
    # Only the faults time requests out (5% dropped, 1% delayed past the time-out), not the bus.
    assert counts["timeouts"] < 0.09 * len(requests)


def test_seeded_faults_never_cost_a_request_its_right_answer() -> None:
    scheduler, requests, _ = _run(3_000, seed=7)
    _verify(scheduler, requests)


def test_the_same_seed_gives_the_same_run() -> None:
    assert _run(500, seed=3)[2] == _run(500, seed=3)[2]


@pytest.mark.slow
def test_seeded_faults_over_100k_requests() -> None:
    scheduler, requests, _ = _run(100_000, seed=11)
    _verify(scheduler, requests)
    print(dict(scheduler.counts))


def test_a_held_key_on_a_half_duplex_line_waits_without_waking_all_the_time() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], one_at_a_time=True, gap_s=0.001, late_hold_s=0.05)
    old = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(old, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.expire(0.01) == [old]
    new = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(new, 0.0)
    assert not scheduler.poll(0.02)[0]  # the rest is over, the key still held
    assert scheduler.next_deadline() == pytest.approx(0.06)  # not the past rest: no busy timer


def test_answered_requests_under_a_long_timeout_do_not_pile_up_in_the_deadline_heap() -> None:
    codecs = [MA.bind(i) for i in (1, 2)]
    scheduler = Scheduler(codecs)
    slow = scheduler.request(codecs[0], ma.ReadStatus2(), timeout_s=60.0)
    scheduler.submit(slow, 0.0)
    _send_all(scheduler, 0.0)
    for n in range(1000):
        now = 0.001 * (n + 1)
        request = scheduler.request(codecs[1], ma.ReadStatus2())
        scheduler.submit(request, 0.0)
        _send_all(scheduler, now)
        scheduler.receive(_reply(2, t=now + 0.0005), now + 0.0005)
        assert request.state is S.REPLIED
    assert len(scheduler.table.deadlines) <= 64 + 4 * 2
    assert scheduler.next_deadline() == pytest.approx(60.0)


def test_a_command_that_waited_too_long_for_its_turn_is_never_sent_but_a_read_is() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], one_at_a_time=True, stale_after_s=0.2)
    first = scheduler.request(codec, ma.ReadStatus1(), timeout_s=0.5)
    command = scheduler.request(codec, ma.SpeedControl(speed_dps=10.0))
    read = scheduler.request(codec, ma.ReadStatus2())
    for request in (first, command, read):
        scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    assert scheduler.expire(0.5) == [first]  # the line was busy for 0.5 s
    sending, stale = scheduler.poll(0.5)
    assert sending == [read] and command.state is S.FAILED and stale == [command]
    assert command.queued_at == 0.0 and read.queued_at is None  # stamped at submit: a command only
    assert "not sent (stale" in str(command.error)  # what its caller gets
    assert scheduler.poll(0.5) == ((), ())
    assert scheduler.counts["not_sent_stale"] == 1


# ---- timeouts and holds from measured round trips (issue [control]) ----


def _exchange(scheduler: Scheduler, codec: object, command: object, at: float, rtt_s: float) -> Request:
    request = scheduler.request(codec, command)  # type: ignore[arg-type]
    scheduler.submit(request, 0.0)
    _send_all(scheduler, at)
    data = STATUS if isinstance(command, ma.ReadStatus2) else None
    if data is not None:
        scheduler.receive(_reply(1, data, t=at + rtt_s), at + rtt_s)
    return request


def test_a_measured_class_gets_its_estimate_and_a_slow_class_keeps_its_codecs_time() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    first = _exchange(scheduler, codec, ma.ReadStatus2(), 0.0, 0.001)
    assert first.timeout_s == 1.0  # nothing measured yet: the conservative first value
    for i in range(1, 40):
        _exchange(scheduler, codec, ma.ReadStatus2(), i * 0.01, 0.001)
    later = _exchange(scheduler, codec, ma.ReadStatus2(), 1.0, 0.001)
    assert later.timeout_s == scheduler.min_timeout_s  # ~1 ms + 4 x its deviation: the 5 ms floor
    # WriteEncoderZero is a flash write: its codec gives it 0.5 s, and however fast it was measured,
    # a timeout never goes below that (the next one may erase a sector).
    write = scheduler.request(codec, ma.WriteEncoderZero(offset_counts=5))
    assert write.rtt is not None and write.rtt.base_s == 0.5 and write.rtt.floor_s == 0.5
    write.rtt.add(0.001)
    scheduler.submit(write, 0.0)
    _send_all(scheduler, 2.0)
    assert write.timeout_s == 0.5


def test_with_nothing_measured_the_requests_waiting_to_be_timed_again_stay_bounded() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec], late_hold_s=0.0)
    for i in range(1000):
        request = scheduler.request(codec, ma.ReadStatus2())
        scheduler.submit(request, 0.0)
        _send_all(scheduler, i * 2.0)
        scheduler.expire(i * 2.0 + 1.5)  # the motor never answers
    assert len(scheduler.table.provisional) <= 64


def test_a_late_reply_after_a_given_up_one_keeps_the_key_ambiguous() -> None:
    """A's hold ended without its reply; B went out and timed out too; a frame then comes: it may
    be A's, so C's reply is counted ambiguous, not taken as plainly C's."""
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    a = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(a, 0.0)
    _send_all(scheduler, 0.0)
    scheduler.expire(0.01)  # held until twice the codec's 20 ms: 0.04
    b = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(b, 0.0)
    _send_all(scheduler, 0.05)  # A's hold ended: doubtful
    scheduler.expire(0.065)
    assert scheduler.receive(_reply(1, t=0.07), 0.07).traffic is Traffic.LATE  # B's, or A's
    c = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(c, 0.0)
    _send_all(scheduler, 0.08)
    got = scheduler.receive(_reply(1, t=0.081), 0.081)
    assert got.request is c and scheduler.counts["ambiguous"] == 1


def test_an_undecodable_reply_before_the_send_report_fails_its_request_at_the_report() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    (sending,) = list(scheduler.poll(0.0)[0])
    assert scheduler.receive(_reply(1, STATUS[:5], t=0.001), 0.001).traffic is Traffic.EARLY
    early = scheduler.sent(sending, 0.0002)
    assert early is not None and early.request is request and request.state is S.FAILED
    assert isinstance(request.error, ProtocolError) and scheduler.counts["malformed"] == 1


def test_every_move_goes_through_the_table_and_an_illegal_one_is_a_typed_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from servobus.errors import RequestStateError, ServobusError
    from servobus.scheduler import _table

    assert not any(hasattr(state, "next") for state in S)  # (the table is the only place)
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    with pytest.raises(RequestStateError, match=r"myactuator motor 1 ReadStatus2: queued -> replied"):
        scheduler.table.move(request, S.REPLIED, 0.0)
    assert issubclass(RequestStateError, RuntimeError) and issubclass(RequestStateError, ServobusError)
    # The hot moves read the table too: one it does not allow fails, typed, naming both states
    # (a send report it does not allow is taken for none).
    monkeypatch.setitem(_table.FROM, S.SENDING, ())
    with pytest.raises(RequestStateError, match="queued -> sending is not allowed"):
        scheduler.poll(0.0)
    monkeypatch.undo()
    scheduler = Scheduler([codec])
    scheduler.submit(scheduler.request(codec, ma.ReadStatus2()), 0.0)
    (sending,) = scheduler.poll(0.0)[0]
    monkeypatch.setitem(_table.FROM, S.SENT, ())
    assert scheduler.sent(sending, 0.0) is None and sending.state is S.SENDING


def test_a_request_whose_send_report_never_comes_still_times_out() -> None:
    """With ``report_within_s``, a request handed over and never reported gets a provisional
    deadline: that long after hand-over, plus its timeout. A report that comes in time re-bases its
    deadline on when the frame left."""
    codec = MA.bind(1)
    scheduler = Scheduler([codec], report_within_s=0.1)
    lost, late = (
        scheduler.request(codec, command, timeout_s=0.05) for command in (ma.ReadStatus2(), ma.ReadStatus1())
    )
    for request in (lost, late):
        scheduler.submit(request, 0.0)
    assert list(scheduler.poll(0.0)[0]) == [lost, late]
    assert scheduler.next_deadline() == pytest.approx(0.1)  # when the first report is overdue
    assert scheduler.sent(late, 0.04) is None  # late, but within report_within_s: timed from then
    assert late.deadline == pytest.approx(0.09)
    assert scheduler.expire(0.0999) == [late]  # (its own timeout: nothing came)
    assert scheduler.expire(0.1) == [] and lost.deadline == pytest.approx(0.15)
    deadline = scheduler.next_deadline()
    assert deadline is not None and deadline == pytest.approx(0.15)
    assert scheduler.expire(deadline) == [lost] and lost.state is S.TIMED_OUT
    assert scheduler.counts["unreported"] == 1 and scheduler.counts["timeouts"] == 2
    assert scheduler.pending == 0
    assert scheduler.sent(lost, 0.2) is None  # a report that still comes changes nothing


def test_a_dropped_frame_fails_its_request_with_a_transport_error_that_says_why() -> None:
    from servobus.errors import TransportError

    codec = MA.bind(1)
    scheduler = Scheduler([codec], name="can0")
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    scheduler.poll(0.0)
    scheduler.not_sent(request, "purged", 0.001)
    assert request.state is S.FAILED and isinstance(request.error, TransportError)
    assert str(request.error) == "can0: myactuator motor 1 ReadStatus2 not sent (purged)"
    assert scheduler.counts["not_sent_purged"] == 1


def test_a_reply_stamped_after_its_deadline_is_late_whichever_the_host_took_first() -> None:
    """The loop may take a reply in before the timer that expires its request: a reply stamped
    after the deadline is still late (the request times out, and says so at the next expire); an
    unstamped one counts from when it was taken in."""
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2(), timeout_s=0.01)
    scheduler.submit(request, 0.0)
    _send_all(scheduler, 0.0)
    got = scheduler.receive(_reply(1, t=0.012), 0.013)
    assert got.traffic is Traffic.LATE and got.request is None and request.state is S.TIMED_OUT
    assert scheduler.next_deadline() == pytest.approx(0.01)  # (its expiry is due: to be told)
    assert scheduler.expire(0.013) == [request] and scheduler.expire(0.013) == []
    assert scheduler.counts["timeouts"] == 1 and scheduler.counts["late"] == 1
    in_time = scheduler.request(codec, ma.ReadStatus1(), timeout_s=0.01)
    scheduler.submit(in_time, 0.1)
    _send_all(scheduler, 0.1)
    assert (
        scheduler.receive(_reply(1, data=bytes.fromhex("9A 32 00 00 00 00 00 00"), t=0.109), 0.2).request
        is in_time
    )

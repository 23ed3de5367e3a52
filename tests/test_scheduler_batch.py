"""The scheduler's batch calls for a pipelined tick (``batch_requests``, ``submit_batch``) make and
queue exactly what ``request`` and ``submit`` do, one by one."""

from __future__ import annotations

import dataclasses

import pytest

from servobus.errors import RequestStateError
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.scheduler import Request, RequestState, Scheduler, batch_requests, submit_batch

MA = get_family("myactuator")

COMMANDS = [
    ma.SpeedControl(speed_dps=30.0),
    ma.ReadStatus2(),
    ma.TorqueControl(current_a=-1.25),
    ma.MotorStop(),
    ma.ReadMultiTurnAngle(),
]


def _fields(request: Request) -> dict[str, object]:
    out = {f.name: getattr(request, f.name) for f in dataclasses.fields(request)}
    out["frame"] = (request.frame.arbitration_id, request.frame.data)
    return out


@pytest.mark.parametrize("timeout_s", [None, 0.02])
def test_a_batch_makes_what_request_makes(timeout_s: float | None) -> None:
    codecs = [MA.bind(i) for i in (1, 2, 3)]
    one, batch = Scheduler(codecs), Scheduler(codecs)
    items = [(codecs[i % 3], command, object()) for i, command in enumerate(COMMANDS * 2)]
    singly = [one.request(codec, command, timeout_s, 0, context) for codec, command, context in items]
    made = batch_requests(batch, items, timeout_s)
    assert len(made) == len(singly)
    for a, b in zip(singly, made, strict=True):
        fa, fb = _fields(a), _fields(b)
        # (each scheduler has its own round-trip estimates: the same motor and class, not the object)
        assert (fa.pop("rtt") is None) == (fb.pop("rtt") is None)
        assert fa == fb
        assert b.rtt is batch.estimates.motors[id(b.codec)][type(b.command)]


def test_a_batch_refuses_what_request_refuses_and_returns_nothing() -> None:
    codec, stranger = MA.bind(1), MA.bind(9)
    scheduler = Scheduler([codec])
    with pytest.raises(ValueError, match="timeout_s"):
        batch_requests(scheduler, [(codec, ma.ReadStatus2(), None)], 0.0)
    with pytest.raises(ValueError, match="not on this bus"):
        batch_requests(scheduler, [(codec, ma.ReadStatus2(), None), (stranger, ma.ReadStatus2(), None)])
    assert not scheduler.table.queue


def test_submit_batch_queues_in_order_and_counts_as_submit() -> None:
    codecs = [MA.bind(i) for i in (1, 2)]
    one, batch = Scheduler(codecs), Scheduler(codecs)
    items = [(codecs[i % 2], command, None) for i, command in enumerate(COMMANDS)]
    singly = batch_requests(one, items)
    for request in singly:
        one.submit(request, 1.5)
    made = batch_requests(batch, items)
    submit_batch(batch, made, 1.5)
    assert list(batch.table.queue) == made
    assert [r.queued_at for r in made] == [r.queued_at for r in singly]
    assert all(r.submitted and r.state is RequestState.QUEUED for r in made)
    assert batch.counts == one.counts and batch.counts["requests"] == len(COMMANDS)
    with pytest.raises(RequestStateError, match="submitted once"):
        submit_batch(batch, made[:1], 2.0)

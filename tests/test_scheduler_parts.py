"""servobus.scheduler's parts (issue 38): the counter the Bus's tick adds to, the one place a request
changes state, matching that changes nothing, the estimates as their own object, and a Scheduler that
composes its parts (no mixins)."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import servobus.scheduler
from servobus import Frame
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.rtt import Estimates, RoundTrip
from servobus.scheduler import Request, RequestState, Scheduler, Traffic
from servobus.scheduler._match import ANSWER, EARLY, NO_MOTOR, match
from servobus.scheduler._table import RequestTable

MA = get_family("myactuator")
S = RequestState
STATUS = bytes.fromhex("9C 32 64 00 F4 01 2D 00")
PACKAGE = Path(servobus.scheduler.__file__).parent


def _reply(motor: int, t: float = 0.0) -> Frame:
    return Frame(arbitration_id=0x240 + motor, data=STATUS, timestamp=t)


def _sent(scheduler: Scheduler, codec: object, now: float) -> Request:
    request = scheduler.request(codec, ma.ReadStatus2())  # type: ignore[arg-type]
    scheduler.submit(request, now)
    (out,) = scheduler.poll(now)[0]
    scheduler.sent(out, now)
    return request


def test_count_adds_to_the_motors_counter_and_to_the_bus_counts() -> None:
    one, two = MA.bind(1), MA.bind(2)
    scheduler = Scheduler([one, two])
    scheduler.count(one, "stream_off_resent")
    scheduler.count(one, "stream_off_resent", 2)
    scheduler.count(two, "skipped")
    assert scheduler.motor_counts[id(one)]["stream_off_resent"] == 3
    assert scheduler.motor_counts[id(two)] == {"skipped": 1}
    assert scheduler.counts["stream_off_resent"] == 3 and scheduler.counts["skipped"] == 1


def test_count_refuses_a_motor_not_on_the_bus() -> None:
    scheduler = Scheduler([MA.bind(1)])
    with pytest.raises(KeyError):
        scheduler.count(MA.bind(2), "skipped")


def test_only_the_request_tables_move_sets_a_requests_state() -> None:
    """Every state move goes through TRANSITIONS: the one assignment to ``.state`` in the package is
    in ``RequestTable.move``, after its check."""
    places = []
    for path in sorted(PACKAGE.glob("*.py")):
        tree = ast.parse(path.read_text())
        for function in ast.walk(tree):
            if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(function):
                targets = node.targets if isinstance(node, ast.Assign) else []
                if isinstance(node, ast.AugAssign | ast.AnnAssign):
                    targets = [node.target]
                for target in targets:
                    if isinstance(target, ast.Attribute) and target.attr == "state":
                        places.append((path.name, function.name))
    assert places == [("_table.py", "move")]


def test_match_changes_nothing_and_says_the_same_twice() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = _sent(scheduler, codec, 0.0)
    table = scheduler.table
    before = (dict(table.pending), dict(table.in_flight), request.state, dict(scheduler.counts))
    first = match(table, _reply(1, 0.001), 0.001)
    again = match(table, _reply(1, 0.001), 0.001)
    assert first == again and first[0] == ANSWER and first[5] is request
    assert (dict(table.pending), dict(table.in_flight), request.state, dict(scheduler.counts)) == before
    assert match(table, Frame(arbitration_id=0x7FF, data=b"\x00"), 0.001)[0] == NO_MOTOR
    got = scheduler.receive(_reply(1, 0.001), 0.001)  # what the Scheduler carries out
    assert got.traffic is Traffic.REPLY and got.request is request and request.state is S.REPLIED


def test_a_reply_before_the_send_report_is_decided_early_and_kept_by_the_table() -> None:
    codec = MA.bind(1)
    scheduler = Scheduler([codec])
    request = scheduler.request(codec, ma.ReadStatus2())
    scheduler.submit(request, 0.0)
    scheduler.poll(0.0)
    assert match(scheduler.table, _reply(1, 0.001), 0.001)[0] == EARLY
    assert scheduler.receive(_reply(1, 0.001), 0.001).traffic is Traffic.EARLY
    assert request.key in scheduler.table.early
    got = scheduler.sent(request, 0.0005)
    assert got is not None and got.request is request and request.state is S.REPLIED
    assert not scheduler.table.early


def test_the_estimates_are_their_own_object_per_motor_and_command_class() -> None:
    one, two = MA.bind(1), MA.bind(2)
    scheduler = Scheduler([one, two])
    for i in range(3):
        _sent(scheduler, one, i * 1.0)
        scheduler.receive(_reply(1, i * 1.0 + 0.002), i * 1.0 + 0.002)
    estimate = scheduler.estimates.get(id(one), ma.ReadStatus2)
    assert isinstance(estimate, RoundTrip) and estimate.samples == 3
    assert estimate.srtt_s == pytest.approx(0.002)
    assert scheduler.estimates.get(id(two), ma.ReadStatus2) is None  # never requested
    assert scheduler.estimates.get(id(one), ma.ReadStatus1) is None
    assert scheduler.motor_timeout_s(one) == pytest.approx(max(0.005, estimate.timeout_s()))
    assert scheduler.motor_timeout_s(two) == scheduler.min_timeout_s


def test_estimates_alone_give_a_timeout_only_once_something_was_measured() -> None:
    estimates = Estimates(initial_timeout_s=1.0, min_timeout_s=0.005, max_timeout_s=10.0)
    estimates.add_motor(1)
    slow, quick = estimates.new(1, ma.WriteEncoderZero, 0.5), estimates.new(1, ma.ReadStatus2, 0.01)
    assert slow.floor_s == 0.5 and quick.floor_s == 0.005  # a slow class keeps its codec's time
    assert estimates.timeout_s(quick) is None  # nothing measured: the caller's first value
    quick.add(0.002)
    estimates.first_measured()
    assert estimates.timeout_s(quick) == pytest.approx(max(0.005, quick.timeout_s()))
    assert estimates.timeout_s(slow) == pytest.approx(max(0.5, 2.0 * quick.timeout_s()))


def test_the_scheduler_composes_its_parts_without_mixins() -> None:
    assert Scheduler.__bases__ == (object,)
    lines, _ = inspect.getsourcelines(Scheduler)
    assert len(lines) < 300
    scheduler = Scheduler([MA.bind(1)])
    assert isinstance(scheduler.table, RequestTable) and isinstance(scheduler.estimates, Estimates)
    assert scheduler.keys.table is scheduler.table and scheduler.hosts.table is scheduler.table

"""The Bus against the FrameLink contract (servobus.transports.contract), on asyncio and trio in
virtual time: sends are handles the report echoes, and a request's deadline fires even when no
report for it ever comes.

* a link that copies each frame and drops the handle (the issue's ``SimTransport`` subclass with
  ``dataclasses.replace``): a request with ``timeout_s=0.05`` ends in MotorTimeout well before 2 s;
* a link that copies each frame but echoes the handle works as any other;
* a link whose rules say it does not report sends still times out (the deadline starts at
  hand-over);
* a link that reports late (after the reply came) still has its replies matched.

The links here are a small in-file one on LinkBase, and SimTransport subclasses.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus
from servobus.errors import MotorTimeout, TransportError
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.transports.base import Transport as LinkBase
from servobus.transports.contract import FrameLink, LineRules
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio

STATUS = bytes.fromhex("9C 32 64 00 F4 01 2D 00")
CAN_1M = LineRules(bitrate=1_000_000)


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


class Line(LinkBase):
    """A FrameLink on LinkBase: MyActuator motors 1..n answer every request with a status frame
    ``reply_s`` after it left (motors in ``silent`` never do); each send is reported ``report_s``
    after it was handed over (None: never), with ``sent_at`` when it left (at once).

    Args:
        copy: send a copy of each frame (``dataclasses.replace``), as a re-encoding link does.
        echo: report the handle given; else the frame it sent (a link that drops the handle).
    """

    name = "line"

    def __init__(
        self,
        *,
        rules: LineRules = CAN_1M,
        reply_s: float = 0.0002,
        report_s: float | None = 0.0,
        copy: bool = False,
        echo: bool = True,
        silent: tuple[int, ...] = (),
    ) -> None:
        super().__init__()
        self.rules = rules
        self.reply_s = reply_s
        self.report_s = report_s
        self.copy = copy
        self.echo = echo
        self.silent = silent
        self.sent: list[Frame] = []

    def send(self, frame: Frame, handle: object = None) -> None:
        out = dataclasses.replace(frame) if self.copy else frame
        self.sent.append(out)
        left_at = self._now()
        handle = handle if (self.echo and handle is not None) else out
        if self.report_s is not None:
            self._later(self.report_s, self._sent, handle, left_at)
        motor = frame.arbitration_id - 0x140
        if 1 <= motor <= 32 and motor not in self.silent and frame.data[:1] == STATUS[:1]:
            reply = Frame(arbitration_id=0x240 + motor, data=STATUS, timestamp=left_at + self.reply_s)
            self._later(self.reply_s, self._deliver, [reply])

    def _later(self, delay_s: float, fn: Callable[..., object], *args: object) -> None:
        async def at() -> None:
            await anyio.sleep(delay_s)
            fn(*args)

        self._tasks.start_soon(at)


class CopyingSim(SimTransport):
    """The issue's case: a SimTransport that sends a copy of each frame and drops the handle."""

    def send(self, frame: Frame, handle: Any = None) -> None:
        super().send(dataclasses.replace(frame))


class CopyingEchoingSim(SimTransport):
    """A SimTransport that sends a copy of each frame and echoes the handle (as the contract says)."""

    def send(self, frame: Frame, handle: Any = None) -> None:
        super().send(dataclasses.replace(frame), handle)


async def _timed(call: Callable[[], Awaitable[Any]]) -> tuple[Any, float]:
    start = anyio.current_time()
    try:
        result = await call()
    except MotorTimeout as exc:
        result = exc
    return result, anyio.current_time() - start


def test_every_link_here_is_a_frame_link() -> None:
    assert isinstance(Line(), FrameLink)


async def test_a_copying_sim_transport_that_drops_the_handle_still_times_out() -> None:
    device = MyActuatorMotor(1)
    device.unresponsive = True
    with anyio.fail_after(2.0):  # (virtual time: the request must end well before)
        async with Bus(CopyingSim(devices=[device]), safe=None) as bus:
            result, elapsed_s = await _timed(lambda: bus.motor("myactuator", 1).read_status2(timeout_s=0.05))
    assert isinstance(result, MotorTimeout) and elapsed_s < 1.0, (result, elapsed_s)
    assert bus.scheduler.pending == 0


async def test_a_link_that_never_reports_sends_still_times_out_each_request() -> None:
    async with Bus(Line(report_s=None, copy=True, echo=False), safe=None) as bus:
        motor = bus.motor("myactuator", 1)
        with anyio.fail_after(2.0):
            result, elapsed_s = await _timed(lambda: motor.read_status2(timeout_s=0.05))
        assert isinstance(result, MotorTimeout) and elapsed_s < 1.0, (result, elapsed_s)
        # a cycle too: every slot ends (another motor: the first one's key is held for a late reply)
        with anyio.fail_after(2.0):
            results = await bus.cycle([(bus.motor("myactuator", 2), ma.ReadStatus2())], timeout_s=0.05)
        assert type(results[0]) is MotorTimeout
        assert bus.scheduler.pending == 0 and bus.stats()["unreported"] == 2


async def test_a_copying_link_that_echoes_the_handle_works_as_any_other() -> None:
    for link in (Line(copy=True), CopyingEchoingSim(devices=[MyActuatorMotor(m) for m in range(1, 5)])):
        async with Bus(link, safe=None) as bus:
            motors = [bus.motor("myactuator", m) for m in range(1, 5)]
            for _ in range(3):
                results = await bus.cycle([(m, ma.ReadStatus2()) for m in motors])
                assert all(isinstance(r, ma.StatusReply) for r in results), results
            assert isinstance(await motors[0].read_status2(timeout_s=0.05), ma.StatusReply)
        stats = bus.stats()
        assert stats["replies"] == 13, stats
        assert stats.get("timeouts", 0) == 0 and stats.get("unreported", 0) == 0, stats


async def test_a_link_that_does_not_report_sends_times_from_hand_over() -> None:
    line = Line(rules=LineRules(bitrate=1_000_000, reports_sends=False), report_s=None, silent=(2,))
    async with Bus(line, safe=None) as bus:
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        assert isinstance(await one.read_status2(timeout_s=0.05), ma.StatusReply)
        result, elapsed_s = await _timed(lambda: two.read_status2(timeout_s=0.05))
        assert isinstance(result, MotorTimeout)
        assert elapsed_s == pytest.approx(0.05, abs=0.002)  # from hand-over: no report to wait for
        results = await bus.cycle([(one, ma.ReadStatus2()), (two, ma.ReadStatus2())], timeout_s=0.05)
        assert isinstance(results[0], ma.StatusReply) and isinstance(results[1], MotorTimeout)


async def test_a_link_that_reports_late_still_has_its_replies_matched() -> None:
    # The report comes 20 ms after the frame left, long after its reply (0.2 ms): the reply waits
    # (EARLY) and is judged when the report says when the frame left.
    async with Bus(Line(report_s=0.02), safe=None) as bus:
        motors = [bus.motor("myactuator", m) for m in range(1, 5)]
        assert isinstance(await motors[0].read_status2(timeout_s=0.05), ma.StatusReply)
        results = await bus.cycle([(m, ma.ReadStatus2()) for m in motors], timeout_s=0.05)
        assert all(isinstance(r, ma.StatusReply) for r in results), results
    stats = bus.stats()
    assert stats["replies"] == 5 and stats.get("timeouts", 0) == 0, stats


async def test_on_a_link_that_does_not_report_more_requests_than_fit_in_flight_all_go() -> None:
    """More requests than ``max_in_flight`` on a link that does not report: each is timed from its
    hand-over, and the ones queued behind go as the first are answered."""
    line = Line(rules=LineRules(bitrate=1_000_000, reports_sends=False), report_s=None)
    async with Bus(line, safe=None, max_in_flight=2) as bus:
        motors = [bus.motor("myactuator", m) for m in range(1, 7)]
        with anyio.fail_after(1.0):
            results = await bus.cycle([(m, ma.ReadStatus2()) for m in motors], timeout_s=0.05)
        assert all(isinstance(r, ma.StatusReply) for r in results), results
        assert len(line.sent) == 6


async def test_on_a_link_that_does_not_report_commands_without_a_reply_never_wait_for_room() -> None:
    """A command with no reply (a system reset) ends when it is handed over to a link that does not
    report; the ones queued behind it (more than ``max_in_flight``) go at once too, not at some
    later frame or timer."""
    line = Line(rules=LineRules(bitrate=1_000_000, reports_sends=False), report_s=None)
    async with Bus(line, safe=None, max_in_flight=2) as bus:
        motors = [bus.motor("myactuator", m) for m in range(1, 7)]
        with anyio.fail_after(1.0):
            results = await bus.cycle([(m, ma.SystemReset()) for m in motors])
        assert results == [None] * 6 and len(line.sent) == 6


class _Unopenable(Line):
    async def open(self) -> None:
        raise TransportError("line: no such port")


class _Hanging(Line):
    async def open(self) -> None:
        await anyio.sleep_forever()


async def test_a_link_that_cannot_open_raises_its_own_error_and_one_that_hangs_can_be_given_up() -> None:
    """The Bus opens its link in a task of its own (so the link's tasks outlive a cancelled block
    until the safe stop went out); opening still raises the link's error as it is, and an opening
    that hangs ends with the scope that gives up on it."""
    with pytest.raises(TransportError, match="no such port"):
        async with Bus(_Unopenable()):
            pass
    with anyio.move_on_after(0.5) as scope:
        async with Bus(_Hanging()):
            raise AssertionError("entered a link that never opened")
    assert scope.cancelled_caught

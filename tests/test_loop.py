"""The pipelined loop (servobus.loop.Loop) on virtual time, on asyncio and trio, against a link whose
replies come a set time after each request (0.5 to 3 ticks, jitter, loss, a silent motor).

The link answers each SpeedControl with a status whose ``speed_dps`` is the commanded speed, and the
body commands the speed ``tick.index``: a command given in tick k's body leaves at tick k + 1's
deadline, so the reply to the command of tick t says ``t - 1``. That is the truth each state's
``tick`` is checked against: equal, or older after a loss, never younger.
"""

from __future__ import annotations

import heapq
import math
import random
import struct
from collections.abc import Callable
from typing import Any

import anyio
import pytest

from _backends import BACKENDS
from _backends import virtual as virtual_backend
from servobus import Bus
from servobus.errors import MotorTimeout
from servobus.frame import Frame
from servobus.loop import Loop, LoopTick, MotorState
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.runtime import current
from servobus.transports import LineRules

pytestmark = pytest.mark.anyio

HZ = 1000
PERIOD = 1.0 / HZ


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual_backend(request.param)


class DelayLink:
    """A FrameLink whose motors answer each request ``delay(i)`` seconds after it left (in order per
    motor: never before the reply ahead of it), unless ``lose(i)`` (``i``: the request's number).
    ``silent``: motor ids that never answer. It runs a task (:meth:`run`) in the test's task group."""

    name = "delay"

    def __init__(
        self,
        delay: Callable[[int], float],
        lose: Callable[[int], bool] = lambda i: False,
        silent: frozenset[int] = frozenset(),
        rules: LineRules | None = None,
        duplicate: Callable[[int], bool] = lambda i: False,
        garble: Callable[[int], bool] = lambda i: False,
    ) -> None:
        self.delay, self.lose, self.silent, self.duplicate = delay, lose, silent, duplicate
        self.garble = garble
        self.rules = rules or LineRules()
        self.sent: list[tuple[float, Frame]] = []
        self._due: list[tuple[float, int, Frame]] = []
        self._last: dict[int, float] = {}  # motor id -> its last reply's time (replies stay in order)
        self._n = 0
        self._consumer: Any = None
        self._reporter: Any = None
        self._open = False
        self._wake: anyio.Event | None = None

    @property
    def is_open(self) -> bool:
        return self._open

    async def open(self) -> None:
        self._time = current().time
        self._open = True

    async def close(self) -> None:
        self._open = False

    def set_consumer(self, consumer: Any) -> None:
        self._consumer = consumer

    def set_send_reporter(self, reporter: Any) -> None:
        self._reporter = reporter

    def add_listener(self, listener: Any) -> None:
        pass

    def remove_listener(self, listener: Any) -> None:
        pass

    def stats(self) -> Any:
        from servobus.transports.contract import TransportStats

        return TransportStats()

    def send(self, frame: Frame, handle: object = None) -> None:
        now = self._time()
        self.sent.append((now, frame))
        if self._reporter is not None:
            self._reporter(frame if handle is None else handle, now, None)
        i, self._n = self._n, self._n + 1
        motor_id = frame.arbitration_id - 0x140
        if motor_id in self.silent or self.lose(i):
            return
        at = max(now + self.delay(i), self._last.get(motor_id, 0.0))
        self._last[motor_id] = at
        reply = _reply(frame, at)
        if self.garble(i):  # (a reply that does not decode: too short)
            reply = Frame(arbitration_id=reply.arbitration_id, data=reply.data[:3], timestamp=at)
        heapq.heappush(self._due, (at, i, reply))
        if self.duplicate(i):
            heapq.heappush(self._due, (at, i, reply))
        if self._wake is not None:
            self._wake.set()

    async def run(self) -> None:
        while True:
            if not self._due:
                self._wake = anyio.Event()
                await self._wake.wait()
                continue
            at = self._due[0][0]
            now = self._time()
            if at > now:
                self._wake = anyio.Event()
                with anyio.move_on_after(at - now):
                    await self._wake.wait()
                continue
            out = []
            while self._due and self._due[0][0] <= now:
                out.append(heapq.heappop(self._due)[2])
            if self._consumer is not None:
                self._consumer(out)

    def frames_of(self, code: int) -> list[tuple[float, Frame]]:
        return [(t, f) for t, f in self.sent if f.data[0] == code]


def _reply(frame: Frame, at: float) -> Frame:
    """A MyActuator motor's answer, ending on the wire ``at``: a SpeedControl's status says the
    commanded speed (whole dps); anything else is echoed (as 0x81's and 0x80's replies are)."""
    data = frame.data
    if data[0] == 0xA2:
        speed_dps = round(struct.unpack_from("<i", data, 4)[0] / 100)
        data = bytes([0xA2, 25, 0, 0]) + struct.pack("<hh", speed_dps, 0)
    return Frame(arbitration_id=frame.arbitration_id + 0x100, data=data, timestamp=at)


def _truth(state: MotorState) -> int:
    """The tick whose command the state's reply answers (see the module's docstring)."""
    return round(state.reply.speed_dps) + 1  # type: ignore[attr-defined]


async def _run(
    links: list[DelayLink],
    ticks: int,
    *,
    motors_per_bus: int = 2,
    body: Callable[[LoopTick, list[Any]], Any] | None = None,
    loop_options: dict[str, Any] | None = None,
    bus_options: dict[str, Any] | None = None,
) -> tuple[Loop, list[tuple[LoopTick, list[MotorState | None]]]]:
    """``ticks`` ticks over one Bus per link, each motor commanded the speed ``tick.index``; returns
    the loop and each tick with the states its body saw."""
    seen: list[tuple[LoopTick, list[MotorState | None]]] = []
    async with anyio.create_task_group() as group:
        for link in links:
            group.start_soon(link.run)
        buses = [Bus(link, name=f"bus{i}", **(bus_options or {})) for i, link in enumerate(links)]
        for bus in buses:
            await bus.__aenter__()
        try:
            motors = [bus.motor("myactuator", i) for bus in buses for i in range(1, motors_per_bus + 1)]
            async with Loop(HZ, **(loop_options or {})) as loop:
                async for tick in loop.ticks(count=ticks):
                    seen.append((tick, [tick.state(m) for m in motors]))
                    if body is not None:
                        await body(tick, motors)
                    for m in motors:
                        tick.command(m, ma.SpeedControl(speed_dps=float(tick.index)))
        finally:
            for bus in reversed(buses):
                await bus.__aexit__(None, None, None)
            group.cancel_scope.cancel()
    return loop, seen


def _check_attribution(seen: list[tuple[LoopTick, list[MotorState | None]]], exact: bool) -> int:
    """Every state answers its tick's command (``exact``) or an older one; its age is exact.
    Returns how many states were checked."""
    checked = 0
    starts = {tick.index: tick.started for tick, _ in seen}
    for tick, states in seen:
        for state in states:
            if state is None:
                continue
            checked += 1
            truth = _truth(state)
            if exact:
                assert state.tick == truth, (tick.index, state)
            else:
                assert state.tick <= truth, (tick.index, state)  # never younger than the truth
            assert state.age_ticks == tick.index - state.tick
            # (virtual time: every tick starts on its deadline, and its batch leaves then)
            assert abs(tick.late_s) < 1e-9
            assert math.isclose(state.age_s, tick.started - starts[state.tick], abs_tol=1e-9)
    return checked


@pytest.mark.parametrize("latency_ticks", [0.5, 1.0, 2.0, 3.0])
async def test_each_state_answers_the_tick_whose_command_left_with_its_exact_age(
    latency_ticks: float,
) -> None:
    links = [DelayLink(lambda i: latency_ticks * PERIOD) for _ in range(2)]
    loop, seen = await _run(links, 60)
    assert _check_attribution(seen, exact=True) > 4 * 40
    # A state as young as the latency allows: one that came at a deadline is seen at that tick or
    # the next (which of the two, the order of the loop's callbacks decides).
    for _, states in seen[10:]:
        for state in states:
            assert state is not None
            assert math.ceil(latency_ticks) <= state.age_ticks <= math.ceil(latency_ticks) + 1
            if latency_ticks % 1:  # (else a reply that comes at a deadline may be seen a tick later)
                assert state.fresh and state.age_ticks == math.ceil(latency_ticks)
    metrics = loop.metrics()
    assert metrics.ticks == 60 and metrics.lost == 0 and metrics.superseded == 0
    assert metrics.overruns == 0 and metrics.late_ticks == 0 and metrics.skipped == 0
    # (ticks 1..58's: the last one's are judged at a tick that never comes)
    assert metrics.commands_sent == 58 * 4
    assert metrics.commands_on_time == metrics.commands_sent
    assert metrics.state_age_max_s is not None
    assert metrics.state_age_max_s <= (math.ceil(latency_ticks) + 1) * PERIOD + 1e-9
    assert all(tick.sent == (4 if tick.index else 0) for tick, _ in seen)
    assert all(tick.commands_late == 0 for tick, _ in seen)


async def test_jitter_loss_and_a_silent_motor_never_make_a_state_younger_than_its_command() -> None:
    rng = random.Random(7)
    delays = [rng.uniform(0.5, 2.5) * PERIOD for _ in range(10_000)]
    lost = {i for i in range(10_000) if rng.random() < 0.05}
    links = [
        DelayLink(delays.__getitem__, lost.__contains__, silent=frozenset({2})),
        DelayLink(delays.__getitem__, lambda i: False),
    ]
    loop, seen = await _run(links, 300)
    assert _check_attribution(seen, exact=False) > 200
    silent = [states[1] for _, states in seen]
    assert silent == [None] * len(seen)
    # The lossless bus's states are exact.
    for _, states in seen:
        for state in states[2:]:
            assert state is None or state.tick == _truth(state)
    metrics = loop.metrics()
    # The silent motor's commands all end lost but those still within their horizon.
    quiet = next(
        track for motor, track in loop.tracks.items() if motor.motor_id == 2 and track.bus.name == "bus0"
    )
    # (offline after its misses, it gets a probe every probe_interval_s: not sent meanwhile)
    sent = len([f for _, f in links[0].frames_of(0xA2) if f.arbitration_id == 0x142])
    # (throttled: the window of unanswered commands is full until they end lost)
    assert 2 < sent < 100 and metrics.not_sent + metrics.throttled >= 299 - sent
    assert metrics.lost >= sent - len(quiet.fifo)
    assert len(quiet.fifo) < sent
    last = seen[-1][0]
    assert all(last.started - (r.sent_at or 0) <= 2 * r.timeout_s + PERIOD for _, r in quiet.fifo)
    assert metrics.stale_states >= 299  # the silent motor, every tick after its first command
    assert all(tick.stale >= 1 for tick, _ in seen[2:])


async def test_a_reply_later_than_its_deadline_is_never_taken_as_a_newer_commands() -> None:
    # Replies take 1.5 ticks, but those to requests 40..45 (ticks 21 to 23) take 5 ms, past their
    # 3 ms timeout (their requests time out) but within the 7 ms horizon: in order per motor, the
    # replies after them wait too, and are matched to the requests in flight after them.
    links = [DelayLink(lambda i: 0.005 if 40 <= i < 46 else 1.5 * PERIOD)]
    loop, seen = await _run(links, 120, loop_options={"timeout_s": 0.003})
    assert _check_attribution(seen, exact=True) > 200
    assert loop.metrics().lost == 0
    # After the episode the states are exact again (the pipeline drained through the lost ones).
    for _, states in seen[-20:]:
        for state in states:
            assert state is not None and state.tick == _truth(state)


async def test_a_duplicated_reply_is_not_taken_as_the_next_commands() -> None:
    # Every 7th reply arrives twice (a frame retransmitted), replies 2.5 ticks late.
    links = [DelayLink(lambda i: 2.5 * PERIOD, duplicate=lambda i: i % 7 == 3)]
    loop, seen = await _run(links, 80)
    assert _check_attribution(seen, exact=True) > 140
    assert loop.metrics().lost == 0
    bus_counts = sum(1 for _, f in links[0].sent if f.data[0] == 0xA2)
    assert bus_counts > 150


@pytest.mark.parametrize(("sleep_ticks", "shown_at", "skipped"), [(1.5, 11, 0), (2.5, 12, 1)])
async def test_an_overrun_is_counted_and_shown_on_the_next_tick(
    sleep_ticks: float, shown_at: int, skipped: int
) -> None:
    async def body(tick: LoopTick, motors: list[Any]) -> None:
        if tick.index == 10:
            await anyio.sleep(sleep_ticks * PERIOD)  # past tick 11's deadline

    links = [DelayLink(lambda i: 0.5 * PERIOD)]
    loop, seen = await _run(links, 30, body=body)
    assert [tick.index for tick, _ in seen if tick.overrun] == [shown_at]
    # (a tick whose time passed whole is skipped; the next starts half a period late)
    assert [(tick.index, tick.skipped) for tick, _ in seen if tick.skipped] == ([(12, 1)] if skipped else [])
    assert [tick.index for tick, _ in seen if tick.late_s > 1e-9] == [shown_at]
    metrics = loop.metrics()
    assert (metrics.overruns, metrics.skipped, metrics.late_ticks) == (1, skipped, 1)


async def test_a_command_still_queued_at_the_next_deadline_is_superseded_never_sent() -> None:
    # A half-duplex line, replies 2 ticks late: of two motors' commands one waits its turn, and the
    # next tick's command for that motor replaces it.
    link = DelayLink(lambda i: 2 * PERIOD, rules=LineRules(half_duplex=True))
    loop, seen = await _run([link], 40)
    metrics = loop.metrics()
    assert metrics.superseded > 10
    for t, frame in link.frames_of(0xA2):
        given = round(struct.unpack_from("<i", frame.data, 4)[0] / 100)
        # given in tick ``given``'s body, for tick given + 1: it may leave within that tick, and is
        # withdrawn at the next deadline, where the next one leaves (a reply that comes at that
        # deadline lets the line's next frame go first)
        assert t <= (given + 2) * PERIOD + 1e-9, (t, given)
    # (bodies 0..39 gave 80: the last body's never leave, the one before's are judged at no tick)
    assert 76 <= metrics.commands_sent + metrics.superseded + metrics.not_sent <= 78
    # (a tick whose commands did not all leave within it says so at the next)
    late = [tick for tick, _ in seen if tick.commands_late]
    # (ticks 1..38's commands, judged at ticks 2..39)
    assert late and sum(tick.commands_late for tick in late) == 38 * 2 - metrics.commands_on_time


async def test_a_refused_command_raises_before_any_frame_of_the_tick_leaves() -> None:
    links = [DelayLink(lambda i: 0.5 * PERIOD) for _ in range(2)]
    async with anyio.create_task_group() as group:
        for link in links:
            group.start_soon(link.run)
        async with Bus(links[0], name="a", safe=None) as a, Bus(links[1], name="b", safe=None) as b:
            m1, m2 = a.motor("myactuator", 1), b.motor("myactuator", 1)
            sent_before = -1
            with pytest.raises(ValueError, match="not a MyActuator command"):
                async with Loop(HZ) as loop:
                    async for tick in loop.ticks(count=10):
                        tick.command(m1, ma.SpeedControl(speed_dps=1.0))
                        if tick.index == 5:
                            tick.command(m2, lk.ReadStatus1())  # one its codec refuses
                            sent_before = len(links[0].sent) + len(links[1].sent)
            assert len(links[0].sent) + len(links[1].sent) == sent_before
        group.cancel_scope.cancel()


async def test_a_cancelled_loop_sends_the_safe_stop_to_every_motor_it_commanded() -> None:
    links = [DelayLink(lambda i: 2 * PERIOD) for _ in range(2)]
    async with anyio.create_task_group() as group:
        for link in links:
            group.start_soon(link.run)
        async with Bus(links[0], name="a") as a, Bus(links[1], name="b") as b:
            commanded = [a.motor("myactuator", 1), b.motor("myactuator", 2)]
            read = a.motor("myactuator", 3)  # only read by the loop: never commanded, never stopped
            with anyio.move_on_after(0.0205):
                async with Loop(HZ) as loop:
                    async for tick in loop:
                        for m in commanded:
                            tick.command(m, ma.SpeedControl(speed_dps=10.0))
                        tick.command(read, ma.ReadStatus2())
            stops_after_loop = [link.frames_of(0x81) for link in links]
            assert loop.tracks.keys() == {*commanded, read} and len(links[0].frames_of(0x9C)) > 10
            # ... and no stale command after the stop
            for link in links:
                ((stop_at, _),) = link.frames_of(0x81)
                assert all(t <= stop_at for t, _ in link.frames_of(0xA2))
        group.cancel_scope.cancel()
    assert [[f.arbitration_id for _, f in stops] for stops in stops_after_loop] == [[0x141], [0x142]]


async def test_a_clean_exit_leaves_the_motors_to_the_bus() -> None:
    link = DelayLink(lambda i: 0.5 * PERIOD)
    async with anyio.create_task_group() as group:
        group.start_soon(link.run)
        async with Bus(link, name="a") as a:
            m = a.motor("myactuator", 1)
            async with Loop(HZ) as loop:
                async for tick in loop:
                    tick.command(m, ma.SpeedControl(speed_dps=10.0))
                    if tick.index == 5:
                        break
            assert link.frames_of(0x81) == []
        assert len(link.frames_of(0x81)) == 1  # the Bus's own exit
        group.cancel_scope.cancel()


async def test_a_motor_without_a_command_gets_no_frame_and_its_state_ages() -> None:
    link = DelayLink(lambda i: 0.5 * PERIOD)
    seen: list[tuple[int, MotorState | None]] = []
    async with anyio.create_task_group() as group:
        group.start_soon(link.run)
        async with Bus(link, name="a", safe=None) as bus:
            m = bus.motor("myactuator", 1)
            async with Loop(HZ) as loop:
                async for tick in loop.ticks(count=20):
                    seen.append((tick.index, tick.state(m)))
                    if tick.index < 5:  # commanded in ticks 0..4: its commands leave at 1..5
                        tick.command(m, ma.SpeedControl(speed_dps=float(tick.index)))
        group.cancel_scope.cancel()
    assert len(link.frames_of(0xA2)) == 5
    last = [(index, state) for index, state in seen if index >= 7]
    for index, state in last:
        assert state is not None and state.tick == 5 and _truth(state) == 5
        assert state.age_ticks == index - 5 and state.fresh is (index == 6)
    metrics = loop.metrics()
    assert metrics.stale_states == 20 - 7 and metrics.lost == 0  # (ticks 7..19: no reply since)


def test_the_loop_is_exported_by_the_package() -> None:
    import servobus
    import servobus.loop

    assert servobus.Loop is servobus.loop.Loop and "Loop" in servobus.__all__


async def test_another_callers_late_reply_is_not_taken_as_one_of_the_loops() -> None:
    # Beside the loop, a read of the same motor times out (0.5 ms) before its reply (1.5 ticks):
    # that late reply has another key, and must not answer one of the loop's commands.
    link = DelayLink(lambda i: 1.5 * PERIOD)

    async def body(tick: LoopTick, motors: list[Any]) -> None:
        if tick.index in (10, 20, 30):
            with pytest.raises(MotorTimeout):
                await motors[0].request(ma.ReadStatus1(), timeout_s=0.0005)

    loop, seen = await _run([link], 50, body=body)
    assert len(link.frames_of(0x9A)) == 3
    assert _check_attribution(seen, exact=True) > 80
    assert loop.metrics().lost == 0


async def test_a_reply_that_does_not_decode_takes_its_place_in_the_order() -> None:
    links = [DelayLink(lambda i: 1.5 * PERIOD, garble=lambda i: i in (30, 31, 50))]
    loop, seen = await _run(links, 60)
    assert _check_attribution(seen, exact=True) > 90
    assert loop.metrics().lost == 0


async def test_a_tick_shows_the_states_as_of_its_start_while_its_body_awaits() -> None:
    # Replies take half a tick: this tick's own reply comes while the body sleeps 0.8 of a period.
    before_after: list[tuple[MotorState | None, MotorState | None]] = []

    async def body(tick: LoopTick, motors: list[Any]) -> None:
        if tick.index in (10, 11, 12):
            before = tick.state(motors[0])
            await anyio.sleep(0.8 * PERIOD)
            before_after.append((before, tick.state(motors[0])))

    links = [DelayLink(lambda i: 0.5 * PERIOD)]
    await _run(links, 20, body=body)
    assert len(before_after) == 3
    for before, after in before_after:
        assert before is not None and after == before and after.age_ticks == 1


async def test_a_second_iteration_goes_on_on_the_same_grid() -> None:
    link = DelayLink(lambda i: 0.5 * PERIOD)
    indices: list[list[int]] = []
    async with anyio.create_task_group() as group:
        group.start_soon(link.run)
        async with Bus(link, name="a", safe=None) as bus:
            m = bus.motor("myactuator", 1)
            async with Loop(HZ) as loop:
                for count in (3, None, 2):
                    run: list[int] = []
                    async for tick in loop.ticks(count=count):
                        run.append(tick.index)
                        tick.command(m, ma.SpeedControl(speed_dps=float(tick.index)))
                        if count is None and tick.index == 5:
                            break
                    indices.append(run)
                    await anyio.sleep(2.5 * PERIOD)  # (two ticks' time passes between runs)
        group.cancel_scope.cancel()
    # (each pause of 2.5 periods skips one tick whole and makes the next late; the time between
    # two iterations counts as the last body's: an overrun)
    assert indices == [[0, 1, 2], [4, 5], [7, 8]]
    metrics = loop.metrics()
    assert (metrics.ticks, metrics.skipped, metrics.overruns, metrics.late_ticks) == (7, 2, 2, 2)


async def test_drop_takes_back_the_commands_of_a_motor_that_have_not_left() -> None:
    """What a stop from elsewhere needs: the set-point the body gave for the next deadline is not
    sent after the stop (Loop.drop; counted superseded); the other motors' commands leave."""
    from servobus.protocols.myactuator.sim.device import MyActuatorMotor
    from servobus.sim.plant import SpeedControl
    from servobus.transports.sim import SimTransport

    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    async with Bus(SimTransport(devices=devices), safe=None) as bus:
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        loop = Loop(100)
        async with loop:
            async for tick in loop.ticks(3):
                if tick.index == 0:
                    tick.command(one, ma.SpeedControl(speed_dps=30.0))
                    tick.command(two, ma.SpeedControl(speed_dps=30.0))
                    assert loop.drop([one]) == 1 and loop.drop([one]) == 0
        await anyio.sleep(0.02)
    assert not isinstance(devices[0].control, SpeedControl) and isinstance(devices[1].control, SpeedControl)
    assert loop.metrics().superseded == 1

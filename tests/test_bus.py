"""servobus.Bus and Motor over the in-process simulated bus, on asyncio and trio in virtual time (no
real clock): anyio's pytest plugin runs each test on both."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus, command_classes
from servobus.errors import MotorTimeout, TransportError
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import Traffic
from servobus.transports.sim import SimTransport
from sim._standins import Sniffer

pytestmark = pytest.mark.anyio


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


async def _until(condition: Callable[[], object]) -> None:
    """Let the other tasks run until ``condition()`` holds (a task started is on its way)."""
    while not condition():
        await anyio.sleep(0)


def _motors(n: int = 4) -> list[MyActuatorMotor]:
    return [MyActuatorMotor(m) for m in range(1, n + 1)]


async def test_a_motor_command_returns_its_typed_reply() -> None:
    async def scenario() -> tuple[Any, Any, float]:
        async with Bus(SimTransport(devices=_motors(1))) as bus:
            motor = bus.motor("myactuator", 1)
            start = anyio.current_time()
            status = await motor.read_status2()
            speed = await motor.speed_control(speed_dps=90.0)
            return status, speed, anyio.current_time() - start

    status, speed, elapsed = await scenario()
    assert isinstance(status, ma.StatusReply) and status.command is ma.StatusCommand.READ_STATUS_2
    assert isinstance(speed, ma.StatusReply) and speed.command is ma.StatusCommand.SPEED_CONTROL
    assert elapsed < 0.002  # two exchanges at 1 Mbit/s with the simulator's turnaround


async def test_a_cycle_returns_every_reply_in_order_and_a_silent_motor_only_costs_its_own() -> None:
    motors = _motors(32)
    motors[4].unresponsive = True

    async def scenario() -> list[Any]:
        async with Bus(SimTransport(devices=motors)) as bus:
            handles = [bus.motor("myactuator", m) for m in range(1, 33)]
            return await bus.cycle([(h, ma.ReadStatus2()) for h in handles])

    results = await scenario()
    assert len(results) == 32
    assert isinstance(results[4], MotorTimeout) and "myactuator motor 5 ReadStatus2" in str(results[4])
    assert all(isinstance(r, ma.StatusReply) for i, r in enumerate(results) if i != 4)


async def test_each_request_of_a_cycle_has_its_own_observable_outcome() -> None:
    motors = _motors(3)
    motors[1].unresponsive = True

    async def scenario() -> tuple[list[Any], list[tuple[bool, Any]], list[Any]]:
        async with Bus(SimTransport(devices=motors)) as bus:
            handles = [bus.motor("myactuator", m) for m in (1, 2, 3)]
            seen: list[tuple[bool, Any]] = []
            make = bus.scheduler.request

            def request(*args: Any, **kwargs: Any) -> Any:
                made = make(*args, **kwargs)
                made.context.add_done_callback(lambda c: seen.append((c.cancelled(), c.exception())))
                return made

            bus.scheduler.request = request  # type: ignore[method-assign]
            results = await bus.cycle([(h, ma.ReadStatus2()) for h in handles], timeout_s=0.01)
            await anyio.sleep(0)  # (done callbacks run soon after, as a future's)
            return results, seen, await bus.cycle([])

    results, seen, empty = await scenario()
    assert [type(r) for r in results] == [ma.StatusReply, MotorTimeout, ma.StatusReply]
    assert sorted((c, type(e).__name__) for c, e in seen) == [
        (False, "MotorTimeout"),
        (False, "NoneType"),
        (False, "NoneType"),
    ]
    assert empty == []


async def test_a_cancelled_cycle_cancels_its_requests_and_leaves_nothing_pending() -> None:
    async def scenario() -> tuple[int, dict[str, int]]:
        async with Bus(SimTransport(devices=_motors(4)), safe=None) as bus:
            handles = [bus.motor("myactuator", m) for m in range(1, 5)]
            ended: list[str] = []

            async def cycle() -> None:
                try:
                    await bus.cycle([(h, ma.ReadStatus2()) for h in handles])
                except anyio.get_cancelled_exc_class():
                    ended.append("cancelled")
                    raise

            async with anyio.create_task_group() as group:
                group.start_soon(cycle)
                await _until(lambda: bus.scheduler.pending)  # the frames are on their way
                group.cancel_scope.cancel()
            assert ended == ["cancelled"]
            pending = bus.scheduler.pending
            await anyio.sleep(0.01)  # the replies arrive, late
            assert all(
                isinstance(r, ma.StatusReply)
                for r in await bus.cycle([(h, ma.ReadStatus2()) for h in handles])
            )
            return pending, bus.stats()

    pending, stats = await scenario()
    assert pending == 0 and stats["replies"] == 4 and stats["late"] + stats["replies"] == 8


async def test_a_timeout_names_motor_command_and_time() -> None:
    motor = MyActuatorMotor(1)
    motor.unresponsive = True

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[motor])) as bus:
            await bus.motor("myactuator", 1).read_status2(timeout_s=0.05)

    with pytest.raises(MotorTimeout, match=r"myactuator motor 1 ReadStatus2: no reply within 50 ms"):
        await scenario()


async def test_a_cancelled_request_leaves_nothing_pending_and_its_reply_is_counted_late() -> None:
    async def scenario() -> dict[str, int]:
        async with Bus(SimTransport(devices=_motors(1)), safe=None) as bus:
            motor = bus.motor("myactuator", 1)

            async def read() -> None:
                await motor.read_status2()

            async with anyio.create_task_group() as group:
                group.start_soon(read)
                await _until(lambda: bus.scheduler.pending)  # the frame is on the wire now
                group.cancel_scope.cancel()
            assert bus.scheduler.pending == 0
            await anyio.sleep(0.01)  # the reply arrives
            later = await motor.read_status2()  # and never answers a later request
            assert isinstance(later, ma.StatusReply)
            return bus.stats()

    stats = await scenario()
    assert stats["late"] == 1 and stats["replies"] == 1


def _stops(sniffer: Sniffer, code: int = 0x81) -> set[int]:
    """The motors a request with command byte ``code`` went to (requests only: 0x141..0x160)."""
    return {
        f.arbitration_id - 0x140
        for _, f in sniffer.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == bytes([code])
    }


async def test_an_exception_in_the_block_stops_every_commanded_motor() -> None:
    sniffer = Sniffer()

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[*_motors(4), sniffer])) as bus:
            for m in (1, 2, 3):
                await bus.motor("myactuator", m).speed_control(speed_dps=30.0)
            await bus.motor("myactuator", 4).read_status2()  # only read: not commanded
            raise RuntimeError("user code failed")

    with pytest.raises(RuntimeError, match="user code failed"):
        await scenario()
    assert _stops(sniffer) == {1, 2, 3}


async def test_the_bus_says_which_motors_it_commanded_and_which_got_the_safe_command() -> None:
    async def scenario(safe: str | None) -> tuple[list[int], list[int]]:
        async with Bus(SimTransport(devices=_motors(3)), safe=safe) as bus:
            for m in (1, 3):
                await bus.motor("myactuator", m).speed_control(speed_dps=30.0)
            await bus.motor("myactuator", 2).read_status2()
            assert bus.safe_sent == ()
        return [m.motor_id for m in bus.commanded], [m.motor_id for m in bus.safe_sent]

    assert await scenario("stop") == ([1, 3], [1, 3])
    assert await scenario(None) == ([1, 3], [])


async def test_cancellation_stops_every_commanded_motor_too() -> None:
    sniffer = Sniffer()

    async def scenario() -> None:
        async def control() -> None:
            async with Bus(SimTransport(devices=[*_motors(2), sniffer]), safe="shutdown") as bus:
                for m in (1, 2):
                    await bus.motor("myactuator", m).torque_control(current_a=0.5)
                await anyio.sleep(10)

        with anyio.move_on_after(1) as scope:
            await control()
        assert scope.cancelled_caught

    await scenario()
    assert _stops(sniffer, 0x80) == {1, 2}


async def test_leaving_the_block_fails_what_is_pending_and_nothing_follows_the_safe_stop() -> None:
    """A task the block did not wait for keeps commanding: its set-points must not reach the motor
    after the safe stop, and its pending request must end (TransportError), not hang."""
    sniffer = Sniffer()
    silent = MyActuatorMotor(2)
    silent.unresponsive = True

    async def scenario() -> tuple[BaseException | None, BaseException | None]:
        async def control(motor: Any) -> None:
            while True:
                await motor.speed_control(speed_dps=30.0)

        transport = SimTransport(devices=[*_motors(1), silent, sniffer])
        await transport.open()  # the user's: the Bus leaves it open
        errors: dict[str, BaseException] = {}

        async def keep(name: str, call: Callable[[], Awaitable[object]]) -> None:
            try:
                await call()
            except Exception as exc:
                errors[name] = exc

        with anyio.move_on_after(1.0):
            # (tasks the Bus's block does not wait for)
            async with anyio.create_task_group() as group, Bus(transport) as bus:
                group.start_soon(keep, "loop", lambda: control(bus.motor("myactuator", 1)))
                group.start_soon(
                    keep, "waiting", lambda: bus.motor("myactuator", 2).read_status2(timeout_s=5.0)
                )
                await anyio.sleep(0.01)
        await transport.close()
        return errors.get("loop"), errors.get("waiting")

    loop_error, waiting_error = await scenario()
    assert isinstance(loop_error, TransportError) and "closed" in str(loop_error)
    assert isinstance(waiting_error, TransportError) and "closed" in str(waiting_error)
    to_motor_1 = [f.data[0] for _, f in sniffer.seen if f.arbitration_id == 0x141]
    assert to_motor_1[-1] == 0x81 and to_motor_1.count(0x81) == 1, to_motor_1[-5:]


async def test_out_of_range_values_raise_before_anything_is_sent() -> None:
    sniffer = Sniffer()

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[*_motors(1), sniffer]), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            with pytest.raises(ValueError, match="speed_dps"):
                await motor.speed_control(speed_dps=1e12)
            with pytest.raises(ValueError, match="motor_id"):
                await bus.cycle([(motor, ma.ReadStatus2()), (motor, ma.SetCanId(motor_id=40))])

    await scenario()
    assert sniffer.seen == []


async def test_every_family_through_one_bus() -> None:
    devices = [MyActuatorMotor(1), LkMotor(9), HollowMotor(20)]

    async def scenario() -> list[Any]:
        async with Bus(SimTransport(devices=devices)) as bus:
            return await bus.cycle(
                [
                    (bus.motor("myactuator", 1), ma.ReadMultiTurnAngle()),
                    (bus.motor("lk", 9), lk.ReadStatus2()),
                    (
                        bus.motor("hollow", 20),
                        ho.Setpoint(position_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=0.0),
                    ),
                ]
            )

    angle, status, hollow_reply = await scenario()
    assert isinstance(angle, ma.MultiTurnAngleReply)
    assert isinstance(status, lk.Status2Reply)
    assert isinstance(hollow_reply, ho.NormalReply) and hollow_reply.motor_id == 20


async def test_motors_that_collide_are_refused_with_both_named() -> None:
    async def scenario() -> None:
        async with Bus(SimTransport(devices=[])) as bus:
            bus.motor("myactuator", 1)
            bus.motor("lk", 1, revision="V2_35")

    with pytest.raises(ValueError, match=r"myactuator motor 1 .* lk motor 1"):
        await scenario()


async def test_a_broadcast_gathers_each_motors_reply() -> None:
    async def scenario() -> dict[int, Any]:
        async with Bus(SimTransport(devices=_motors(4))) as bus:
            handles = [bus.motor("myactuator", m) for m in range(1, 5)]
            return await bus.broadcast(ma.ReadStatus2(), handles)

    results = await scenario()
    assert sorted(results) == [1, 2, 3, 4] and all(isinstance(r, ma.StatusReply) for r in results.values())


async def test_a_broadcast_after_a_timeout_gets_the_reply_and_sends_only_its_frame() -> None:
    """A motor that missed one broadcast (its key held for a late reply) answers the next: that reply
    is its result, and nothing but the broadcast frames goes out (no request's placeholder frame)."""
    motors = _motors(2)
    sniffer = Sniffer()

    async def scenario() -> list[dict[int, Any]]:
        async with Bus(SimTransport(devices=[*motors, sniffer]), safe=None) as bus:
            handles = [bus.motor("myactuator", m) for m in (1, 2)]
            motors[1].unresponsive = True
            first = await bus.broadcast(ma.ReadStatus2(), handles)
            motors[1].unresponsive = False
            second = await bus.broadcast(ma.ReadStatus2(), handles)
            assert bus.scheduler.pending == 0
            return [first, second]

    first, second = await scenario()
    assert isinstance(first[2], MotorTimeout)
    assert all(isinstance(r, ma.StatusReply) for r in second.values()), second
    sent = [f.arbitration_id for _, f in sniffer.seen if not 0x241 <= f.arbitration_id <= 0x260]
    assert sent == [0x280, 0x280]


async def test_state_and_subscribers_see_stream_frames() -> None:
    async def scenario() -> tuple[list[Traffic], Any]:
        seen: list[Traffic] = []
        async with Bus(SimTransport(devices=_motors(1)), safe=None) as bus:
            bus.subscribe(lambda motor, traffic, reply: seen.append(traffic))
            motor = bus.motor("myactuator", 1)
            await motor.request(
                ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10)
            )
            await anyio.sleep(0.1)
            read = await motor.read_status2()  # answered by the next stream frame
            await motor.request(
                ma.ActiveReply(command=ma.StreamableCommand(0x9C), enabled=False, interval_ms=None)
            )
            return seen, read

    seen, read = await scenario()
    assert seen.count(Traffic.STREAM) >= 9 and isinstance(read, ma.StatusReply)


async def test_a_lost_transport_fails_what_is_pending_at_once() -> None:
    motor = MyActuatorMotor(1)
    motor.unresponsive = True
    transport = SimTransport(devices=[motor], reopen=False)

    async def unplug() -> None:
        await anyio.sleep(0.01)
        transport.unplug()

    async with Bus(transport, safe=None) as bus, anyio.create_task_group() as group:
        group.start_soon(unplug)
        with pytest.raises(TransportError, match="lost"):
            await bus.motor("myactuator", 1).read_status2(timeout_s=5.0)
        assert anyio.current_time() < 0.1  # at once, not after its 5 s


def test_command_classes_are_the_motor_methods_by_name() -> None:
    classes = command_classes("myactuator")
    assert classes["read_status2"] is ma.ReadStatus2 and classes["speed_control"] is ma.SpeedControl
    assert command_classes("lk")["read_multi_turn_angle"] is lk.ReadMultiTurnAngle


async def test_unknown_commands_are_an_attribute_error() -> None:
    async def scenario() -> None:
        async with Bus(SimTransport(devices=[])) as bus:
            motor = bus.motor("lk", 2)
            assert "read_status2" in dir(motor)
            motor.fly_to_the_moon  # noqa: B018

    with pytest.raises(AttributeError, match="lk motors have no command 'fly_to_the_moon'"):
        await scenario()


async def test_a_motors_stream_frames_come_through_a_bounded_iterator() -> None:
    async def scenario() -> tuple[list[Any], int, int]:
        async with Bus(SimTransport(devices=_motors(1)), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            async with motor.frames(size=4) as frames:
                await motor.active_reply(command=ma.StreamableCommand(0x9C), enabled=True, interval_ms=10)
                got = [await frames.__anext__() for _ in range(3)]
                await anyio.sleep(0.1)  # ten more frames come; only the newest four are kept
                kept = len(frames._items)
                dropped = frames.dropped
            await motor.active_reply(command=ma.StreamableCommand(0x9C), enabled=False, interval_ms=None)
            return got, kept, dropped

    got, kept, dropped = await scenario()
    assert all(isinstance(r, ma.StatusReply) for r in got)
    assert kept == 4 and dropped >= 5


async def test_motor_commands_take_their_fields_by_position_in_declaration_order() -> None:
    sniffer = Sniffer()

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[*_motors(1), sniffer])) as bus:
            motor = bus.motor("myactuator", 1)
            await motor.set_comm_timeout(100)
            await motor.speed_control(45.0, 50, timeout_s=0.1)
            with pytest.raises(TypeError, match="positional arguments but 4 were given"):
                await motor.speed_control(1.0, 2, 3)
            with pytest.raises(TypeError, match="multiple values for argument 'speed_dps'"):
                await motor.speed_control(1.0, speed_dps=2.0)

    await scenario()
    sent = [f.data for _, f in sniffer.seen if f.arbitration_id == 0x141]
    assert sent[:2] == [  # then the safe stop on leaving the block
        ma.SetCommTimeout(timeout_ms=100).encode(),
        ma.SpeedControl(speed_dps=45.0, max_torque_pct=50).encode(),
    ]


class _AsyncCallable:
    async def __call__(self, *args: object) -> None:
        raise AssertionError("never awaited")


async def test_an_async_subscriber_is_refused_with_a_clear_type_error() -> None:
    async def on_reply(*args: object) -> None:
        raise AssertionError("never awaited")

    async def scenario() -> None:
        async with Bus(SimTransport(devices=_motors(1))) as bus:
            for callback in (on_reply, _AsyncCallable()):
                with pytest.raises(TypeError, match="subscribe\\(\\) takes a plain function"):
                    bus.subscribe(callback)
                with pytest.raises(TypeError, match="subscribe_status\\(\\) takes a plain function"):
                    bus.subscribe_status(callback)
            heard: list[object] = []
            bus.subscribe(lambda motor, traffic, reply: heard.append(reply))  # a plain one still works
            await bus.motor("myactuator", 1).read_status2()
            assert len(heard) == 1

    await scenario()


@pytest.mark.parametrize(
    ("owner_backend", "caller_backend"), [("asyncio", "asyncio"), ("trio", "asyncio"), ("asyncio", "trio")]
)
def test_a_bus_used_from_another_event_loop_says_so_at_once_and_logs_no_traceback(
    caplog: pytest.LogCaptureFixture, owner_backend: str, caller_backend: str
) -> None:
    """A Bus entered in a thread's own loop, called from a coroutine on another loop: request(),
    cycle() and broadcast() raise one clear RuntimeError before anything is queued (it used to
    be asyncio's "attached to a different loop", and the request's future, never awaited, was
    logged as "Future exception was never retrieved" with its traceback when the block was left)."""
    import gc
    import threading

    device = MyActuatorMotor(1)
    device.unresponsive = True  # (a request let through fails when the block is left)
    entered, leave = threading.Event(), threading.Event()
    box: dict[str, Bus] = {}

    async def owner() -> None:
        async with Bus(SimTransport(devices=[device])) as bus:
            box["bus"] = bus
            entered.set()
            while not leave.is_set():
                await anyio.sleep(0.002)

    thread = threading.Thread(target=anyio.run, args=(owner,), kwargs={"backend": owner_backend})
    thread.start()
    assert entered.wait(10)
    bus = box["bus"]
    motor = bus.motor("myactuator", 1)
    calls: list[Callable[[], Awaitable[Any]]] = [
        lambda: motor.read_status2(),
        lambda: motor.request(ma.ReadStatus2()),
        lambda: bus.cycle([(motor, ma.ReadStatus2())]),
        lambda: bus.broadcast(ma.ReadStatus2(), [motor]),
    ]

    async def elsewhere() -> list[str]:
        errors = []
        for call in calls:
            with pytest.raises(RuntimeError) as caught:
                await call()
            errors.append(str(caught.value))
        return errors

    try:
        with caplog.at_level("ERROR"):
            errors = anyio.run(elsewhere, backend=caller_backend)
            assert bus.scheduler.pending == 0  # nothing went in
    finally:
        leave.set()
        thread.join(10)
    gc.collect()
    for error in errors:
        assert error.startswith("sim: this Bus runs on another event loop"), error
        assert "use servobus.sync.Bus from other threads" in error
    assert not [r for r in caplog.records if r.levelname == "ERROR"], caplog.text


async def test_an_error_in_the_bus_s_own_task_is_raised_from_its_block_not_lost() -> None:
    """The Bus's timer task runs in the Bus's task group: a bug there cancels the block (after its
    safe stop) and is raised when the block is left."""
    device = MyActuatorMotor(1)
    device.unresponsive = True
    sniffer = Sniffer()
    with pytest.raises(BaseExceptionGroup) as caught:
        async with Bus(SimTransport(devices=[device, MyActuatorMotor(2), sniffer])) as bus:
            await bus.motor("myactuator", 2).speed_control(speed_dps=10.0)

            def broken(now: float | None = None) -> None:
                raise ZeroDivisionError("a bug in the timer")

            bus.engine.on_timer = broken  # type: ignore[method-assign]
            await bus.motor("myactuator", 1).read_status2(timeout_s=0.01)  # its timeout fires the timer
    assert [type(e) for e in caught.value.exceptions] == [ZeroDivisionError]
    assert _stops(sniffer) == {2}  # the safe stop went out all the same

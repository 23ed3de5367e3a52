"""Safety: what happens when the control task dies or stalls, how fast the host sees a motor go
silent, and that out-of-range commands never leave. (SIGTERM: tests/test_signals.py.)

All on the in-process bus, on asyncio and trio in virtual time: a passive node records every frame
on the wire.
"""

from __future__ import annotations

import contextlib

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus, MotorStatus
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.network import SimCanNetwork
from servobus.transports import SimTransport
from sim._standins import Sniffer

COMM_TIMEOUT_MS = 100

pytestmark = pytest.mark.anyio


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


def _bench(n: int = 2) -> tuple[SimTransport, list[MyActuatorMotor], Sniffer]:
    motors = [MyActuatorMotor(i) for i in range(1, n + 1)]
    sniffer = Sniffer()
    return SimTransport(SimCanNetwork([*motors, sniffer])), motors, sniffer


@pytest.mark.parametrize("how", ["dies", "stalls"])
async def test_when_the_control_task_dies_or_stalls_the_motor_side_timeout_stops_the_motor(how: str) -> None:
    """0xB3 set to 100 ms; a 100 Hz speed loop runs, then dies (an exception) or stalls (blocks on
    something that never comes) while the Bus stays open: no frame reaches the motor, and within
    100 ms of the last one the motor cuts its output, locks the brake and slows to a stop."""
    transport, (motor, other), _ = _bench()
    async with transport, Bus(transport, safe=None) as bus:
        m = bus.motor("myactuator", 1)
        await m.request(ma.SetCommTimeout(timeout_ms=COMM_TIMEOUT_MS))
        never = anyio.Event()

        async def control() -> None:
            for _i in range(50):
                await m.speed_control(speed_dps=360)
                await anyio.sleep(0.01)
            if how == "dies":
                raise RuntimeError("the control task's bug")
            await never.wait()

        died: list[BaseException] = []

        async def watched() -> None:
            try:
                await control()
            except RuntimeError as exc:
                died.append(exc)

        group = anyio.create_task_group()
        await group.__aenter__()
        group.start_soon(watched)
        await anyio.sleep(0.6)
        assert not motor.comm_tripped and motor.plant.speed_dps > 300  # running while commanded
        last = motor._last_heard_s
        if how == "dies":
            assert [str(e) for e in died] == ["the control task's bug"]
        await anyio.sleep(0.5)
        motor.advance(
            transport.network_time(anyio.current_time())
        )  # the plant is integrated lazily: bring it up
        assert motor.comm_tripped and motor.counters["comm_timeouts"] == 1
        assert not motor.enabled and not motor.brake_released
        assert abs(motor.plant.speed_dps) < 1.0
        assert other.counters["comm_timeouts"] == 0  # 0xB3 was set on motor 1 only
        # It tripped 100 ms after the last frame it heard (its own clock, in the network's time).
        assert transport.loop_time(last) + COMM_TIMEOUT_MS / 1000 <= anyio.current_time()
        group.cancel_scope.cancel()
        await group.__aexit__(None, None, None)


async def test_host_side_offline_detection_fires_within_its_configured_time() -> None:
    """Two watchdogs: ``offline_after_misses`` missed replies in a row (a polled motor), and
    ``offline_after_s`` of silence (a motor that was heard and then is not). Each fires within its
    own bound of the moment the motor stopped answering, and the motor is online at its next reply."""
    transport, (motor, _other), _ = _bench()
    statuses: list[MotorStatus] = []
    # (late_hold_s: each poll goes out 10 ms after the last timed out, not after the hold a motor
    # measured a few times gets, twice the codec's 20 ms)
    async with (
        transport,
        Bus(transport, offline_after_misses=3, offline_after_s=0.2, late_hold_s=0.01) as bus,
    ):
        bus.subscribe_status(statuses.append)
        m1, m2 = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        await m1.read_status1()
        await m2.read_status1()
        assert m1.online and m2.online
        # Motor 1 stops answering while it is polled every 10 ms with a 10 ms timeout.
        motor.unresponsive = True
        silent_at = anyio.current_time()

        async def poll() -> None:
            while True:
                with contextlib.suppress(Exception):
                    await m1.read_status2(timeout_s=0.01)
                await anyio.sleep(0.01)

        poller = anyio.create_task_group()
        await poller.__aenter__()
        poller.start_soon(poll)
        await anyio.sleep(0.3)
        # Motor 2 is simply not asked any more: only the silence watchdog can see it.
        offline = {s.motor.motor_id: s for s in statuses if not s.online}
        assert set(offline) == {1, 2}
        assert offline[1].reason == "3 replies missed"
        assert offline[1].at - silent_at <= 3 * 0.02 + 0.01  # three polls, each a 10 ms timeout
        assert offline[2].reason == "silent for 200 ms"
        assert offline[2].at - m2.last_seen <= 0.2 + 1e-6  # type: ignore[operator]
        motor.unresponsive = False
        await anyio.sleep(0.05)
        assert m1.online and statuses[-1].motor is m1 and statuses[-1].online
        poller.cancel_scope.cancel()
        await poller.__aexit__(None, None, None)


async def test_limits_are_enforced_before_any_frame_leaves() -> None:
    """An out-of-range set-point raises ValueError naming the field and its limit, and nothing goes
    on the wire; a cycle with one bad command sends none of its commands."""
    transport, _, sniffer = _bench()
    async with transport, Bus(transport, safe=None) as bus:
        m1, m2 = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        before = len(sniffer.seen)
        with pytest.raises(ValueError, match="speed_dps"):
            await m1.speed_control(speed_dps=1e9)
        with pytest.raises(ValueError):
            await m1.request(ma.SetCommTimeout(timeout_ms=0))
        with pytest.raises(ValueError, match="speed_dps"):
            await bus.cycle([(m1, ma.SpeedControl(speed_dps=10)), (m2, ma.SpeedControl(speed_dps=-1e12))])
        await anyio.sleep(0.05)
        assert sniffer.seen[before:] == []
        assert bus.stats().get("requests", 0) == 0
        await m1.speed_control(speed_dps=10)  # a good one still goes
        assert len(sniffer.seen) == before + 2


def _stops(sniffer: Sniffer, code: int = 0x81) -> set[int]:
    """The motors a request with command byte ``code`` went to (requests only: 0x141..0x160)."""
    return {
        f.arbitration_id - 0x140
        for _, f in sniffer.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == bytes([code])
    }


class _TaskClockSim(SimTransport):
    task_clock = True  # (its clock is a task of the link on asyncio too, as on trio)


@pytest.mark.parametrize("opener", ["bus", "user", "user, clock task"])
@pytest.mark.parametrize("how", ["exception", "cancelled", "cancelled while waiting"])
async def test_a_bus_left_by_an_exception_or_a_cancellation_stops_its_motors(how: str, opener: str) -> None:
    """Left by the block's exception, by the cancellation of the scope around it (its deadline),
    or by that cancellation while a request waits for its reply: every commanded motor gets the
    safe command and acknowledges it, and the block's exception goes on as it was. The same when
    the user opened the link around the Bus: the cancellation does not take the link's tasks (its
    clock, on the task lane) away before the safe stop went out and was answered."""
    motors = [MyActuatorMotor(i) for i in (1, 2, 3)]
    motors[2].unresponsive = True  # (for "cancelled while waiting")
    sniffer = Sniffer()
    kind = _TaskClockSim if opener.endswith("task") else SimTransport
    transport = kind(SimCanNetwork([*motors, sniffer]))
    with anyio.move_on_after(1.0) as scope, contextlib.suppress(RuntimeError):
        async with contextlib.AsyncExitStack() as stack:
            if opener != "bus":
                await stack.enter_async_context(transport)
            bus = await stack.enter_async_context(Bus(transport))
            for m in (1, 2):
                await bus.motor("myactuator", m).speed_control(speed_dps=90)
            if how == "exception":
                raise RuntimeError("the control task's bug")
            if how == "cancelled":
                await anyio.sleep_forever()
            await bus.motor("myactuator", 3).read_status2(timeout_s=10.0)
    assert scope.cancelled_caught == (how != "exception")
    assert _stops(sniffer) == {1, 2}
    assert [m.motor_id for m in bus.safe_acknowledged] == [1, 2]
    assert not transport.is_open

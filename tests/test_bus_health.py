"""The Bus's watchdogs (host side, and the motor's own 0xB3), streams and metrics, on asyncio and trio
in virtual time."""

from __future__ import annotations

from collections.abc import Awaitable
from typing import Any

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus, MotorStatus
from servobus.errors import MotorFault, MotorTimeout, TransportError
from servobus.metrics import LatencyWindow
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.ticks import ticks
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


async def _into(box: list[Any], call: Awaitable[Any]) -> None:
    box.append(await call)


def _events(bus: Bus) -> list[MotorStatus]:
    seen: list[MotorStatus] = []
    bus.subscribe_status(seen.append)
    return seen


def _brief(events: list[MotorStatus]) -> list[tuple[int, bool, str]]:
    return [(s.motor.motor_id, s.online, s.reason) for s in events]


async def test_a_motor_that_misses_replies_goes_offline_and_comes_back_when_it_answers() -> None:
    device = MyActuatorMotor(1)

    async def scenario() -> tuple[list[MotorStatus], list[bool | None]]:
        async with Bus(SimTransport(devices=[device]), offline_after_misses=2) as bus:
            events = _events(bus)
            motor = bus.motor("myactuator", 1)
            states = [motor.online]
            await motor.read_status1()
            states.append(motor.online)
            device.unresponsive = True
            for _ in range(2):
                with pytest.raises(MotorTimeout):
                    await motor.read_status1(timeout_s=0.01)
                states.append(motor.online)
            device.unresponsive = False
            await motor.read_status1()
            states.append(motor.online)
            return events, states

    events, states = await scenario()
    assert states == [None, True, True, False, True]
    assert _brief(events) == [(1, True, "answered"), (1, False, "2 replies missed"), (1, True, "answered")]


async def test_a_silent_motor_goes_offline_after_the_silence_limit_and_only_then() -> None:
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]

    async def scenario() -> tuple[list[MotorStatus], float, float]:
        async with Bus(SimTransport(devices=devices), offline_after_s=0.5) as bus:
            events = _events(bus)
            one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
            await bus.cycle([(one, ma.ReadStatus1()), (two, ma.ReadStatus1())])
            heard = two.last_seen
            assert heard is not None
            for _ in range(10):  # motor 1 is polled every 0.1 s; motor 2 never again
                await anyio.sleep(0.1)
                await one.read_status1()
            return events, heard, anyio.current_time()

    events, heard, end = await scenario()
    assert _brief(events) == [(1, True, "answered"), (2, True, "answered"), (2, False, "silent for 500 ms")]
    assert events[-1].at == pytest.approx(heard + 0.5, abs=1e-6) and end > heard + 1.0


def test_watchdog_options_are_checked() -> None:
    with pytest.raises(ValueError, match="offline_after_misses=0"):
        Bus(SimTransport(devices=[]), offline_after_misses=0)
    with pytest.raises(ValueError, match="offline_after_s=0"):
        Bus(SimTransport(devices=[]), offline_after_s=0)


async def test_the_motor_side_watchdog_0xb3_stops_a_motor_the_host_stopped_talking_to() -> None:
    device = MyActuatorMotor(1)

    async def scenario() -> tuple[bool, bool]:
        async with Bus(SimTransport(devices=[device]), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            await motor.set_comm_timeout(timeout_ms=100)
            await motor.speed_control(speed_dps=90.0)
            await anyio.sleep(0.05)
            before = device.comm_tripped
            await anyio.sleep(0.2)  # the host goes quiet (a crashed control loop)
            return before, device.comm_tripped

    before, after = await scenario()
    assert (before, after) == (False, True)


async def test_a_stream_is_switched_on_iterated_and_switched_off_even_on_an_exception() -> None:
    device = MyActuatorMotor(1)

    async def scenario() -> tuple[list[Any], int]:
        async with Bus(SimTransport(devices=[device]), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            got: list[Any] = []
            with pytest.raises(RuntimeError, match="user code"):
                async with motor.stream(ma.ReadStatus2, interval_ms=10) as frames:
                    async for reply in frames:
                        got.append(reply)
                        if len(got) == 5:
                            raise RuntimeError("user code")
            after = bus.stats().get("stream", 0)
            await anyio.sleep(0.1)  # switched off: no more frames
            return got, bus.stats().get("stream", 0) - after

    got, more = await scenario()
    assert len(got) == 5 and all(isinstance(r, ma.StatusReply) for r in got)
    assert more == 0


async def test_a_family_without_streams_says_so() -> None:
    async def scenario() -> None:
        async with Bus(SimTransport(devices=[LkMotor(1)])) as bus:
            stream = bus.motor("lk", 1).stream(0x9C, interval_ms=10)
            await stream.__aenter__()

    with pytest.raises(ValueError, match="lk motors have no active-reply streams"):
        await scenario()


async def test_metrics_count_per_bus_and_per_motor_with_latency_from_the_wire() -> None:
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    devices[1].unresponsive = True

    async def scenario() -> tuple[Any, Any, Any]:
        # (never offline, and each tick after the silent motor's late hold: every tick asks both)
        async with Bus(SimTransport(devices=devices), offline_after_misses=100, late_hold_s=0.01) as bus:
            one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
            for _ in range(10):
                await bus.cycle([(one, ma.ReadStatus2()), (two, ma.ReadStatus2())], timeout_s=0.01)
                await anyio.sleep(0.02)
            return bus.metrics(), one.metrics(), two.metrics()

    bus, one, two = await scenario()
    assert (bus.requests, bus.replies, bus.timeouts) == (20, 10, 10)
    assert (one.requests, one.replies, one.timeouts) == (10, 10, 0)
    assert (two.requests, two.replies, two.timeouts) == (10, 0, 10)
    assert one.latency.samples == 10 and two.latency.samples == 0 and two.latency.p50_s is None
    # Request and reply are two 8-byte standard frames at 1 Mbit/s (~111 bits each with stuffing
    # and interframe space) plus the simulator's turnaround: a fraction of a millisecond.
    assert one.latency.p50_s is not None and 0.0002 < one.latency.p50_s < 0.001
    assert bus.bus_load_pct is not None and bus.bus_load_pct > 0


def test_latency_percentiles_are_nearest_rank() -> None:
    window = LatencyWindow(100)
    for ms in range(1, 201):  # only the last 100 are kept: 101..200
        window.add(ms / 1000)
    latency = window.snapshot()
    assert latency.samples == 100
    assert latency.p50_s == pytest.approx(0.150) and latency.p99_s == pytest.approx(0.199)
    assert latency.max_s == pytest.approx(0.200)
    with pytest.raises(ValueError, match="size=0"):
        LatencyWindow(0)


async def test_while_a_motor_streams_a_write_is_sent_without_awaiting_the_reply_it_will_never_get() -> None:
    device = MyActuatorMotor(1)

    async def scenario() -> tuple[Any, Any, float, int]:
        async with Bus(SimTransport(devices=[device]), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            async with motor.stream(ma.ReadStatus2, interval_ms=10):
                start = anyio.current_time()
                written = await motor.speed_control(speed_dps=45.0)
                took = anyio.current_time() - start
                read = await motor.read_status2()  # the streamed command: the next stream frame
            return written, read, took, bus.metrics().timeouts

    written, read, took, timeouts = await scenario()
    assert written is None and isinstance(read, ma.StatusReply) and read.speed_dps == pytest.approx(45, abs=1)
    assert took < 0.001 and timeouts == 0


async def test_a_reported_fault_is_kept_as_a_motor_fault_with_its_flags_until_a_report_without_it() -> None:
    device = MyActuatorMotor(1)
    lk_device = LkMotor(2)

    async def scenario() -> list[Any]:
        async with Bus(SimTransport(devices=[device, lk_device]), safe=None) as bus:
            motor, lk_motor = bus.motor("myactuator", 1), bus.motor("lk", 2)
            seen: list[Any] = [motor.fault]
            await motor.read_status1()
            seen.append(motor.fault)
            device.inject_error(ma.ErrorFlags.OVER_VOLTAGE, anyio.current_time())
            await motor.read_status2()  # a reply without flags says nothing about them
            seen.append(motor.fault)
            await motor.read_status1()
            seen.append(motor.fault)
            device.clear_error(ma.ErrorFlags.OVER_VOLTAGE, anyio.current_time())
            await motor.read_status1()
            seen.append(motor.fault)
            lk_device.inject_error(lk.ErrorState.MOTOR_OVER_TEMPERATURE, anyio.current_time())
            await lk_motor.read_status1()
            seen.append(lk_motor.fault)
            return seen

    seen = await scenario()
    assert seen[:3] == [None, None, None] and seen[4] is None
    fault = seen[3]
    assert isinstance(fault, MotorFault) and fault.flags == ma.ErrorFlags.OVER_VOLTAGE and fault.motor_id == 1
    assert "OVER_VOLTAGE" in str(fault) and "myactuator 1" in str(fault)
    assert isinstance(seen[5], MotorFault) and seen[5].flags == lk.ErrorState.MOTOR_OVER_TEMPERATURE


async def test_after_a_transport_loss_the_pending_fail_at_once_and_requests_work_after_recovery() -> None:
    device = MyActuatorMotor(1)

    async def scenario() -> tuple[BaseException, float, Any]:
        transport = SimTransport(devices=[device], reopen_backoff_s=(0.05, 0.1))
        async with Bus(transport, safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            device.unresponsive = True

            async def unplug() -> float:
                await anyio.sleep(0.01)
                transport.unplug()
                return anyio.current_time()

            async with anyio.create_task_group() as group:
                lost: list[float] = []
                group.start_soon(_into, lost, unplug())
                try:
                    await motor.read_status2(timeout_s=5.0)
                except TransportError as exc:
                    failed = [exc]
            took = anyio.current_time() - lost[0]
            device.unresponsive = False
            transport.replug()
            await transport.wait_open(timeout=1.0)
            return failed[0], took, await motor.read_status2()

    failed, took, after = await scenario()
    assert isinstance(failed, TransportError) and "lost" in str(failed)
    assert took < 0.001  # at once, not after the 5 s timeout
    assert isinstance(after, ma.StatusReply)


async def test_one_pacer_drives_two_buses() -> None:
    async def scenario() -> list[tuple[int, int, int]]:
        one = Bus(SimTransport(devices=[MyActuatorMotor(i) for i in (1, 2)]))
        two = Bus(SimTransport(devices=[LkMotor(i) for i in (1, 2)]))
        seen: list[tuple[int, int, int]] = []
        async with one, two:
            a = [one.motor("myactuator", i) for i in (1, 2)]
            b = [two.motor("lk", i) for i in (1, 2)]
            async for tick in ticks(hz=100, count=5):
                out: tuple[list[Any], list[Any]] = ([], [])
                async with anyio.create_task_group() as group:
                    group.start_soon(_into, out[0], one.cycle([(m, ma.ReadStatus2()) for m in a]))
                    group.start_soon(_into, out[1], two.cycle([(m, lk.ReadStatus2()) for m in b]))
                (first,), (second,) = out
                replies = sum(r is not None and not isinstance(r, BaseException) for r in [*first, *second])
                seen.append((tick.index, tick.skipped, replies))
        return seen

    assert await scenario() == [(i, 0, 4) for i in range(5)]


async def test_motion_mode_through_the_bus_for_myactuator_and_hollow() -> None:
    async def scenario() -> tuple[Any, Any, Any]:
        devices = [MyActuatorMotor(1), HollowMotor(20)]
        async with Bus(SimTransport(devices=devices)) as bus:
            motor, joint = bus.motor("myactuator", 1), bus.motor("hollow", 20)
            first = await motor.motion_command(
                position_rad=0.5, velocity_rad_s=0.0, kp=50.0, kd=1.0, torque_ff_nm=0.0
            )
            await anyio.sleep(0.5)  # the simulated rotor follows the spring toward 0.5 rad
            later = await motor.motion_command(
                position_rad=0.5, velocity_rad_s=0.0, kp=50.0, kd=1.0, torque_ff_nm=0.0
            )
            hollow = await joint.request(
                ho.Setpoint(position_deg=10.0, speed_rad_s=0.0, kp=5, kd=1, current_a=0.0)
            )
            return first, later, hollow

    first, later, hollow = await scenario()
    assert isinstance(first, ma.MotionReply) and first.motor_id == 1
    assert isinstance(later, ma.MotionReply) and abs(later.position_rad - 0.5) < abs(first.position_rad - 0.5)
    assert isinstance(hollow, ho.NormalReply) and hollow.motor_id == 20


async def test_a_frame_iterator_ends_when_the_bus_closes_instead_of_hanging() -> None:
    async def scenario() -> int:
        got = 0

        async def read(frames: Any) -> None:
            nonlocal got
            async for _ in frames:
                got += 1

        bus = Bus(SimTransport(devices=[MyActuatorMotor(1)]), safe=None)
        with anyio.fail_after(1.0):  # the reader ends once the Bus is closed
            async with anyio.create_task_group() as group, bus:
                frames = await bus.motor("myactuator", 1).frames().__aenter__()
                group.start_soon(read, frames)
                await anyio.sleep(0.01)
        return got

    assert await scenario() == 0

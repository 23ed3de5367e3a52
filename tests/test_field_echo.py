"""A command echoed and not executed ([field] case 1), on the project's simulator in virtual time.

After a MyActuator motor's communication watchdog (0xB3) trips, it sends 0xF1 at the trip and about
every second after, and echoes the first command after communication resumes byte for byte without
executing it (2b-t/myactuator_rmd_ros, pull request 4; the simulator's ``trip_echo``). Before this,
the echo of a control command came back as a StatusReply (0 °C, the set-point bytes read as speed and
current) and the 0xF1 frames were counted ``malformed``. Now: the request fails with
MotorNotExecuted, the trip is counted, shown in ``motor.fault`` and told to the status listeners, and
the safe stop sends an echoed stop again.
"""

from __future__ import annotations

import logging
from typing import Any

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus, MotorStatus
from servobus.errors import MotorNotExecuted
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import Traffic
from servobus.sim.attach import serve_slcan
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import PositionControl
from servobus.sim.pty import PtyPort
from servobus.transports import SimTransport, SlcanTransport
from sim._standins import Sniffer
from transports._anyio_help import serving

pytestmark = pytest.mark.anyio

TRIP = 0xF1
COMM_TIMEOUT_MS = 50


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


def _bench(n: int = 1) -> tuple[SimTransport, list[MyActuatorMotor], Sniffer]:
    motors = [MyActuatorMotor(i) for i in range(1, n + 1)]
    sniffer = Sniffer()
    return SimTransport(SimCanNetwork([*motors, sniffer])), motors, sniffer


def _trip_frames(sniffer: Sniffer, motor_id: int) -> int:
    return sum(1 for _, f in sniffer.seen if f.arbitration_id == 0x240 + motor_id and f.data[:1] == b"\xf1")


async def test_a_one_shot_command_after_a_trip_raises_motor_not_executed_and_the_trip_is_surfaced(
    caplog: pytest.LogCaptureFixture,
) -> None:
    transport, (device,), sniffer = _bench()
    statuses: list[MotorStatus] = []
    events: list[tuple[Traffic, Any]] = []
    caplog.set_level(logging.INFO, logger="servobus.bus")
    async with transport, Bus(transport, safe=None) as bus:
        bus.subscribe_status(statuses.append)
        bus.subscribe(lambda motor, traffic, reply: events.append((traffic, reply)))
        motor = bus.motor("myactuator", 1)
        await motor.set_comm_timeout(COMM_TIMEOUT_MS)
        await motor.speed_control(speed_dps=90.0)
        await anyio.sleep(2.5)  # the host goes quiet: the watchdog trips, 0xF1 at once and each second
        assert device.comm_tripped and device.counters["comm_trip_frames"] == 3
        assert motor.fault is not None and "communication watchdog tripped (0xF1)" in str(motor.fault)
        before = motor.state

        with pytest.raises(MotorNotExecuted, match="echoed back") as caught:
            await motor.absolute_position_control(90.0, None)
        # never a StatusReply with 0 °C and the set-point bytes read as current and speed
        assert caught.value.motor_id == 1 and caught.value.command == 0xA4
        assert caught.value.raw == ma.AbsolutePositionControl(angle_deg=90.0, max_speed_dps=None).encode()
        assert not isinstance(device.control, PositionControl)  # the motor did not move
        assert motor.state is before  # the echo is no measurement
        assert motor.fault is not None  # still: nothing was executed yet

        reply = await motor.absolute_position_control(90.0, None)  # sent again: executed
        assert isinstance(reply, ma.StatusReply)
        assert isinstance(device.control, PositionControl)
        assert motor.fault is None
        metrics, motor_metrics = bus.metrics(), motor.metrics()

    # every 0xF1 counted by name (and none malformed), the echo counted, the episode told once
    assert _trip_frames(sniffer, 1) == 3
    assert motor_metrics.comm_tripped == metrics.comm_tripped == 3 and metrics.malformed == 0
    assert motor_metrics.not_executed == metrics.not_executed == 1
    assert [s.reason for s in statuses if "0xF1" in s.reason] == ["communication watchdog tripped (0xF1)"]
    assert [type(r) for t, r in events if t is Traffic.REPORT] == [ma.CommunicationTimeoutTripped] * 3
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert sum("0xF1" in w for w in warnings) == 1 and sum("echoed back" in w for w in warnings) == 1


async def test_in_a_200_hz_loop_with_trips_no_echo_is_returned_as_a_reply() -> None:
    """Four motors in a 200 Hz cycle() loop; the host stalls for 150 ms six times (the watchdog,
    50 ms, trips each time). Every echo fails its item with MotorNotExecuted; every reply returned
    is a real one; every 0xF1 on the wire is counted and each trip is told once."""
    transport, devices, sniffer = _bench(4)
    statuses: list[MotorStatus] = []
    seen_results: list[Any] = []
    async with transport, Bus(transport, safe=None) as bus:
        bus.subscribe_status(statuses.append)
        motors = [bus.motor("myactuator", d.motor_id) for d in devices]
        for m in motors:
            await m.set_comm_timeout(COMM_TIMEOUT_MS)
        batch = [(m, ma.SpeedControl(speed_dps=30.0 + m.motor_id)) for m in motors]
        async for tick in bus.ticks(200.0, spin_s=0.0):
            if tick.index >= 1200:
                break
            if tick.index % 200 == 100:
                await anyio.sleep(0.15)  # a stalled host
                continue
            seen_results += await bus.cycle(batch)
        metrics = bus.metrics()

    echoed = sum(d.counters["comm_echoed"] for d in devices)
    replies = [r for r in seen_results if isinstance(r, ma.StatusReply)]
    refused = [r for r in seen_results if isinstance(r, MotorNotExecuted)]
    as_replies = [r for r in replies if any(r.encode() == c.encode() for _, c in batch)]
    trip_frames = sum(_trip_frames(sniffer, d.motor_id) for d in devices)
    tripped = [s for s in statuses if "0xF1" in s.reason]
    print(
        f"200 Hz: {len(replies)} replies, {echoed} echoes, {len(refused)} MotorNotExecuted, "
        f"{len(as_replies)} echoes returned as replies; 0xF1 on the wire {trip_frames}, counted "
        f"{metrics.comm_tripped}, trips {len(tripped)} told"
    )
    assert echoed == 4 * 6 and len(refused) == echoed and as_replies == []
    assert all(r.temperature_c != 0 for r in replies)
    assert trip_frames == sum(d.counters["comm_trip_frames"] for d in devices) >= 24
    assert metrics.comm_tripped == trip_frames and metrics.not_executed == echoed
    assert metrics.malformed == 0
    assert len(tripped) == sum(d.counters["comm_timeouts"] for d in devices) == 24


def _stops(sniffer: Sniffer) -> int:
    return sum(1 for _, f in sniffer.seen if f.arbitration_id == 0x141 and f.data[:1] == b"\x81")


async def test_the_safe_stop_is_sent_again_after_an_echoed_stop() -> None:
    transport, (device,), sniffer = _bench()
    async with transport, Bus(transport) as bus:
        motor = bus.motor("myactuator", 1)
        await motor.set_comm_timeout(COMM_TIMEOUT_MS)
        await motor.speed_control(speed_dps=90.0)
        await anyio.sleep(0.2)  # tripped before the block is left
        assert device.comm_tripped
    # the first stop was echoed (not executed), the second acknowledged
    assert device.counters["comm_echoed"] == 1
    assert _stops(sniffer) == 2
    assert [m.motor_id for m in bus.safe_acknowledged] == [1]
    assert bus.metrics().not_executed == 1


# ---- through a real transport: the simulator's SLCAN adapter on a pseudo-terminal, real time ----

T = 0.5  # a reply's timeout through the pty (the simulator shares the process; see test_bus_pty.py)


@pytest.mark.parametrize("backend", BACKENDS)
def test_over_slcan_on_a_pty_the_echo_fails_its_request_and_every_0xf1_is_counted(backend: str) -> None:
    device, sniffer = MyActuatorMotor(1), Sniffer()
    port = PtyPort()

    async def main() -> tuple[Any, Any, list[str]]:
        statuses: list[str] = []
        with anyio.fail_after(10):
            transport = SlcanTransport(port.path, bitrate=1_000_000)
            network = SimCanNetwork([device, sniffer])
            async with serving(serve_slcan(network, port)), Bus(transport, safe=None) as bus:
                bus.subscribe_status(lambda status: statuses.append(status.reason))
                motor = bus.motor("myactuator", 1)
                await motor.set_comm_timeout(COMM_TIMEOUT_MS, timeout_s=T)
                await motor.speed_control(speed_dps=90.0, timeout_s=T)
                await anyio.sleep(0.3)  # quiet: the watchdog trips, one 0xF1
                with pytest.raises(MotorNotExecuted):
                    await motor.absolute_position_control(90.0, None, timeout_s=T)
                reply = await motor.absolute_position_control(90.0, None, timeout_s=T)
                return reply, bus.metrics(), statuses

    try:
        reply, metrics, statuses = anyio.run(main, backend=backend)
    finally:
        port.close()
    assert isinstance(reply, ma.StatusReply) and isinstance(device.control, PositionControl)
    assert device.counters["comm_echoed"] == 1 and device.counters["comm_trip_frames"] == 1
    assert _trip_frames(sniffer, 1) == metrics.comm_tripped == 1
    assert metrics.not_executed == 1 and metrics.malformed == 0
    assert statuses.count("communication watchdog tripped (0xF1)") == 1


async def test_a_broadcast_to_tripped_motors_gives_each_motor_not_executed() -> None:
    transport, devices, _ = _bench(2)
    async with transport, Bus(transport, safe=None) as bus:
        motors = [bus.motor("myactuator", d.motor_id) for d in devices]
        for m in motors:
            await m.set_comm_timeout(COMM_TIMEOUT_MS)
        await anyio.sleep(0.2)
        assert all(d.comm_tripped for d in devices)
        echoed = await bus.broadcast(ma.SpeedControl(speed_dps=20.0), motors)
        executed = await bus.broadcast(ma.SpeedControl(speed_dps=20.0), motors)
    assert all(isinstance(r, MotorNotExecuted) for r in echoed.values()), echoed
    assert all(isinstance(r, ma.StatusReply) for r in executed.values()), executed


def test_motor_not_executed_crosses_the_remote_wire_as_itself() -> None:
    from servobus.remote import wire

    schema = wire.Schema.of("myactuator")
    error = MotorNotExecuted("motor 1 SpeedControl was echoed back", motor_id=1, command=0xA2)
    back = wire.decode_result(schema, wire.encode_result(schema, wire.Result(error=error))).error
    assert isinstance(back, MotorNotExecuted) and back.motor_id == 1 and "echoed back" in str(back)


async def test_a_motion_mode_command_echoed_after_a_trip_is_not_executed() -> None:
    """The echo of a 0x400+ID frame comes on 0x500+ID (the simulator's choice: the report names no
    identifier): it is told apart while the trip is known, since a motion reply could be any bytes."""
    transport, (device,), _ = _bench()
    async with transport, Bus(transport, safe=None) as bus:
        motor = bus.motor("myactuator", 1)
        await motor.set_comm_timeout(COMM_TIMEOUT_MS)
        await anyio.sleep(0.2)
        command = ma.MotionCommand(position_rad=1.0, velocity_rad_s=0.0, kp=20.0, kd=1.0, torque_ff_nm=0.0)
        with pytest.raises(MotorNotExecuted):
            await motor.request(command)
        assert isinstance(await motor.request(command), ma.MotionReply)
    assert device.counters["comm_echoed"] == 1

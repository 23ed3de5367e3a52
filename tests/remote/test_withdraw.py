"""A client's commands end with its hold on a motor, in one process (asyncio and trio): what the
bridge withdraws from the Bus when a client loses a motor, and what that client may still do.

On a slow simulated bus (10 kbit/s: a frame takes ~12 ms), so that requests queue on the Bus behind
a reply still due, and what reached each motor is the list of frames the transport was given."""

from __future__ import annotations

import functools
from collections.abc import AsyncIterator
from typing import Any

import anyio
import anyio.lowlevel
import pytest

import servobus
from _ports import loopback_endpoint as _endpoint
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.remote import Bridge, connect
from servobus.remote.security import bridge_config
from servobus.sim.canbus import CanBusModel
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio

pytest.importorskip("zenoh")

STOP = 0x81


class Logged(SimTransport):
    """A simulated bus that keeps every frame it was given: ``(arbitration id, data)``."""

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.sent: list[tuple[int, bytes]] = []

    def _put(self, frame: Any, handle: Any, now: float) -> None:
        self.sent.append((frame.arbitration_id, bytes(frame.data)))
        super()._put(frame, handle, now)


def slow_bus(*ids: int) -> Logged:
    return Logged(devices=[MyActuatorMotor(i) for i in ids], bus=CanBusModel(bitrate=10_000))


async def _until(predicate: Any, timeout_s: float = 5.0) -> None:
    with anyio.fail_after(timeout_s):
        while not predicate():
            await anyio.sleep(0.002)


def after(sent: list[tuple[int, bytes]], first: Any, then: Any) -> list[bytes]:
    """The frames matching ``then`` sent after the first one matching ``first``."""
    start = next(i for i, frame in enumerate(sent) if first(frame))
    return [data for frame in sent[start + 1 :] if then(frame) for _, data in [frame]]


async def test_a_set_point_queued_behind_a_request_does_not_follow_a_stop_once_withdrawn() -> None:
    """The bridge's tick (``Bus.cycle``) queues a set-point behind a request of the same reply key
    that waits for a free slot; once that request is on the wire, the set-point waits for its reply
    while a stop (another key) goes: withdrawn before the stop, it never leaves."""
    transport = slow_bus(1, 2, 3)
    async with servobus.Bus(transport, max_in_flight=2, safe=None) as bus:  # (one stop: the test's)
        m1, m2, m3 = (bus.motor(ma.FAMILY, i) for i in (1, 2, 3))
        outcomes: dict[str, Any] = {}
        read3 = anyio.Event()

        async def request(name: str, motor: Any, command: Any) -> None:
            try:
                outcomes[name] = await bus.request(motor, command)
            except Exception as exc:
                outcomes[name] = exc
            if name == "read3":
                read3.set()

        async def tick() -> None:
            outcomes["tick"] = await bus.cycle([(m1, ma.SpeedControl(speed_dps=45.0))])

        async with anyio.create_task_group() as group:
            for name, motor, command in [
                ("read2", m2, ma.ReadStatus2()),  # the two slots
                ("read3", m3, ma.ReadStatus2()),
                ("speed", m1, ma.SpeedControl(speed_dps=90.0)),  # queued: no slot
            ]:
                group.start_soon(request, name, motor, command)
                await anyio.lowlevel.checkpoint()
            group.start_soon(tick)  # queued behind it (its key is not in flight yet)
            await anyio.lowlevel.checkpoint()
            await read3.wait()  # the request took a slot, the set-point waits for its reply
            withdrawn = bus.engine.withdraw(m1, PermissionError("released"), lambda request: False)
            group.start_soon(request, "stop", m1, ma.MotorStop())
        assert [type(r.command) for r in withdrawn] == [ma.SpeedControl]
        assert isinstance(outcomes["tick"][0], PermissionError), outcomes  # the tick's slot: the error
        assert isinstance(outcomes["speed"], ma.StatusReply), outcomes  # (on the wire before: answered)
        assert isinstance(outcomes["stop"], ma.Echo), outcomes
    assert [d[0] for a, d in transport.sent if a == 0x141] == [0xA2, STOP], transport.sent


async def _serve(
    allow_takeover: bool, transport: Logged
) -> AsyncIterator[tuple[Bridge, servobus.Bus, Logged, str]]:
    endpoint = _endpoint()
    async with servobus.Bus(transport) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        config = bridge_config("n", [endpoint])
        async with Bridge("n", {"b": (bus, motors)}, config=config, allow_takeover=allow_takeover) as bridge:
            yield bridge, bus, transport, endpoint


@pytest.fixture
async def takeover() -> AsyncIterator[tuple[Bridge, servobus.Bus, Logged, str]]:
    async for served in _serve(True, slow_bus(1, 2)):
        yield served


@pytest.fixture
async def served() -> AsyncIterator[tuple[Bridge, servobus.Bus, Logged, str]]:
    async for served in _serve(False, Logged(devices=[MyActuatorMotor(1), MyActuatorMotor(2)])):
        yield served


async def test_a_client_taken_over_loses_its_queued_requests_and_its_set_point(
    takeover: tuple[Bridge, servobus.Bus, Logged, str],
) -> None:
    bridge, bus, transport, endpoint = takeover
    codec = bus.motor(ma.FAMILY, 1).codec
    a_bytes = bytes(codec.encode(ma.SpeedControl(speed_dps=90.0)).data)
    b_bytes = bytes(codec.encode(ma.SpeedControl(speed_dps=-30.0)).data)
    async with connect("n/b", endpoints=[endpoint]) as a, connect("n/b", endpoints=[endpoint]) as b:
        outcomes: list[Any] = []

        async def a_speed() -> None:
            try:
                outcomes.append(await a.motor(1).speed_control(speed_dps=90.0))
            except Exception as exc:
                outcomes.append(exc)

        await a.cycle([(a.motor(1), ma.SpeedControl(speed_dps=10.0))], valid_for_s=5.0)
        await _until(lambda: bridge.served["b"].owners.get(1) == a.token_id)
        counts = bridge.served["b"].counts
        requests_before = counts["requests"]
        async with anyio.create_task_group() as group:
            for _ in range(6):
                group.start_soon(a_speed)
            # all six reached the bridge (one still on its way would take the motor back from B, as
            # takeover allows: CI failed there), and A's requests queue on the Bus
            await _until(lambda: counts["requests"] >= requests_before + 6)
            await _until(lambda: bus.scheduler.pending >= 4)
            assert isinstance(await b.motor(1).speed_control(speed_dps=-30.0), ma.StatusReply)
        assert bridge.served["b"].owners == {1: b.token_id}
        assert 1 not in bridge.served["b"].held  # A's set-point went with its hold
        withdrawn = [o for o in outcomes if isinstance(o, PermissionError)]
        assert withdrawn and all("taken over" in str(o) for o in withdrawn), outcomes
        assert bridge.served["b"].counts["withdrawn"] == len(withdrawn)
    a_after_b = after(transport.sent, lambda f: f == (0x141, b_bytes), lambda f: f == (0x141, a_bytes))
    assert a_after_b == [], f"{len(a_after_b)} of A's frames after B took the motor"


async def test_a_client_stopped_for_stale_set_points_takes_the_motor_back_only_by_a_set_point_or_a_stop(
    served: tuple[Bridge, servobus.Bus, Logged, str],
) -> None:
    """Its requests (some sent before the stop, still on their way) are refused; reads are free;
    its stop request (or a fresh set-point) takes the motor back, and its requests go again."""
    bridge, _, _, endpoint = served
    async with connect("n/b", endpoints=[endpoint]) as a:
        motor = a.motor(ma.FAMILY, 2)
        await a.cycle([(motor, ma.SpeedControl(speed_dps=30.0))], valid_for_s=0.1)
        await _until(lambda: bridge.served["b"].counts["stops"] == 1)
        assert "stale" in bridge.stop_log[-1][3]
        with pytest.raises(PermissionError, match="set-points went stale"):
            await motor.speed_control(speed_dps=40.0)
        assert isinstance(await motor.read_status2(), ma.StatusReply)
        assert bridge.served["b"].owners == {}
        assert isinstance(await motor.motor_stop(), ma.Echo)
        assert isinstance(await motor.speed_control(speed_dps=40.0), ma.StatusReply)
        assert bridge.served["b"].owners == {2: a.token_id}


async def test_a_bridge_that_closes_withdraws_what_its_clients_queued_before_its_stop() -> None:
    endpoint, transport = _endpoint(), slow_bus(1, 2)
    outcomes: list[Any] = []

    async def a_speed(remote: Any) -> None:
        with anyio.move_on_after(5):
            try:
                outcomes.append(await remote.motor(1).speed_control(speed_dps=90.0))
            except Exception as exc:  # withdrawn, or no answer from a bridge that went
                outcomes.append(exc)

    async with servobus.Bus(transport, safe=None) as bus, anyio.create_task_group() as group:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        async with Bridge("n", {"b": (bus, motors)}, config=bridge_config("n", [endpoint])) as bridge:
            remote = await connect("n/b", endpoints=[endpoint]).__aenter__()
            try:
                for _ in range(6):
                    group.start_soon(a_speed, remote)
                await _until(lambda: bus.scheduler.pending >= 4)  # queued on the Bus
            except BaseException:
                await remote.__aexit__(None, None, None)
                raise
        await remote.__aexit__(None, None, None)
    stop = lambda f: f[0] == 0x141 and f[1][0] == STOP  # noqa: E731
    speed_after_stop = after(transport.sent, stop, lambda f: f[0] == 0x141)
    assert speed_after_stop == [], [d.hex() for d in speed_after_stop]
    assert [(m, why) for _, _, m, why in bridge.stop_log] == [(1, "bridge closing")]
    assert bridge.served["b"].counts.get("withdrawn", 0) >= 1
    assert any(isinstance(o, PermissionError) for o in outcomes), outcomes


async def test_a_command_after_a_clients_own_stop_keeps_the_motor_held_so_its_leaving_stops_it() -> None:
    """A client's stop request, acknowledged, releases the motor (its leaving must not undo that);
    but a command it sent after the stop moves the motor again: then the motor stays held, and the
    client's leaving stops it (it was left running, held by nobody)."""
    endpoint, transport = _endpoint(), slow_bus(1)
    async with servobus.Bus(transport, safe=None) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        async with Bridge("n", {"b": (bus, [motor])}, config=bridge_config("n", [endpoint])) as bridge:
            async with connect("n/b", endpoints=[endpoint]) as remote:
                async with anyio.create_task_group() as group:
                    group.start_soon(remote.motor(1).request, ma.MotorStop())
                    await _until(lambda: bridge.served["b"].counts["requests"] >= 1)
                    group.start_soon(functools.partial(remote.motor(1).speed_control, speed_dps=90.0))
                assert bridge.served["b"].owners.get(1) == remote.token_id
            await _until(lambda: len(bridge.stop_log) >= 1)
    assert [(m, why) for _, _, m, why in bridge.stop_log] == [(1, "client left")]
    assert transport.sent[-1][1][0] == STOP  # (the last frame the motor got: the stop)


async def test_set_points_past_the_bus_or_without_a_token_are_refused_from_their_header() -> None:
    """More set-points in a message than the bus has motors, or a client id without a live token:
    refused from the header alone (no command decoded), counted ``malformed`` and ``refused``."""
    from servobus.remote import wire

    schema = wire.Schema.of("myactuator")
    endpoint, transport = _endpoint(), slow_bus(1, 2)
    async with servobus.Bus(transport, safe=None) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        async with Bridge("n", {"b": (bus, motors)}, config=bridge_config("n", [endpoint])) as bridge:
            served = bridge.served["b"]
            async with connect("n/b", endpoints=[endpoint]) as remote:
                speed = ma.SpeedControl(speed_dps=9.0)
                now = 10**18
                three = wire.Setpoints(
                    remote.client_id, 1, now, now + 10**9, ((1, speed), (2, speed), (1, speed))
                )
                bridge._on_setpoints(
                    served, ("n/b/setpoints", wire.encode_setpoints(lambda m: schema, three), 0)
                )
                assert served.counts["malformed"] == 1 and 1 not in served.held
                stranger = wire.Setpoints("ab" * 16, 1, now, now + 10**9, ((1, speed),))
                body = bytearray(wire.encode_setpoints(lambda m: schema, stranger))
                body[-1] ^= 0xFF  # (a command that would not decode: never looked at)
                bridge._on_setpoints(served, ("n/b/setpoints", bytes(body), 0))
                assert served.counts["refused"] == 1 and served.counts["malformed"] == 1

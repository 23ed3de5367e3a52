"""The bridge and the client in one process, on asyncio and trio: set-point freshness, stops on
stale set-points, what a read may be, clients without a token, a bridge that goes away."""

from __future__ import annotations

import contextlib
import time
import uuid
from collections.abc import AsyncIterator

import anyio
import pytest

import servobus
from _ports import loopback_endpoint as _endpoint
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim import MyActuatorMotor
from servobus.remote import Bridge, BridgeLost, RemoteError, connect, wire
from servobus.remote.security import bridge_config, client_config
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio

zenoh = pytest.importorskip("zenoh")


class Served:
    def __init__(self, bridge: Bridge, bus: servobus.Bus, endpoint: str) -> None:
        self.bridge, self.bus, self.endpoint = bridge, bus, endpoint

    def counts(self) -> dict[str, int]:
        return self.bridge.served["b"].counts


async def _serve(endpoint: str, **options: object) -> AsyncIterator[Served]:
    transport = SimTransport(devices=[MyActuatorMotor(i) for i in range(1, 5)])
    async with servobus.Bus(transport) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in range(1, 5)]
        async with Bridge(
            "n", {"b": (bus, motors)}, config=bridge_config("n", [endpoint]), **options
        ) as bridge:
            yield Served(bridge, bus, endpoint)


@pytest.fixture
async def served() -> AsyncIterator[Served]:
    async for item in _serve(_endpoint(), stop_after_s=0.05):
        yield item


async def _until(predicate: object, timeout_s: float = 3.0) -> None:
    with anyio.fail_after(timeout_s):
        while not predicate():  # type: ignore[operator]
            await anyio.sleep(0.005)


async def test_set_points_go_out_every_tick_then_go_stale_and_the_motor_is_stopped(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        motor = remote.motor(ma.FAMILY, 2)
        await remote.cycle([(motor, ma.SpeedControl(speed_dps=90.0))], valid_for_s=0.2)
        await _until(lambda: served.counts()["applied"] == 1)
        sent = served.bus.metrics().requests
        await anyio.sleep(0.1)
        assert served.bus.metrics().requests > sent + 5  # the bridge's tick repeats the fresh set-point
        await _until(lambda: served.counts()["expired"] == 1)
        await _until(lambda: served.counts()["stops"] == 1)
        assert [(bus, mid) for _, bus, mid, why in served.bridge.stop_log] == [("b", 2)]
        assert "stale" in served.bridge.stop_log[0][3]
        await _until(lambda: isinstance(motor.state, ma.StatusReply) or motor.state is not None)


async def test_a_set_point_that_arrives_stale_is_dropped_and_counted(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        motor = remote.motor(1)
        await remote.cycle([(motor, ma.SpeedControl(speed_dps=10.0))], valid_for_s=1e-7)
        await _until(lambda: served.counts()["stale"] == 1)
        assert served.counts()["applied"] == 0
        assert 1 not in served.bridge.served["b"].owners


async def test_leaving_the_block_stops_the_motors_the_client_commanded(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        motors = [remote.motor(i) for i in (1, 3)]
        await remote.cycle([(m, ma.SpeedControl(speed_dps=30.0)) for m in motors], valid_for_s=5.0)
        await _until(lambda: served.counts()["applied"] == 2)
    await _until(lambda: served.counts()["stops"] == 2)
    assert sorted(mid for _, _, mid, why in served.bridge.stop_log if why == "client left") == [1, 3]


async def test_requests_reads_and_typed_replies(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        motor = remote.motor(ma.FAMILY, 4)
        status = await motor.request(ma.ReadStatus2())
        assert isinstance(status, ma.StatusReply)
        assert isinstance(await motor.read_status1(), ma.Status1Reply)
        assert isinstance(await motor.speed_control(speed_dps=5.0), ma.StatusReply)
        assert served.counts()["reads"] == 2 and served.counts()["requests"] == 1
        assert served.bridge.served["b"].owners == {4: remote.token_id}
        with pytest.raises(ValueError, match="no motor 9"):
            remote.motor(9)
        with pytest.raises(AttributeError, match="no command"):
            motor.read_statuss2  # noqa: B018
        metrics = await remote.metrics()
        assert metrics["bridge"]["reads"] == 2


async def test_a_read_only_connection_commands_nothing(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint], read_only=True) as remote:
        motor = remote.motor(1)
        assert isinstance(await motor.read_status2(), ma.StatusReply)
        with pytest.raises(PermissionError, match="read-only"):
            await motor.speed_control(speed_dps=10.0)
        with pytest.raises(PermissionError, match="read-only"):
            await remote.cycle([(motor, ma.SpeedControl(speed_dps=10.0))])
    assert served.counts()["setpoints"] == 0 and served.bridge.served["b"].owners == {}


async def test_the_read_key_runs_reads_only_and_a_client_without_a_token_commands_nothing(
    served: Served,
) -> None:
    """A raw session (no liveliness token) tries a command through ``read`` and through ``request``,
    and set-points: every one is refused by the bridge itself."""
    schema = wire.Schema.of("myactuator")
    stranger = uuid.uuid4().hex
    session = await anyio.to_thread.run_sync(zenoh.open, client_config([served.endpoint]))
    try:
        for leaf in ("read", "request"):
            payload = wire.encode_request(schema, wire.Request(stranger, ma.SpeedControl(speed_dps=5.0)))
            key = f"servobus/n/b/1/{leaf}"
            replies = await anyio.to_thread.run_sync(
                lambda key=key, payload=payload: list(session.get(key, payload=payload, timeout=2.0))
            )
            error = wire.decode_result(schema, replies[0].ok.payload.to_bytes()).error
            assert isinstance(error, PermissionError), leaf
        now = time.time_ns()
        message = wire.Setpoints(stranger, 1, now, now + 10**9, ((1, ma.SpeedControl(speed_dps=5.0)),))
        session.put("servobus/n/b/setpoints", wire.encode_setpoints(lambda mid: schema, message))
        await _until(lambda: served.counts()["refused"] >= 3)
    finally:
        await anyio.to_thread.run_sync(session.close)
    assert served.counts()["setpoints"] == 0 and served.bridge.served["b"].owners == {}


async def test_a_bridge_that_goes_away_fails_calls_at_once() -> None:
    endpoint = _endpoint()
    async with anyio.create_task_group() as group:
        stop = anyio.Event()

        async def bridge() -> None:
            async for _ in _serve(endpoint):
                await stop.wait()

        group.start_soon(bridge)
        with anyio.fail_after(5):
            while True:
                try:
                    remote = await connect("n/b", endpoints=[endpoint], timeout_s=0.5).__aenter__()
                    break
                except RemoteError:
                    await anyio.sleep(0.05)
        try:
            motor = remote.motor(1)
            await motor.read_status2()
            stop.set()
            await _until(lambda: remote.lost is not None)
            with anyio.fail_after(1), pytest.raises(BridgeLost):
                await motor.read_status2()
            with pytest.raises(BridgeLost):
                await remote.cycle([(motor, ma.SpeedControl(speed_dps=1.0))])
        finally:
            await remote.__aexit__(None, None, None)


async def test_clear_errors_on_connect(served: Served) -> None:
    with pytest.raises(RemoteError, match=r"no bus 'x'.*its buses: b"):
        async with connect("n/x", endpoints=[served.endpoint]):
            pass
    with pytest.raises(RemoteError, match="no bridge named 'm'"):
        async with connect("m/b", endpoints=[served.endpoint], timeout_s=0.3):
            pass
    with anyio.fail_after(5), pytest.raises(RemoteError, match="no bridge reachable"):
        async with connect("n/b", endpoints=[_endpoint()], timeout_s=0.3):
            pass
    with pytest.raises(ValueError, match="NODE/BUS"):
        connect("n")


async def test_a_motor_the_client_made_safe_itself_is_left_as_it_is(served: Served) -> None:
    """``off`` then leaving must not re-engage the motor with the bridge's stop; a motor left
    running by a request is stopped."""
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        await remote.motor(1).motor_shutdown()
        await remote.motor(2).speed_control(speed_dps=20.0)
        assert served.bridge.served["b"].owners == {2: remote.token_id}
    await _until(lambda: served.counts()["stops"] == 1)
    await anyio.sleep(0.05)
    assert [mid for _, _, mid, _ in served.bridge.stop_log] == [2]


async def test_the_missing_bus_error_lists_every_bus() -> None:
    endpoint = _endpoint()
    async with contextlib.AsyncExitStack() as stack:
        buses = {}
        for name in ("s1", "s2", "s3"):
            bus = await stack.enter_async_context(servobus.Bus(SimTransport(devices=[MyActuatorMotor(1)])))
            buses[name] = (bus, [bus.motor(ma.FAMILY, 1)])
        await stack.enter_async_context(Bridge("n", buses, config=bridge_config("n", [endpoint])))
        with pytest.raises(RemoteError, match=r"its buses: s1, s2, s3\)"):
            async with connect("n/x", endpoints=[endpoint]):
                pass


async def test_a_client_leaving_is_never_dropped_even_when_set_points_are(
    served: Served,
) -> None:
    """With the backlog full (every set-point and query dropped on Zenoh's thread), a client's
    token vanishing still reaches the bridge, and its motor is stopped."""
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        await remote.motor(3).speed_control(speed_dps=40.0)
        served.bridge._handover._limit = 0  # type: ignore[union-attr]  # (full: nothing more waits)
        await remote.cycle([(remote.motor(3), ma.SpeedControl(speed_dps=1.0))])
        await _until(lambda: served.bridge.dropped_events >= 1)
    await _until(lambda: served.counts()["stops"] == 1)
    assert [mid for _, _, mid, _ in served.bridge.stop_log] == [3]


async def test_a_client_cannot_speak_in_another_clients_name(served: Served) -> None:
    """The owner's public id (metrics, token) is not the secret its messages carry: a message that
    carries it is a message from no live client."""
    async with connect("n/b", endpoints=[served.endpoint]) as holder:
        await holder.motor(1).speed_control(speed_dps=40.0)
        shown = (await holder.metrics())["owners"]["1"]
        assert shown == holder.shown_id and len({shown, holder.token_id, holder.client_id}) == 3
        async with connect("n/b", endpoints=[served.endpoint]) as other:
            other.client_id = holder.token_id  # forged: its token's key (what a bridge's peer could see)
            with pytest.raises(PermissionError, match="no liveliness token"):
                await other.motor(1).speed_control(speed_dps=-40.0)
            await other.cycle([(other.motor(1), ma.SpeedControl(speed_dps=-40.0))])
            await _until(lambda: served.counts()["refused"] >= 2)
        assert served.bridge.served["b"].owners == {1: holder.token_id}
        assert served.counts()["setpoints"] == 0


@pytest.mark.parametrize("safe", [None, "brake"])
async def test_a_leaving_client_s_motors_are_stopped_whatever_the_bus_s_safe_kind(safe: str | None) -> None:
    """A Bus with safe=None (no stop on its own exit) still stops a remote client's motors when the
    client leaves; a kind the family lacks (hollow has no brake) falls back to "stop", and the
    bridge lives on."""
    from servobus.protocols import hollow
    from servobus.protocols.hollow.sim import HollowMotor

    endpoint = _endpoint()
    family = ma if safe is None else hollow
    device = MyActuatorMotor(1) if safe is None else HollowMotor(1)
    async with servobus.Bus(SimTransport(devices=[device]), safe=safe) as bus:
        motor = bus.motor(family.FAMILY, 1)
        async with Bridge("n", {"b": (bus, [motor])}, config=bridge_config("n", [endpoint])) as bridge:
            async with connect("n/b", endpoints=[endpoint]) as remote:
                command = ma.SpeedControl(speed_dps=5.0) if safe is None else hollow.Start()
                await remote.motor(1).request(command)
            await _until(lambda: bridge.served["b"].counts["stops"] == 1)
            stop = bridge.served["b"].stop_commands[1]
            assert stop == motor.codec.safe_command("stop")
            await _until(lambda: bus.metrics().replies >= 2)  # the command's reply, then the stop's
            async with connect("n/b", endpoints=[endpoint]) as again:  # the bridge still serves
                assert (await again.metrics())["bridge"]["stops"] == 1


async def test_a_client_faster_than_the_bridge_costs_no_queue_only_replaced_batches(served: Served) -> None:
    """100 batches published while the bridge's loop is busy: the newest one wins, the rest are
    replaced on Zenoh's thread (counted), none waits in a queue to be applied late."""
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        motor = remote.motor(2)
        for speed in range(1, 101):  # (cycle publishes without awaiting: the loop is ours meanwhile)
            await remote.cycle([(motor, ma.SpeedControl(speed_dps=float(speed)))], valid_for_s=1.0)
        time.sleep(0.2)  # the bridge's Zenoh thread receives them all while its loop is held here
        held = served.bridge.served["b"].held
        await _until(lambda: 2 in held and held[2].command == ma.SpeedControl(speed_dps=100.0))
        counts = served.counts()
        assert counts["overwritten"] > 50, counts
        assert counts["setpoints"] + counts["overwritten"] + counts["reordered"] <= 100, counts


async def test_a_client_that_joins_late_sees_each_state_within_a_second(served: Served) -> None:
    async with connect("n/b", endpoints=[served.endpoint]) as first:
        await first.motor(4).read_status2()
    await anyio.sleep(0.2)  # (nothing changes from now on)
    async with connect("n/b", endpoints=[served.endpoint], read_only=True) as late:
        with anyio.fail_after(2.0):
            while late.motor(4).state is None:
                await anyio.sleep(0.02)
        assert isinstance(late.motor(4).state, ma.StatusReply) and late.motor(4).online is True
        assert late.motor(1).state is None  # (never heard from: nothing to say)


async def test_a_bridge_that_closes_stops_the_motors_its_clients_hold() -> None:
    """Leaving the bridge's block (its Bus going on, with safe=None) stops what clients drove."""
    endpoint = _endpoint()
    async with servobus.Bus(SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2)]), safe=None) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        async with Bridge("n", {"b": (bus, motors)}, config=bridge_config("n", [endpoint])) as bridge:
            remote = await connect("n/b", endpoints=[endpoint]).__aenter__()
            try:
                await remote.cycle([(remote.motor(1), ma.SpeedControl(speed_dps=30.0))], valid_for_s=1.0)
                await _until(lambda: bridge.served["b"].counts["applied"] == 1)
                requests = bus.metrics().requests
            except BaseException:
                await remote.__aexit__(None, None, None)
                raise
        try:
            assert [(m, why) for _, _, m, why in bridge.stop_log] == [(1, "bridge closing")]
            assert bus.metrics().replies >= requests + 1  # the stop, answered before the block ended
        finally:
            await remote.__aexit__(None, None, None)


async def test_a_stop_request_the_motor_does_not_acknowledge_leaves_it_to_the_bridge() -> None:
    """A client's own stop that gets no reply does not release the motor: the bridge stops it."""
    endpoint = _endpoint()
    async with servobus.Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 9)]  # (no device answers as motor 9)
        config = bridge_config("n", [endpoint])
        async with (
            Bridge("n", {"b": (bus, motors)}, config=config) as bridge,
            connect("n/b", endpoints=[endpoint]) as remote,
        ):
            with pytest.raises(servobus.MotorTimeout):
                await remote.motor(9).motor_stop(timeout_s=0.05)
            await _until(lambda: [m for _, _, m, _ in bridge.stop_log] == [9])
            assert bridge.served["b"].owners == {}


async def test_a_motor_the_bridge_does_not_serve_is_none_of_its_business() -> None:
    """A Bus motor left out of the bridge answers locally; the bridge publishes nothing of it and
    lives on."""
    endpoint = _endpoint()
    async with servobus.Bus(SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2)])) as bus:
        served_motor, local = bus.motor(ma.FAMILY, 1), bus.motor(ma.FAMILY, 2)
        async with Bridge("n", {"b": (bus, [served_motor])}, config=bridge_config("n", [endpoint])) as bridge:
            for _ in range(3):
                await local.read_status2()
                await anyio.sleep(0.03)  # (past the states' publishing period)
            async with connect("n/b", endpoints=[endpoint]) as remote:
                assert sorted(remote.motors) == [1]
                assert isinstance(await remote.motor(1).read_status2(), ma.StatusReply)
            assert 2 not in bridge.served["b"].published


async def test_batches_naming_different_motors_are_not_lost_to_each_other(served: Served) -> None:
    """Two batches of one client, for different motors, both waiting for a busy bridge: both taken."""
    async with connect("n/b", endpoints=[served.endpoint]) as remote:
        await remote.cycle([(remote.motor(1), ma.SpeedControl(speed_dps=11.0))], valid_for_s=1.0)
        await remote.cycle([(remote.motor(2), ma.SpeedControl(speed_dps=22.0))], valid_for_s=1.0)
        time.sleep(0.2)  # (both reach the bridge's Zenoh thread while its loop is held here)
        held = served.bridge.served["b"].held
        await _until(lambda: {1, 2} <= set(held))
        assert held[1].command == ma.SpeedControl(speed_dps=11.0)
        assert held[2].command == ma.SpeedControl(speed_dps=22.0)
        assert served.counts()["overwritten"] == 0

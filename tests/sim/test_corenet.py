"""CoreCanNetwork (the C engine) against SimCanNetwork (the reference): the same traffic gives the same
(time, frame) trace, the same device counters and the same plant states, bit for bit.

The device models of all three families are on the bus, with an unlinked sniffer and an unlinked
streamer (asked for their deadline at every event), extended and CAN FD frames, seeded faults both
ways, a bit-rate change, a device removed and added back, and the host driven the way SimTransport
drives a network (advance to each send, then run_ahead). Until the families' C paths are hot,
everything a device does goes through the engine's events to the Python models.
"""

from __future__ import annotations

import math
import os
import random
import time
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow import ControlMode, FdCommand, Setpoint
from servobus.protocols.hollow.codec import request_frame as hollow_frame
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk import LkModel, MotorType
from servobus.protocols.lk.codec import request_frame as lk_frame
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.codec import request_frame as ma_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Device
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.sim.network import SimCanNetwork

from ._standins import Responder, Sniffer, Streamer

Network = SimCanNetwork | CoreCanNetwork
LK_MODEL = LkModel(revision=lk.Revision.V2_36, motor_type=MotorType.MG)


def _devices() -> list[Device]:
    return [
        MyActuatorMotor(1),
        MyActuatorMotor(2),
        MyActuatorMotor(3, revision=ma.Revision.V4_3),
        LkMotor(4, model=LK_MODEL),
        LkMotor(5, model=LK_MODEL),
        HollowMotor(7),
        HollowMotor(8, fd_enabled=True),
        Sniffer(),
        Streamer(period_s=0.0037),
    ]


def _requests(rng: random.Random) -> list[Frame]:
    """Every kind of frame the test host sends, one drawn per send."""
    speed = rng.uniform(-300.0, 300.0)
    return [
        ma_frame(ma.ReadStatus2(), 1),
        ma_frame(ma.ReadStatus1(), 2),
        ma_frame(ma.SpeedControl(speed_dps=speed), 1),
        ma_frame(ma.TorqueControl(current_a=rng.uniform(-2.0, 2.0)), 2),
        ma_frame(ma.ReadStatus2(), 3, revision=ma.Revision.V4_3),
        ma_frame(ma.ReadMultiTurnAngle(), broadcast=True),
        ma_frame(ma.SetCommTimeout(timeout_ms=30), 2),
        lk_frame(lk.ReadStatus2(), motor_id=4, model=LK_MODEL),
        lk_frame(lk.ReadStatus2(), motor_id=5, model=LK_MODEL),
        lk_frame(lk.MotorOff(), motor_id=5, model=LK_MODEL),
        hollow_frame(
            7, Setpoint(position_deg=rng.uniform(-90, 90), speed_rad_s=1.0, kp=10, kd=1, current_a=2.0)
        ),
        hollow_frame(8, FdCommand(mode=ControlMode.VELOCITY, velocity_rpm=30.0, current_raw=1000, run=True)),
        Frame(arbitration_id=0x1ABCDE, data=bytes([rng.randrange(256)] * 4), is_extended_id=True),
        Frame(arbitration_id=0x141, data=bytes(12), is_fd=True, bitrate_switch=True),
        Frame(arbitration_id=0x600, data=b""),
    ]


def _state(network: Network) -> dict[str, Any]:
    """What a test can read of the devices and the bus after a run."""
    out: dict[str, Any] = {"now": network.now_s, "busy": network.bus.busy_s, "frames": network.bus.frames}
    for name, device in network.devices.items():
        if isinstance(device, MyActuatorMotor | LkMotor | HollowMotor):
            plant = device.plant
            out[name] = (
                dict(device.counters),
                plant.position_deg,
                plant.speed_dps,
                plant.current_a,
                plant.temperature_c,
                plant.now_s,
            )
        elif isinstance(device, Sniffer):
            out[name] = list(device.seen)
    return out


def _drive(
    make: Callable[..., Network],
    seed: int,
    *,
    sends: int = 300,
    faults: bool = False,
    bitrate_change: bool = False,
    remove_add: bool = False,
    ahead: bool = True,
) -> tuple[list[tuple[float, Frame]], dict[str, Any]]:
    """Seeded host traffic as SimTransport sends it; the host's trace and the state at the end."""
    rng = random.Random(seed)
    kwargs: dict[str, Any] = {}
    if faults:
        plan = FaultPlan(drop=0.05, corrupt=0.05, duplicate=0.05, reorder=0.05, delay=0.05)
        kwargs = {"to_devices": FaultInjector(plan, seed), "to_host": FaultInjector(plan, seed + 1)}
    network = make(_devices(), bus=CanBusModel(bitrate=1_000_000, data_bitrate=5_000_000), **kwargs)
    trace: list[tuple[float, Frame]] = []
    removed: Device | None = None
    t = 0.0
    for k in range(sends):
        t += rng.choice((0.0, 0.0, 1e-5, 1.3e-4, 4e-4, 2e-3))
        trace += network.advance(t)
        if bitrate_change and k == sends // 2:
            network.bus.bitrate = 500_000
        if remove_add and k == sends // 3:
            removed = network.remove("lk4")
        if remove_add and k == 2 * sends // 3 and removed is not None:
            network.add(removed)
        network.send(rng.choice(_requests(rng)), max(t, network.now_s))
        if ahead:
            network.run_ahead(t)
    trace += network.run_until_idle(0.05)
    return trace, _state(network)


def _same(seed: int, **options: Any) -> list[tuple[float, Frame]]:
    expected = _drive(SimCanNetwork, seed, **options)
    got = _drive(CoreCanNetwork, seed, **options)
    assert got[0] == expected[0]
    assert [t for t, _ in got[0]] == [t for t, _ in expected[0]]  # bit for bit, not approx
    assert got[1] == expected[1]
    return got[0]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_mixed_families_give_the_reference_trace_and_states(seed: int) -> None:
    trace = _same(seed)
    assert len(trace) > 100
    assert any(f.is_fd for _, f in trace) and any(f.arbitration_id == 0x7FF for _, f in trace)


def test_faults_both_ways_give_the_same_seeded_trace() -> None:
    _same(11, faults=True)


def test_a_bit_rate_change_halfway() -> None:
    _same(12, bitrate_change=True)


def test_a_device_removed_and_added_back() -> None:
    _same(13, remove_add=True)


def test_plain_advance_without_run_ahead() -> None:
    _same(14, ahead=False)


def test_everything_at_once() -> None:
    _same(15, faults=True, bitrate_change=True, remove_add=True, sends=500)


def test_a_zero_latency_bus() -> None:
    def run(make: Callable[..., Network]) -> list[tuple[float, Frame]]:
        network = make([Responder(i) for i in (3, 1, 2)] + [Sniffer()], bus=CanBusModel(bitrate=math.inf))
        for motor_id in (3, 1, 2, 1):
            network.send(Frame(arbitration_id=0x140 + motor_id, data=bytes([motor_id])), 0.0)
        return network.run_until_idle()

    assert run(CoreCanNetwork) == run(SimCanNetwork)


def test_frames_the_host_sends_come_back_as_the_same_objects() -> None:
    responder = Responder(1)
    network = CoreCanNetwork([responder])
    request = Frame(arbitration_id=0x141, data=b"\x01\x02")
    network.send(request, 0.0)
    ((_, reply),) = network.run_until_idle()
    assert responder.seen[0][1] is request
    assert reply.arbitration_id == 0x241 and reply.data == b"\x01\x02"


def test_the_bus_facade_reads_as_the_bus_model() -> None:
    for make in (SimCanNetwork, CoreCanNetwork):
        network = make([Responder(1), Responder(2)], bus=CanBusModel(bitrate=500_000, data_bitrate=2_000_000))
        bus = network.bus
        frame = Frame(arbitration_id=0x141, data=bytes(8))
        network.send(frame, 0.001)
        network.send(Frame(arbitration_id=0x142, data=bytes(2)), 0.001)
        assert bus.pending == 2 and bus.queued("host") == 2 and bus.queued("motor1") == 0
        assert bus.head("host") == (0.001, 0.001) and bus.head("motor1") is None
        completion = bus.next_completion()
        assert completion is not None and completion[1] == "host"
        assert completion[0] == 0.001 + bus.frame_time_s(frame) == bus.next_event_s()
        fd = Frame(
            arbitration_id=0x1234567,
            data=bytes(range(48)),
            is_extended_id=True,
            is_fd=True,
            bitrate_switch=True,
        )
        assert bus.frame_time_s(fd) == CanBusModel(bitrate=500_000, data_bitrate=2_000_000).frame_time_s(fd)
        bus.data_bitrate = None
        assert bus.data_bitrate is None and bus.bitrate == 500_000
        network.run_until_idle()
        assert bus.frames == 4 and bus.pending == 0 and bus.next_completion() is None


def test_a_frame_before_the_bus_time_is_refused_as_by_the_reference() -> None:
    for make in (SimCanNetwork, CoreCanNetwork):
        network = make([Responder(1)])
        network.send(Frame(arbitration_id=0x141), 0.0)
        network.advance(0.01)
        with pytest.raises(ValueError, match="before the bus time"):
            network.send(Frame(arbitration_id=0x141), 0.0)


def test_names_are_unique_and_the_host_is_taken() -> None:
    network = CoreCanNetwork([Responder(1)])
    with pytest.raises(ValueError, match="already on this bus"):
        network.add(Responder(1))
    with pytest.raises(ValueError, match="already on this bus"):
        network.add(Sniffer(name="host"))


def test_a_device_on_another_network_is_refused_and_leaves_nothing_behind() -> None:
    motor = MyActuatorMotor(1)
    CoreCanNetwork([motor])
    network = CoreCanNetwork([Responder(2)])
    with pytest.raises(ValueError, match="already on a network"):
        network.add(motor)
    assert list(network.devices) == ["motor2"]
    network.send(Frame(arbitration_id=0x142, data=b"\x01"), 0.0)
    assert [f.arbitration_id for _, f in network.run_until_idle()] == [0x242]


def test_more_devices_than_the_c_network_holds_is_a_clear_error() -> None:
    network = CoreCanNetwork([Sniffer(name=f"s{i}") for i in range(lib.SB_NET_NODES - 1)])
    with pytest.raises(ValueError, match="holds 63 devices"):
        network.add(Sniffer(name="one too many"))


def test_a_long_run_drops_the_frame_log_and_keeps_the_counts() -> None:
    def run(make: Callable[..., Network]) -> dict[str, Any]:
        motors = [MyActuatorMotor(i) for i in range(1, 5)]
        network = make(motors)
        for k in range(3000):  # more frames than the log keeps (network.LOG_LIMIT)
            network.send(ma_frame(ma.ReadStatus2(), 1 + k % 4), k * 3e-4)
            network.advance(k * 3e-4)
        network.run_until_idle()
        return _state(network)

    assert run(CoreCanNetwork) == run(SimCanNetwork)


# ---- the C engine's own contract ----


def test_c_refuses_bad_arguments() -> None:
    net = ffi.new("sb_simnet *")
    null = ffi.NULL
    assert lib.sb_simnet_init(null, 1e6, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_init(net, 0.0, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_init(net, math.nan, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_init(net, 1e6, -1.0) == lib.SB_E_ARG
    assert lib.sb_simnet_init(net, 1e6, 0) == lib.SB_OK
    send = lib.sb_simnet_send
    assert send(net, 0, 0x800, 0, b"", 0, 0.0, 0) == lib.SB_E_ARG  # too wide for a standard id
    assert send(net, 0, 1, 8, b"", 0, 0.0, 0) == lib.SB_E_ARG  # unknown flag
    assert send(net, 0, 1, 0, bytes(9), 9, 0.0, 0) == lib.SB_E_ARG  # classic: 8 bytes at most
    assert send(net, 0, 1, lib.SB_FRAME_BRS, b"", 0, 0.0, 0) == lib.SB_E_ARG  # BRS without FD
    assert send(net, 0, 1, 0, null, 3, 0.0, 0) == lib.SB_E_ARG
    assert send(net, 5, 1, 0, b"", 0, 0.0, 0) == lib.SB_E_ARG  # no such node
    assert send(net, 64, 1, 0, b"", 0, 0.0, 0) == lib.SB_E_ARG
    assert send(net, 0, 1, 0, b"", 0, math.nan, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_add(net, lib.SB_NODE_HOST, 1, 0, 0.0, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_remove(net, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_touch(net, 1) == lib.SB_E_ARG
    n = ffi.new("int *")
    events = ffi.new("sb_netevent[]", 4)
    assert lib.sb_simnet_run(net, 1.0, math.inf, math.inf, 0, null, 4, n) == lib.SB_E_ARG
    assert lib.sb_simnet_run(net, 1.0, math.inf, math.inf, 0, events, 4, null) == lib.SB_E_ARG
    assert lib.sb_simnet_run(net, 1.0, math.inf, math.inf, 16, events, 4, n) == lib.SB_E_ARG
    assert lib.sb_simnet_run(net, math.nan, math.inf, math.inf, 0, events, 4, n) == lib.SB_E_ARG
    assert lib.sb_simnet_run(null, 1.0, math.inf, math.inf, 0, events, 4, n) == lib.SB_E_ARG
    ends, counts = ffi.new("double[]", lib.SB_NET_LOG), ffi.new("int64_t[]", 2)
    assert lib.sb_simnet_catch_up(net, 0, 1, counts, counts + 1, ends, lib.SB_NET_LOG, n) == lib.SB_E_ARG
    node = lib.sb_simnet_add(net, lib.SB_NODE_PYTHON, 1, 0, 0.0, 0)
    assert node == 1
    assert lib.sb_simnet_catch_up(net, node, 1, counts, counts + 1, ends, 10, n) == lib.SB_E_ARG  # room
    assert lib.sb_simnet_set_rates(net, -1.0, 0) == lib.SB_E_ARG
    assert lib.sb_simnet_drop_log(null) == lib.SB_E_ARG
    assert math.isnan(lib.sb_simnet_next_event(null, 0))


def test_c_queue_capacity_is_an_error_not_an_overflow() -> None:
    network = CoreCanNetwork()
    frame = Frame(arbitration_id=0x100)
    for _ in range(lib.SB_NET_FRAMES):
        network.send(frame, 1.0)
    with pytest.raises(RuntimeError, match="queued frames"):
        network.send(frame, 1.0)
    assert network.bus.pending == lib.SB_NET_FRAMES
    received = network.run_until_idle(10.0)
    assert received == [] and network.bus.frames == lib.SB_NET_FRAMES


def test_the_event_buffer_fills_and_the_run_goes_on() -> None:
    network = CoreCanNetwork([Responder(i) for i in range(1, 33)], bus=CanBusModel(bitrate=math.inf))
    reference = SimCanNetwork([Responder(i) for i in range(1, 33)], bus=CanBusModel(bitrate=math.inf))
    for net in (network, reference):
        for _ in range(20):
            for i in range(1, 33):
                net.send(Frame(arbitration_id=0x140 + i, data=bytes([i])), 0.0)
    assert network.run_until_idle() == reference.run_until_idle()


# ---- random traffic ----


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0.0, 0.004),
            st.sampled_from([0x141, 0x142, 0x143, 0x100, 0x7FF, 0x1FFFFFFF, 0x0]),
            st.binary(max_size=8),
            st.booleans(),
            st.booleans(),
        ),
        max_size=60,
    ),
    st.sampled_from([125_000.0, 1_000_000.0, math.inf]),
)
def test_random_traffic_gives_the_reference_trace(
    sends: list[tuple[float, int, bytes, bool, bool]], bitrate: float
) -> None:
    def run(make: Callable[..., Network]) -> tuple[Any, ...]:
        responders = [Responder(i) for i in (1, 2, 3)]
        sniffer = Sniffer()
        network = make([*responders, sniffer, Streamer(period_s=0.0011)], bus=CanBusModel(bitrate=bitrate))
        received: list[tuple[float, Frame]] = []
        for at, can_id, data, extended, fd in sorted(sends, key=lambda s: s[0]):
            if fd and len(data) not in (0, 1, 2, 3, 4, 5, 6, 7, 8):
                continue
            frame = Frame(
                arbitration_id=can_id & (0x1FFFFFFF if extended else 0x7FF),
                data=data,
                is_extended_id=extended,
                is_fd=fd,
            )
            received += network.advance(at)
            network.send(frame, max(at, network.now_s))
            network.run_ahead(at)
        received += network.run_until_idle(0.01)
        return received, sniffer.seen, [r.seen for r in responders], network.bus.busy_s, network.now_s

    assert run(CoreCanNetwork) == run(SimCanNetwork)


# ---- cost ----


def _exchange_cost_us(make: Callable[..., Network], motors: int = 32, rounds: int = 60) -> float:
    """CPU µs per request/reply pair: every motor asked ReadStatus2 once a round, as a control loop does."""
    network = make([MyActuatorMotor(i) for i in range(1, motors + 1)])
    requests = [ma_frame(ma.ReadStatus2(), i) for i in range(1, motors + 1)]
    t = 0.0
    start = time.process_time()
    for _ in range(rounds):
        for request in requests:
            network.send(request, t)
        t += 0.008  # 64 frames of up to 135 bits at 1 Mbit/s: every reply is in before the next round
        assert len(network.advance(t)) == motors
    return (time.process_time() - start) / (rounds * motors) * 1e6


@pytest.mark.skipif("libasan" in os.environ.get("LD_PRELOAD", ""), reason="timing under the sanitizers")
def test_the_engine_costs_no_more_than_the_reference_per_exchange() -> None:
    core = min(_exchange_cost_us(CoreCanNetwork) for _ in range(3))
    python = min(_exchange_cost_us(SimCanNetwork) for _ in range(3))
    print(f"\nper request/reply pair, 32 MyActuator motors: C engine {core:.2f} µs, Python {python:.2f} µs")
    assert core < python * 1.2

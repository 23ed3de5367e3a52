"""The host's raw path into the C network (issue [loop]): ``host_turn`` (one C call: advance, run
ahead, next event; the host's Frames made once, stamped) gives exactly what ``advance`` then
``run_ahead`` give, on the C engine and on the Python reference, on every path C stops on (a Python
model, faults, a full log); the host's send key, the frame checks and the Frame twin."""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from typing import Any

import pytest

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow import ControlMode, FdCommand
from servobus.protocols.hollow.codec import request_frame as hollow_frame
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Device
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.sim.network import LOG_LIMIT, FrameSlots, SimCanNetwork, stamped

from ._standins import Responder, Streamer

Network = CoreCanNetwork | SimCanNetwork
Got = tuple[float, int, bytes, bool, bool, bool, bool]  # timestamp, id, data, extended, FD, BRS, rx


def _myactuator_cycles(seed: int, cycles: int, motors: int) -> list[list[Frame]]:
    """Position set-points (a seeded sine with noise), every fourth cycle a status read."""
    rng = random.Random(seed)
    codecs = [ma.FAMILY.bind(i) for i in range(1, motors + 1)]
    out: list[list[Frame]] = []
    for c in range(cycles):
        if c % 4 == 3:
            out.append([codec.encode(ma.ReadStatus2()) for codec in codecs])
            continue
        out.append(
            [
                codec.encode(
                    ma.AbsolutePositionControl(
                        angle_deg=round(90.0 * math.sin(c / 30 + n) + rng.uniform(-1, 1), 2),
                        max_speed_dps=rng.choice((None, 360.0, 1800.0)),
                    )
                )
                for n, codec in enumerate(codecs)
            ]
        )
    return out


def _fd_cycles(seed: int, cycles: int, motors: int) -> list[list[Frame]]:
    rng = random.Random(seed)
    return [
        [
            hollow_frame(
                i,
                FdCommand(
                    position_deg=round(rng.uniform(-90, 90), 1),
                    velocity_rpm=100.0,
                    current_raw=800,
                    mode=ControlMode.POSITION,
                    run=True,
                ),
            )
            for i in range(1, motors + 1)
        ]
        for _ in range(cycles)
    ]


def _seen(frame: Frame) -> Got:
    return (
        frame.timestamp,
        frame.arbitration_id,
        frame.data,
        frame.is_extended_id,
        frame.is_fd,
        frame.bitrate_switch,
        frame.is_rx,
    )


def _drive(
    net: Network, cycles: Sequence[Sequence[Frame]], turn: Callable[[float], tuple[list[Frame], float | None]]
) -> list[tuple[list[Got], float | None]]:
    """Each cycle's requests at the network's time, then turns until nothing more will happen before
    the next cycle (the replies in): every turn's frames and the time it says comes next."""
    out: list[tuple[list[Got], float | None]] = []
    for batch in cycles:
        t = net.now_s
        for frame in batch:
            net.send(frame, t)
        at = net.next_event_s()
        while at is not None and at < t + 0.02:
            frames, at = turn(at)
            out.append(([_seen(frame) for frame in frames], at))
    return out


def _by_parts(net: Network, stamp_s: float) -> Callable[[float], tuple[list[Frame], float | None]]:
    """The turn as SimTransport took it before host_turn: advance, the host's stamped copies, run_ahead."""

    def turn(until_s: float) -> tuple[list[Frame], float | None]:
        received = net.advance(until_s)
        return [stamped(frame, at + stamp_s) for at, frame in received], net.run_ahead(until_s)

    return turn


class _PythonMotor(MyActuatorMotor):
    """A motor whose receive is its own (a user's device): it stays in Python, linked, and every frame
    it gets and sends is an event that stops the C turn for Python."""

    def receive(self, frame: Frame, now_s: float) -> Any:
        return super().receive(frame, now_s)


def _motors(kind: str) -> list[Device]:
    if kind == "fd":
        return [HollowMotor(i, fd_enabled=True) for i in range(1, 7)]
    if kind == "python model":
        return [*(MyActuatorMotor(i) for i in range(1, 7)), _PythonMotor(7), _PythonMotor(8)]
    if kind == "unlinked":  # devices C asks Python for their deadline before every run
        return [*(MyActuatorMotor(i) for i in range(1, 9)), Responder(20), Streamer(period_s=3e-3)]
    return [MyActuatorMotor(i) for i in range(1, 17)]


def _cycles(kind: str) -> list[list[Frame]]:
    if kind == "fd":
        return _fd_cycles(3, 60, 6)
    cycles = _myactuator_cycles(5, 60, 16 if kind == "myactuator" else 8)
    if kind == "unlinked":
        for batch in cycles:
            batch.append(Frame(arbitration_id=0x140 + 20, data=bytes(range(8))))
    return cycles


def _bus(kind: str) -> CanBusModel:
    return CanBusModel(bitrate=1_000_000, data_bitrate=5_000_000) if kind == "fd" else CanBusModel()


@pytest.mark.parametrize("kind", ["myactuator", "fd", "python model", "unlinked"])
def test_host_turn_gives_what_advance_then_run_ahead_give(kind: str) -> None:
    stamp_s = 100.25
    core_turn, core_parts = (
        CoreCanNetwork(_motors(kind), bus=_bus(kind)),
        CoreCanNetwork(_motors(kind), bus=_bus(kind)),
    )
    py_turn = SimCanNetwork(_motors(kind), bus=_bus(kind))
    cycles = _cycles(kind)
    want = _drive(core_parts, cycles, _by_parts(core_parts, stamp_s))
    assert sum(len(frames) for frames, _ in want) >= 360
    assert _drive(core_turn, cycles, lambda at: core_turn.host_turn(at, stamp_s)) == want
    assert _drive(py_turn, cycles, lambda at: py_turn.host_turn(at, stamp_s)) == want
    for net in (core_turn, py_turn):
        assert net.now_s == core_parts.now_s
        assert net.bus.busy_s == core_parts.bus.busy_s and net.bus.frames == core_parts.bus.frames
    for a, b in zip(core_turn.devices.values(), core_parts.devices.values(), strict=True):
        assert getattr(a, "counters", None) == getattr(b, "counters", None)


def test_the_host_gets_frame_objects_stamped_on_its_clock() -> None:
    net = CoreCanNetwork([MyActuatorMotor(1)])
    request = ma.FAMILY.bind(1).encode(ma.ReadStatus2())
    net.send(request, 0.0)
    frames: list[Frame] = []
    at = net.next_event_s()
    while at is not None and not frames:
        frames, at = net.host_turn(at, 5.0)
    (reply,) = frames
    assert type(reply) is Frame and reply.is_rx and not reply.is_serial
    assert reply.timestamp == 5.0 + net.now_s  # it ended at the network's time, stamped + 5 s
    assert reply == Frame(arbitration_id=0x241, data=reply.data) and hash(reply) == hash(
        Frame(arbitration_id=0x241, data=reply.data)
    )
    with pytest.raises(AttributeError):
        reply.data = b""  # type: ignore[misc]
    assert at is None  # nothing else will happen: the motor is idle


def test_faults_towards_the_host_take_the_python_path_and_give_the_same() -> None:
    plan = FaultPlan(drop=0.05, delay=0.2, delay_s=(1e-4, 2e-3))
    cycles = _myactuator_cycles(9, 40, 8)
    nets = [
        CoreCanNetwork([MyActuatorMotor(i) for i in range(1, 9)], to_host=FaultInjector(plan, 4))
        for _ in range(2)
    ]
    want = _drive(nets[0], cycles, _by_parts(nets[0], 0.0))
    assert _drive(nets[1], cycles, lambda at: nets[1].host_turn(at)) == want


def test_a_turn_that_fills_the_log_drops_it_as_run_ahead_would() -> None:
    motors = 32
    cycles = _myactuator_cycles(11, 2 * LOG_LIMIT // motors // 2 + 8, motors)  # > LOG_LIMIT frames
    nets = [CoreCanNetwork([MyActuatorMotor(i) for i in range(1, motors + 1)]) for _ in range(2)]
    want = _drive(nets[0], cycles, _by_parts(nets[0], 0.0))
    assert _drive(nets[1], cycles, lambda at: nets[1].host_turn(at)) == want
    assert nets[1].bus.frames > LOG_LIMIT
    logged = [int(net._net.log_count - net._net.log_base) for net in nets]
    assert logged[0] == logged[1] < LOG_LIMIT  # dropped at the same turn


def test_a_nan_time_fails_as_advance_does() -> None:
    net = CoreCanNetwork([MyActuatorMotor(1)])
    with pytest.raises(RuntimeError, match="status"):
        net.host_turn(math.nan)


@pytest.mark.parametrize(
    "frame",
    [
        Frame(arbitration_id=0x1ABCDEF0, data=bytes(8), is_extended_id=True),
        Frame(arbitration_id=0x123, data=bytes(range(48)), is_fd=True, bitrate_switch=True),
        Frame(arbitration_id=0x7FF, data=b""),
    ],
)
def test_the_hosts_send_key_carries_id_and_flags(frame: Frame) -> None:
    bus: dict[str, Any] = {"bitrate": 500_000, "data_bitrate": 2_000_000}
    core, python = CoreCanNetwork(bus=CanBusModel(**bus)), SimCanNetwork(bus=CanBusModel(**bus))
    for net in (core, python):
        net.send(frame, 0.0)
        net.advance(1.0)
    assert core.bus.frames == python.bus.frames == 1
    assert core.bus.busy_s == python.bus.busy_s == python.bus.frame_time_s(frame)


def test_a_queued_frame_is_checked_as_its_bit_count_checks_it() -> None:
    net = ffi.new("sb_simnet *")
    nominal, data_bits = ffi.new("int *"), ffi.new("int *")
    for flags in range(-1, 9):
        for can_id in (0, 0x7FF, 0x800, 0x1FFFFFFF, 0x20000000):
            for length in [*range(66), 100]:
                assert lib.sb_simnet_init(net, 1e6, 0.0) == lib.SB_OK
                data = bytes(length)
                counted = lib.sb_can_frame_bits(can_id, flags, data, length, nominal, data_bits) == lib.SB_OK
                queued = lib.sb_simnet_send(net, 0, can_id, flags, data, length, 0.0, 0) >= 0
                assert queued == counted, (flags, hex(can_id), length)


def test_the_frame_twin_has_frames_layout() -> None:
    assert FrameSlots.__slots__ == Frame.__slots__
    original = Frame(
        arbitration_id=0x12345, data=b"\x01\x02", is_extended_id=True, timestamp=1.0, is_rx=False
    )
    copy = stamped(original, 2.5)
    assert type(copy) is Frame and copy == original and copy.timestamp == 2.5 and not copy.is_rx
    assert original.timestamp == 1.0

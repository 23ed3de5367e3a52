"""servobus.Bus through real pseudo-terminals, in real time: the simulator's SLCAN adapter with motors of
all three families on a 1 Mbit/s CAN bus (native SlcanTransport, and python-can's ``slcan``), and
RS485 lines (MyActuator motors on their own line; hollow motors behind the 485 -> CAN FD converter,
transparent at 1 Mbaud and Modbus RTU at 19200). Each test takes well under a second when the
machine is not loaded; timeouts are generous (``T``) because the simulator shares the process.

tests/test_bus.py runs the Bus on the in-process bus with virtual time; the one link it leaves out
there, hollow motors on CAN FD, is at the end of this file, on virtual time too.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import anyio
import pytest

from servobus.bus import Bus, Motor
from servobus.errors import MotorTimeout
from servobus.frame import Frame
from servobus.protocols import Command, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor, RunState
from servobus.protocols.myactuator.rs485 import decode_rs485_request, rs485_deframer
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.sim import virtual
from servobus.sim.attach import serve_rs485, serve_slcan
from servobus.sim.canbus import CanBusModel
from servobus.sim.device import Device, SerialDevice, SerialEmission
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import Off, PositionControl
from servobus.sim.pty import PtyPort
from servobus.timing import uart_time_s
from servobus.transports import CanTransport, SerialTransport, SimTransport, SlcanTransport
from sim._standins import Sniffer
from transports._anyio_help import needs_bus_on, serving

pytestmark = pytest.mark.anyio

MA_IDS = (1, 2, 3)
LK_IDS = (9, 10)
HOLLOW_IDS = (20, 21)
BAUD = 1_000_000
# Real time through a pty and a simulator in the same process: a loaded machine can take milliseconds
# to pass a frame along, more than a motor's own timeout (hollow: 10 ms), so the tests give 0.5 s.
T = 0.5


# ---- SLCAN: all three families on one CAN bus behind a simulated USB adapter ----


@dataclass
class CanBench:
    """The simulated motors on the far side of the adapter, and a sniffer that hears every frame."""

    myactuator: dict[int, MyActuatorMotor] = field(
        default_factory=lambda: {i: MyActuatorMotor(i) for i in MA_IDS}
    )
    lk: dict[int, LkMotor] = field(default_factory=lambda: {i: LkMotor(i) for i in LK_IDS})
    hollow: dict[int, HollowMotor] = field(default_factory=lambda: {i: HollowMotor(i) for i in HOLLOW_IDS})
    sniffer: Sniffer = field(default_factory=Sniffer)

    def network(self) -> SimCanNetwork:
        return SimCanNetwork(
            [*self.myactuator.values(), *self.lk.values(), *self.hollow.values(), self.sniffer]
        )

    def heard(self, frame: Frame) -> int:
        """How many times ``frame`` crossed the bus (a request from the host)."""
        return sum(1 for _, f in self.sniffer.seen if f == frame)


@contextlib.asynccontextmanager
async def slcan_bus(bench: CanBench, *, native: bool = True, **options: Any) -> AsyncIterator[Bus]:
    port = PtyPort()
    transport: SlcanTransport | CanTransport
    if native:
        transport = SlcanTransport(port.path, bitrate=1_000_000)
    else:
        transport = CanTransport(
            "slcan", port.path, bitrate=1_000_000, sleep_after_open=0, ignore_config=True
        )
    needs_bus_on()
    try:
        with anyio.fail_after(5):
            async with serving(serve_slcan(bench.network(), port)), Bus(transport, **options) as bus:
                yield bus
    finally:
        port.close()


def _all_motors(bus: Bus) -> list[Motor]:
    return [
        *(bus.motor("myactuator", i) for i in MA_IDS),
        *(bus.motor("lk", i) for i in LK_IDS),
        *(bus.motor("hollow", i) for i in HOLLOW_IDS),
    ]


def _read(motor: Motor) -> Command:
    """A command each family answers without moving the motor."""
    family = motor.codec.family
    if family == "myactuator":
        return ma.ReadStatus2()
    if family == "lk":
        return lk.ReadStatus1()
    return ho.Start()  # hollow has no read: every frame is a command, and Start moves nothing


def _all_answered(stats: dict[str, int], n: int) -> None:
    """``n`` requests, ``n`` replies, and no frame late, duplicate, unsolicited, malformed or foreign."""
    assert (stats.get("requests"), stats.get("replies")) == (n, n), stats
    bad = ("timeouts", "retries", "late", "duplicate", "unsolicited", "malformed", "foreign")
    assert not any(stats.get(kind) for kind in bad), stats


def _stop_frame(family: str, motor_id: int) -> Frame:
    """The frame of the Bus's default safe command to ``family`` motor ``motor_id`` on CAN."""
    codec = get_family(family).bind(motor_id)
    return codec.encode(codec.safe_command("stop"))


def _check_reply(motor: Motor, reply: object) -> None:
    family = motor.codec.family
    if family == "myactuator":
        assert isinstance(reply, ma.StatusReply) and reply.command is ma.StatusCommand.READ_STATUS_2
    elif family == "lk":
        assert isinstance(reply, lk.Status1Reply) and reply.motor_state is lk.MotorState.ON
    else:
        assert isinstance(reply, ho.NormalReply) and reply.motor_id == motor.motor_id


async def test_single_requests_and_a_cycle_over_native_slcan_reach_every_family() -> None:
    bench = CanBench()
    async with slcan_bus(bench, safe=None) as bus:
        one = await bus.motor("myactuator", 2).read_multi_turn_angle(timeout_s=T)
        status = await bus.motor("lk", 10).read_status2(timeout_s=T)
        started = await bus.motor("hollow", 21).start(timeout_s=T)
        motors = _all_motors(bus)
        results = await bus.cycle([(m, _read(m)) for m in motors], timeout_s=T)
        again = await bus.cycle([(m, _read(m)) for m in motors], timeout_s=T)
        assert isinstance(bus.transport, SlcanTransport)
        stats, line = bus.stats(), bus.transport.stats()
    assert isinstance(one, ma.MultiTurnAngleReply)
    assert isinstance(status, lk.Status2Reply) and status.temperature_c == 25
    assert isinstance(started, ho.NormalReply) and started.motor_id == 21
    for motor, reply in zip(motors * 2, results + again, strict=True):
        _check_reply(motor, reply)
    n = 3 + 2 * len(motors)
    _all_answered(stats, n)
    assert (line.frames_out, line.frames_in, line.bad_frames) == (n, n, 0)
    assert all(bench.heard(m.codec.encode(_read(m))) >= 2 for m in motors)


async def test_a_silent_motor_on_native_slcan_costs_only_its_own_reply() -> None:
    bench = CanBench()
    bench.lk[9].unresponsive = True
    async with slcan_bus(bench, safe=None) as bus:
        motors = _all_motors(bus)
        began = anyio.current_time()
        results = await bus.cycle([(m, _read(m)) for m in motors], timeout_s=0.1)
        took = anyio.current_time() - began
    silent = motors.index(bus.motor("lk", 9))
    assert isinstance(results[silent], MotorTimeout) and "lk motor 9 ReadStatus1" in str(results[silent])
    for i, (motor, reply) in enumerate(zip(motors, results, strict=True)):
        if i != silent:
            _check_reply(motor, reply)
    assert 0.1 <= took < 0.5


async def test_an_exception_over_native_slcan_stops_every_commanded_motor() -> None:
    bench = CanBench()
    with pytest.raises(RuntimeError, match="user code failed"):
        async with slcan_bus(bench, safe_timeout_s=T) as bus:
            await bus.motor("myactuator", 1).speed_control(speed_dps=90.0, timeout_s=T)
            await bus.motor("lk", 9).speed_control(
                speed_dps=90.0, motor_type=lk.MotorType.MG, current_limit_a=1.0, timeout_s=T
            )
            hollow = bus.motor("hollow", 20)
            await hollow.start(timeout_s=T)
            await hollow.setpoint(position_deg=0.0, speed_rad_s=1.0, kp=0, kd=0, current_a=0.5, timeout_s=T)
            for m in _all_motors(bus):  # others are only read (hollow 21: nothing; Start commands)
                if m.motor_id not in (1, 9, 20) and m.codec.family != "hollow":
                    await m.request(_read(m), timeout_s=T)
            assert bench.myactuator[1].control != Off() and bench.hollow[20].enabled
            await anyio.sleep(0.05)  # the motors run for a while
            raise RuntimeError("user code failed")
    # Each commanded motor got its family's stop, once, and acted on it.
    stops = {
        (family, i): _stop_frame(family, i)
        for family, ids in (("myactuator", MA_IDS), ("lk", LK_IDS), ("hollow", HOLLOW_IDS))
        for i in ids
    }
    heard = {key: bench.heard(frame) for key, frame in stops.items()}
    assert heard == {key: int(key in {("myactuator", 1), ("lk", 9), ("hollow", 20)}) for key in stops}
    assert isinstance(bench.myactuator[1].control, PositionControl)  # 0x81: hold where it is
    assert bench.lk[9].state is RunState.STOPPED
    assert not bench.hollow[20].enabled
    assert bench.myactuator[2].control == Off() and bench.lk[10].state is RunState.ON


async def test_requests_over_python_can_slcan_reach_every_family() -> None:
    bench = CanBench()
    async with slcan_bus(bench, native=False, safe=None) as bus:
        motors = _all_motors(bus)
        results = [await m.request(_read(m), timeout_s=T) for m in motors]
        stats = bus.stats()
    for motor, reply in zip(motors, results, strict=True):
        _check_reply(motor, reply)
    _all_answered(stats, len(motors))


# ---- RS485: half-duplex lines, one request at a time ----


@dataclass
class Timed:
    """A serial device, and when it heard each frame and when its reply left the line (sim clock)."""

    device: SerialDevice
    heard: list[float] = field(default_factory=list)
    replied: list[float] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.device.name

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        out = self.device.receive_bytes(data, now_s)
        self.heard.append(now_s)
        self.replied += [e.ready_s + uart_time_s(len(e.data), BAUD) for e in out]
        return out

    def poll(self, now_s: float) -> list[SerialEmission]:
        return self.device.poll(now_s)

    def next_deadline_s(self) -> float | None:
        return self.device.next_deadline_s()


@contextlib.asynccontextmanager
async def rs485_bus(
    devices: Sequence[SerialDevice], family: str, *, link: str = "rs485", baud: int = BAUD, **options: Any
) -> AsyncIterator[Bus]:
    """A Bus on a SerialTransport whose framing is ``family``'s on ``link``, to ``devices`` on a pty."""
    port = PtyPort()
    framing = get_family(family).bind(1, link=link).framing
    needs_bus_on()
    try:
        transport = SerialTransport(port.path, framing=framing, baud=baud)
        with anyio.fail_after(5):
            async with serving(serve_rs485(devices, port, baud=baud)), Bus(transport, **options) as bus:
                yield bus
    finally:
        port.close()


def _one_at_a_time(timed: Timed) -> None:
    """Every request was answered once, and each came only after the reply before it had left the
    line: the Bus waits for the reply on a half-duplex line (the time each reply's last byte would
    end at the baud rate; the simulator writes it no sooner)."""
    assert len(timed.replied) == len(timed.heard) > 1
    for reply_end, next_heard in zip(timed.replied, timed.heard[1:], strict=False):
        assert next_heard >= reply_end


@dataclass
class Line:
    """Several serial devices as one (every device hears every byte), so one Timed can watch them all."""

    devices: list[MyActuatorRs485Motor]
    name: str = "line"

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        return list(itertools.chain.from_iterable(d.receive_bytes(data, now_s) for d in self.devices))

    def poll(self, now_s: float) -> list[SerialEmission]:
        return list(itertools.chain.from_iterable(d.poll(now_s) for d in self.devices))

    def next_deadline_s(self) -> float | None:
        return min((t for d in self.devices if (t := d.next_deadline_s()) is not None), default=None)


@dataclass
class Heard:
    """A passive node on a MyActuator RS485 line: the requests the host wrote, decoded."""

    name: str = "heard"
    requests: list[tuple[int, Command]] = field(default_factory=list)
    deframer: Any = field(default_factory=rs485_deframer)

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        self.requests += [decode_rs485_request(bytes(frame)) for frame in self.deframer.feed(data)]
        return []

    def poll(self, now_s: float) -> list[SerialEmission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


async def test_myactuator_rs485_motors_answer_a_request_and_a_cycle_one_at_a_time() -> None:
    fronts = {i: MyActuatorRs485Motor(MyActuatorMotor(i)) for i in MA_IDS}
    line = Timed(Line(list(fronts.values())))
    async with rs485_bus([line], "myactuator", safe=None) as bus:
        assert bus.scheduler.one_at_a_time and bus.scheduler.max_in_flight == 1
        motors = [bus.motor("myactuator", i, link="rs485") for i in MA_IDS]
        status = await motors[0].read_status1(timeout_s=T)
        items: list[tuple[Motor, Command]] = [
            *((m, ma.ReadStatus2()) for m in motors),
            *((m, ma.ReadMultiTurnAngle()) for m in motors),
        ]
        results = await bus.cycle(items, timeout_s=T)
        stats = bus.stats()
    assert isinstance(status, ma.Status1Reply) and status.voltage_v > 0
    assert [type(r) for r in results] == [ma.StatusReply] * 3 + [ma.MultiTurnAngleReply] * 3
    _all_answered(stats, 7)
    assert len(line.heard) == 7 and len(line.replied) == 7
    _one_at_a_time(line)


async def test_an_exception_on_rs485_stops_every_commanded_motor() -> None:
    fronts = {i: MyActuatorRs485Motor(MyActuatorMotor(i)) for i in MA_IDS}
    heard = Heard()
    with pytest.raises(RuntimeError, match="user code failed"):
        async with rs485_bus([*fronts.values(), heard], "myactuator", safe_timeout_s=T) as bus:
            await bus.motor("myactuator", 1, link="rs485").speed_control(speed_dps=60.0, timeout_s=T)
            await bus.motor("myactuator", 3, link="rs485").torque_control(current_a=0.2, timeout_s=T)
            await bus.motor("myactuator", 2, link="rs485").read_status2(timeout_s=T)
            raise RuntimeError("user code failed")
    assert heard.requests[:3] == [
        (1, ma.SpeedControl(speed_dps=60.0)),
        (3, ma.TorqueControl(current_a=0.2)),
        (2, ma.ReadStatus2()),
    ]
    assert sorted(heard.requests[3:]) == [(1, ma.MotorStop()), (3, ma.MotorStop())]  # one each, no more
    assert isinstance(fronts[1].motor.control, PositionControl)  # 0x81: hold where it is
    assert isinstance(fronts[3].motor.control, PositionControl)
    assert fronts[2].motor.control == Off()
    assert [fronts[i].counters["replies"] for i in MA_IDS] == [2, 1, 2]


async def test_hollow_motors_behind_the_rs485_converter_answer_and_are_stopped() -> None:
    converter = HollowConverter([HollowMotor(i, fd_enabled=True) for i in (1, 2)])
    line = Timed(converter)
    with pytest.raises(RuntimeError, match="user code failed"):
        async with rs485_bus([line], "hollow", safe_timeout_s=T) as bus:
            motors = [bus.motor("hollow", i, link="rs485") for i in (1, 2)]
            first = await motors[0].request(ho.FdCommand(), timeout_s=T)
            results = await bus.cycle([(m, ho.FdCommand(run=True)) for m in motors], timeout_s=T)
            assert all(m.enabled for m in converter.motors.values())
            raise RuntimeError("user code failed")
    assert isinstance(first, ho.FdReply) and first.slave_id == 1 and not first.running
    assert [(r.slave_id, r.running) for r in results] == [(1, True), (2, True)]  # type: ignore[union-attr]
    assert not any(m.enabled for m in converter.motors.values())  # the safe stop: FdCommand(run=False)
    assert len(line.heard) == 5
    _one_at_a_time(line)


async def test_hollow_motors_behind_the_modbus_converter_answer_and_are_stopped() -> None:
    converter = HollowConverter([HollowMotor(i, fd_enabled=True) for i in (5, 6)], mode=ConverterMode.MODBUS)
    line = Timed(converter)
    with pytest.raises(RuntimeError, match="user code failed"):
        async with rs485_bus([line], "hollow", link="modbus", baud=19_200, safe_timeout_s=T) as bus:
            motors = [bus.motor("hollow", i, link="modbus") for i in (5, 6)]
            acks = await bus.cycle(
                [(m, ho.ModbusWrite(slave_id=m.motor_id, command=ho.FdCommand(run=True))) for m in motors],
                timeout_s=T,
            )
            read = await motors[1].request(ho.ModbusRead(slave_id=6), timeout_s=T)
            assert all(m.enabled for m in converter.motors.values())
            raise RuntimeError("user code failed")
    assert [(type(a), a.slave_id) for a in acks] == [(ho.ModbusWriteAck, 5), (ho.ModbusWriteAck, 6)]  # type: ignore[union-attr]
    assert isinstance(read, ho.ModbusReadReply) and read.slave_id == 6 and read.reply.running
    assert not any(m.enabled for m in converter.motors.values())  # the safe stop, written through Modbus
    assert len(line.heard) == 5
    _one_at_a_time(line)


# ---- the in-process bus, virtual time: the link tests/test_bus.py leaves out ----


def test_hollow_can_fd_motors_share_the_in_process_bus_with_the_other_families() -> None:
    needs_bus_on()
    hollow = {i: HollowMotor(i, fd_enabled=True) for i in HOLLOW_IDS}
    devices: list[Device] = [MyActuatorMotor(1), LkMotor(9), *hollow.values()]

    async def scenario() -> tuple[list[Any], float]:
        transport = SimTransport(devices=devices, bus=CanBusModel(data_bitrate=5_000_000))
        async with Bus(transport) as bus:
            loop = asyncio.get_running_loop()
            began = loop.time()
            results = await bus.cycle(
                [
                    (bus.motor("myactuator", 1), ma.ReadStatus2()),
                    (bus.motor("lk", 9), lk.ReadStatus1()),
                    *((bus.motor("hollow", i, link="canfd"), ho.FdCommand(run=True)) for i in HOLLOW_IDS),
                ]
            )
            assert all(m.enabled for m in hollow.values())
            return results, loop.time() - began

    results, took = virtual.run(scenario())
    assert isinstance(results[0], ma.StatusReply) and isinstance(results[1], lk.Status1Reply)
    assert [(r.slave_id, r.running) for r in results[2:]] == [(i, True) for i in HOLLOW_IDS]
    assert took < 0.002  # four exchanges on 1 Mbit/s with a 5 Mbit/s data phase, virtual time
    assert not any(m.enabled for m in hollow.values())  # left the block: the commanded hollows stop

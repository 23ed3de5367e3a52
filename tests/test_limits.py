"""Host-side limits (servobus.limits): which fields meet which limit in every family, refused or
clamped, the file, and the Bus applying them to every way a command leaves (request, cycle, a
pipelined Loop, broadcast), counted; the simulated drives given the same envelope."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus import Bus, LimitBook, LimitExceeded, Limits
from servobus.limits import _plan, angle_of, load, parse
from servobus.loop import Loop
from servobus.protocols import FAMILIES, Command, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.limits import bound
from servobus.transports.sim import SimTransport
from sim._standins import Sniffer

# ---- which fields meet which limit ----


def _commands(family: str) -> list[type[Command]]:
    return [c for c in get_family(family).commands if dataclasses.is_dataclass(c)]


def test_every_family_command_field_with_a_unit_meets_its_limit() -> None:
    quantities = {}
    for family in FAMILIES:
        for cls in _commands(family):
            for name, quantity, _, _ in _plan(cls):
                quantities[f"{family}.{cls.__name__}.{name}"] = quantity
    expected = {
        "myactuator.SpeedControl.speed_dps": "speed_dps",
        "myactuator.AbsolutePositionControl.angle_deg": "position_deg",
        "myactuator.AbsolutePositionControl.max_speed_dps": "speed_dps",
        "myactuator.TorqueControl.current_a": "current_a",
        "myactuator.WriteAcceleration.acceleration_dps_s": "acceleration_dps_s",
        "myactuator.MotionCommand.position_rad": "position_deg",
        "myactuator.MotionCommand.velocity_rad_s": "speed_dps",
        "myactuator.MotionCommand.torque_ff_nm": "torque_nm",
        "lk.SpeedControl.current_limit_a": "current_a",
        "lk.IncrementalPosition.increment_deg": "position_deg",
        "lk.WriteAcceleration.acceleration_dps2": "acceleration_dps_s",
        "lk.MultiMotorTorque.currents_a": "current_a",
        "hollow.Setpoint.position_deg": "position_deg",
        "hollow.Setpoint.speed_rad_s": "speed_dps",
        "hollow.Setpoint.current_a": "current_a",
        "hollow.FdCommand.velocity_rpm": "speed_dps",
    }
    for key, quantity in expected.items():
        assert quantities.get(key) == quantity, key
    # raw counts, percentages, indices and ids meet no quantity limit (a ``fields`` range instead)
    assert not any(k.endswith(("_pct", "_counts", "_raw", "_ms", "motor_id", "index")) for k in quantities)


def test_relative_and_single_turn_commands_say_so() -> None:
    assert ma.IncrementalPositionControl.POSITION == "relative"
    assert lk.IncrementalPositionSpeed.POSITION == "relative"
    assert ho.IncrementalSetpoint.POSITION == "relative"
    assert ma.SingleTurnPositionControl.POSITION == "single_turn"
    assert lk.SingleTurnPositionV235.POSITION == "single_turn"
    assert ma.AbsolutePositionControl.POSITION == "absolute"


# ---- refused or clamped ----


def test_a_speed_beyond_the_limit_is_refused_naming_field_value_and_limit() -> None:
    limits = Limits(speed_dps=720)
    assert limits.apply(ma.SpeedControl(speed_dps=-720.0)) == ma.SpeedControl(speed_dps=-720.0)
    with pytest.raises(
        LimitExceeded, match=r"SpeedControl\.speed_dps=10000 is beyond the host limit speed_dps 720"
    ):
        limits.apply(ma.SpeedControl(speed_dps=10000.0))
    with pytest.raises(ValueError):  # (a LimitExceeded is a ValueError, as a set-point out of range)
        limits.apply(ma.SpeedControl(speed_dps=-721.0))


def test_clamped_keeps_the_sign_and_the_other_fields() -> None:
    limits = Limits(speed_dps=720, clamp=True)
    command = ma.SpeedControl(speed_dps=-5000.0, max_torque_pct=40)
    assert limits.apply(command) == ma.SpeedControl(speed_dps=-720.0, max_torque_pct=40)


def test_an_open_speed_bound_is_beyond_any_speed_limit() -> None:
    command = ma.AbsolutePositionControl(angle_deg=10.0, max_speed_dps=None)
    with pytest.raises(LimitExceeded, match="max_speed_dps=none"):
        Limits(speed_dps=100).apply(command)
    assert Limits(speed_dps=100, clamp=True).apply(command).max_speed_dps == 100  # type: ignore[attr-defined]
    assert Limits().apply(command) is command


def test_units_are_converted_to_the_limit_s() -> None:
    mit = ma.MotionCommand(position_rad=1.0, velocity_rad_s=20.0, kp=10, kd=1, torque_ff_nm=0.5)
    # 20 rad/s = 1146 dps; 1 rad = 57.3 deg
    with pytest.raises(
        LimitExceeded, match=r"velocity_rad_s=20 is beyond the host limit speed_dps 720 \(12\.57"
    ):
        Limits(speed_dps=720).apply(mit)
    clamped = Limits(speed_dps=720, position_deg=(-45, 45), clamp=True).apply(mit)
    assert clamped.velocity_rad_s == pytest.approx(math.radians(720))  # type: ignore[attr-defined]
    assert clamped.position_rad == pytest.approx(math.radians(45))  # type: ignore[attr-defined]
    fd = ho.FdCommand(velocity_rpm=200.0, mode=ho.ControlMode.VELOCITY, run=True)
    with pytest.raises(LimitExceeded, match="velocity_rpm=200"):  # 200 rpm = 1200 dps
        Limits(speed_dps=1000).apply(fd)


def test_a_position_range_checks_absolute_targets_and_increments_from_the_last_angle() -> None:
    limits = Limits(position_deg=(-90, 90))
    assert limits.apply(ma.AbsolutePositionControl(angle_deg=90.0, max_speed_dps=100))
    with pytest.raises(
        LimitExceeded, match=r"angle_deg=91 is beyond the host limit position_deg \[-90, 90\]"
    ):
        limits.apply(ma.AbsolutePositionControl(angle_deg=91.0, max_speed_dps=100))
    step = ma.IncrementalPositionControl(angle_deg=30.0, max_speed_dps=100)
    with pytest.raises(LimitExceeded, match="angle is not known yet"):
        limits.apply(step)
    at_70 = ma.StatusReply(temperature_c=25, current_a=0.0, speed_dps=0.0, angle_deg=70.0)
    with pytest.raises(LimitExceeded, match=r"to 100 deg from 70"):
        limits.apply(step, at_70)
    assert limits.apply(dataclasses.replace(step, angle_deg=-30.0), at_70).angle_deg == -30.0  # type: ignore[attr-defined]
    clamped = Limits(position_deg=(-90, 90), clamp=True).apply(step, at_70)
    assert clamped.angle_deg == pytest.approx(20.0)  # type: ignore[attr-defined]
    with pytest.raises(LimitExceeded, match="single-turn"):
        Limits(position_deg=(-90, 90), clamp=True).apply(
            ma.SingleTurnPositionControl(
                angle_deg=10.0, max_speed_dps=100, direction=ma.SpinDirection.CLOCKWISE
            )
        )


def test_each_current_of_a_multi_motor_frame_is_limited() -> None:
    command = lk.MultiMotorTorque(motor_type=lk.MotorType.MF, currents_a=(1.0, -9.0, 0.0, 2.0))
    with pytest.raises(LimitExceeded, match="currents_a"):
        Limits(current_a=5).apply(command)
    clamped = Limits(current_a=5, clamp=True).apply(command)
    assert clamped.currents_a == pytest.approx((1.0, -5.0, 0.0, 2.0))  # type: ignore[attr-defined]


def test_field_ranges_cover_gains_and_settings_by_class_first() -> None:
    limits = Limits(fields={"kp": (0, 50), "WritePidRam.value": (0, 5)})
    with pytest.raises(
        LimitExceeded, match=r"WritePidRam\.value=99999 is beyond the host limit fields value \[0, 5\]"
    ):
        limits.apply(ma.WritePidRam(index=ma.PidIndex.SPEED_KP, value=99999))
    mit = ma.MotionCommand(position_rad=0.0, velocity_rad_s=0.0, kp=400, kd=1, torque_ff_nm=0)
    with pytest.raises(LimitExceeded, match="kp=400"):
        limits.apply(mit)
    assert Limits(fields={"kp": (0, 50)}, clamp=True).apply(mit).kp == 50  # type: ignore[attr-defined]


def test_a_command_without_limited_fields_is_the_same_object() -> None:
    command = ma.ReadStatus2()
    assert Limits(speed_dps=1, current_a=1, position_deg=(0, 0)).apply(command) is command


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"speed_dps": -1}, "speed_dps=-1: expected a finite number >= 0"),
        ({"current_a": math.inf}, "current_a=inf"),
        ({"position_deg": (10, -10)}, "expected finite low <= high"),
        ({"fields": {"kp": (1,)}}, r"fields\['kp'\]"),
    ],
)
def test_bad_limits_are_refused_when_declared(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Limits(**kwargs)


# ---- the file ----

FILE = """
clamp = true
[all]
speed_dps = 720
current_a = 8.0
[motor.1]
position_deg = [-90, 90]
current_a = 3
[motor."2-3"]
fields = { kp = [0, 50] }
"""


def test_a_file_gives_each_motor_its_own_over_all(tmp_path: Any) -> None:
    path = tmp_path / "limits.toml"
    path.write_text(FILE)
    book = load(path)
    one = book.of(1)
    assert one == Limits(position_deg=(-90, 90), speed_dps=720, current_a=3, clamp=True)
    assert book.of(3) == Limits(speed_dps=720, current_a=8, fields={"kp": (0, 50)}, clamp=True)
    assert book.of(9) == Limits(speed_dps=720, current_a=8, clamp=True)
    assert LimitBook().of(1) is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("speed_dps = 1", "unknown key 'speed_dps'"),
        ("[all]\nspeed = 1", "unknown limit 'speed'"),
        ("[motor.x]\nspeed_dps = 1", r"\[motor\.x\]: a motor id or a range"),
        ('[motor."4-2"]\nspeed_dps = 1', "ids between 0 and 2047, low to high"),
        ("[all]\nposition_deg = 5", r"position_deg=5: expected \[low, high\]"),
        ("clamp = 1", "clamp=1: true or false"),
        ("[all\n", "not TOML"),
    ],
)
def test_a_bad_file_is_one_line_naming_where(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message) as caught:
        parse(text, source="lim.toml")
    assert str(caught.value).startswith("lim.toml") and "\n" not in str(caught.value)


# ---- through the Bus ----


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


def _sent(sniffer: Sniffer, code: int) -> list[bytes]:
    return [
        bytes(f.data) for _, f in sniffer.seen if 0x141 <= f.arbitration_id <= 0x160 and f.data[0] == code
    ]


@pytest.mark.anyio
async def test_the_bus_refuses_before_a_frame_leaves_and_counts_it() -> None:
    sniffer = Sniffer()
    async with Bus(
        SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2), sniffer]), limits=Limits(speed_dps=360)
    ) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        with pytest.raises(LimitExceeded, match=r"myactuator motor 1 on sim: SpeedControl\.speed_dps=1000"):
            await motor.speed_control(speed_dps=1000.0)
        other = bus.motor(ma.FAMILY, 2)
        with pytest.raises(LimitExceeded):  # a tick: nothing of it is sent
            await bus.cycle(
                [(other, ma.SpeedControl(speed_dps=10.0)), (motor, ma.SpeedControl(speed_dps=-400.0))]
            )
        assert _sent(sniffer, 0xA2) == []
        assert bus.metrics().limit_refused == 2 and motor.metrics().limit_refused == 2
        assert bus.metrics().requests == 0 and bus.commanded == ()
        await motor.speed_control(speed_dps=360.0)
        assert len(_sent(sniffer, 0xA2)) == 1


@pytest.mark.anyio
async def test_the_bus_clamps_per_motor_and_the_motor_runs_at_the_limit() -> None:
    sim = MyActuatorMotor(1)
    async with Bus(SimTransport(devices=[sim, MyActuatorMotor(2)])) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        motor.limits = Limits(speed_dps=90, clamp=True)
        free = bus.motor(ma.FAMILY, 2)
        for _ in range(100):
            await bus.cycle(
                [(motor, ma.SpeedControl(speed_dps=1000.0)), (free, ma.SpeedControl(speed_dps=180.0))]
            )
            await anyio.sleep(0.01)
        status = await motor.read_status2()
        assert status.speed_dps == pytest.approx(90.0, abs=3.0)
        assert (await free.read_status2()).speed_dps == pytest.approx(180.0, abs=3.0)
        assert motor.metrics().limit_clamped == 100 and free.metrics().limit_clamped == 0
        motor.limits = None  # (taken away at any time)
        await motor.speed_control(speed_dps=1000.0)
        assert bus.metrics().limit_clamped == 100


@pytest.mark.anyio
async def test_a_pipelined_loop_meets_the_same_limits() -> None:
    async with Bus(
        SimTransport(devices=[MyActuatorMotor(1)]), limits=LimitBook(motors={1: Limits(current_a=2)})
    ) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        with pytest.raises(LimitExceeded, match=r"TorqueControl\.current_a=3"):
            async with Loop(200) as loop:
                async for tick in loop.ticks(count=5):
                    tick.command(motor, ma.TorqueControl(current_a=1.0 + tick.index))
        assert bus.metrics().limit_refused == 1


@pytest.mark.anyio
async def test_a_broadcast_is_within_every_motor_s_limits() -> None:
    sniffer = Sniffer()
    devices = [MyActuatorMotor(1), MyActuatorMotor(2), sniffer]
    async with Bus(SimTransport(devices=devices)) as bus:
        one, two = bus.motor(ma.FAMILY, 1), bus.motor(ma.FAMILY, 2)
        one.limits, two.limits = Limits(current_a=2, clamp=True), Limits(current_a=1, clamp=True)
        await bus.broadcast(ma.TorqueControl(current_a=5.0), [one, two])
        frames = [bytes(f.data) for _, f in sniffer.seen if f.arbitration_id == 0x280]
        assert frames == [ma.TorqueControl(current_a=1.0).encode()]


@pytest.mark.anyio
async def test_a_relative_move_is_checked_from_the_motor_s_last_status() -> None:
    async with Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        motor.limits = Limits(position_deg=(-10, 10))
        step = ma.IncrementalPositionControl(angle_deg=20.0, max_speed_dps=100)
        with pytest.raises(LimitExceeded, match="not known yet"):
            await motor.request(step)
        await motor.read_status2()
        assert angle_of(motor.state) == 0.0
        with pytest.raises(LimitExceeded, match="to 20 deg from 0"):
            await motor.request(step)
        await motor.request(dataclasses.replace(step, angle_deg=5.0))


# ---- the simulated drives' own envelope ----


@pytest.mark.anyio
async def test_the_simulated_drive_keeps_the_file_s_speed_and_current() -> None:
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    assert bound(devices, LimitBook(motors={1: Limits(speed_dps=90, current_a=1.5)})) == 1
    assert devices[0].plant.params.speed_limit_dps == 90 and devices[0].plant.params.max_current_a == 1.5
    assert devices[1].plant.params.speed_limit_dps == math.inf
    async with Bus(SimTransport(devices=devices)) as bus:  # no host-side limits: the drive's own
        motors = [bus.motor(ma.FAMILY, i) for i in (1, 2)]
        for _ in range(100):
            await bus.cycle([(m, ma.SpeedControl(speed_dps=500.0)) for m in motors])
            await anyio.sleep(0.01)
        one, two = [await m.read_status2() for m in motors]
        assert one.speed_dps == pytest.approx(90.0, abs=3.0) and two.speed_dps == pytest.approx(
            500.0, abs=10.0
        )
        torque = await motors[0].torque_control(current_a=10.0)
        await anyio.sleep(0.05)
        assert abs((await motors[0].read_status2()).current_a) <= 1.5 + 1e-6
        assert torque is not None


# ---- through a real transport path: python-can's virtual bus ----


def test_limits_from_a_file_hold_through_python_can_s_virtual_bus(tmp_path: Any) -> None:
    import time

    import can

    from servobus.sim.attach import serve_python_can
    from servobus.sim.network import SimCanNetwork
    from servobus.transports import CanTransport

    path = tmp_path / "limits.toml"
    path.write_text("[motor.1]\nspeed_dps = 60\n[motor.2]\nspeed_dps = 60\n")
    sniffer = Sniffer()
    network = SimCanNetwork([MyActuatorMotor(1), MyActuatorMotor(2), sniffer])
    channel = f"limits-{time.monotonic_ns()}"

    async def main() -> tuple[int, int]:
        sim_side = can.Bus(interface="virtual", channel=channel)
        try:
            with anyio.fail_after(10):
                async with anyio.create_task_group() as group:
                    group.start_soon(lambda: serve_python_can(network, sim_side))
                    transport = CanTransport("virtual", channel, ignore_config=True)
                    async with Bus(transport, limits=load(path)) as bus:
                        one, two = bus.motor(ma.FAMILY, 1), bus.motor(ma.FAMILY, 2)
                        await one.read_status2(timeout_s=0.5)  # (the first exchange through the adapter)
                        with pytest.raises(LimitExceeded, match="speed_dps 60"):
                            await one.speed_control(speed_dps=61.0)
                        two.limits = dataclasses.replace(two.limits, clamp=True)  # type: ignore[arg-type]
                        await two.speed_control(speed_dps=-600.0, timeout_s=0.5)
                        metrics = bus.metrics()
                    group.cancel_scope.cancel()
        finally:
            sim_side.shutdown()
        return metrics.limit_refused, metrics.limit_clamped

    assert anyio.run(main) == (1, 1)
    speeds = [
        int.from_bytes(bytes(f.data[4:8]), "little", signed=True) / 100
        for _, f in sniffer.seen
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == b"\xa2"  # (requests, not replies)
    ]
    assert speeds == [-60.0]


def test_out_of_its_range_a_motor_is_not_driven_further_out() -> None:
    """Sent as 0, whether the limits refuse or clamp: where the motor is, no caller can check."""
    at_95 = ma.StatusReply(temperature_c=25, current_a=0.0, speed_dps=0.0, angle_deg=95.0)
    for limits in (Limits(position_deg=(-90, 90)), Limits(position_deg=(-90, 90), clamp=True)):
        assert limits.apply(ma.SpeedControl(speed_dps=30.0), at_95) == ma.SpeedControl(speed_dps=0.0)
        assert limits.apply(ma.TorqueControl(current_a=0.5), at_95) == ma.TorqueControl(current_a=0.0)
        back = ma.SpeedControl(speed_dps=-30.0)
        assert limits.apply(back, at_95) is back
        inside = ma.StatusReply(temperature_c=25, current_a=0.0, speed_dps=0.0, angle_deg=89.0)
        forward = ma.SpeedControl(speed_dps=30.0)
        assert limits.apply(forward, inside) is forward


@pytest.mark.anyio
async def test_one_motor_out_of_its_range_costs_the_others_nothing_of_the_tick() -> None:
    sniffer = Sniffer()
    async with Bus(SimTransport(devices=[MyActuatorMotor(1), MyActuatorMotor(2), sniffer])) as bus:
        one, two = bus.motor(ma.FAMILY, 1), bus.motor(ma.FAMILY, 2)
        one.limits = Limits(position_deg=(-10, 10))  # refusing, not clamping
        for _ in range(60):  # motor 1 runs out of its range at 60 dps
            await bus.cycle([(one, ma.SpeedControl(speed_dps=60.0)), (two, ma.SpeedControl(speed_dps=60.0))])
            await anyio.sleep(0.01)
        results = await bus.cycle(
            [(one, ma.SpeedControl(speed_dps=60.0)), (two, ma.SpeedControl(speed_dps=60.0))]
        )
        assert all(isinstance(r, ma.StatusReply) for r in results)
        assert 10.0 < (await one.read_status2()).angle_deg < 30.0
        assert (await two.read_status2()).angle_deg > 30.0
        assert one.metrics().limit_clamped > 0 and one.metrics().limit_refused == 0
        sent_to_1 = [f.data for _, f in sniffer.seen if f.arbitration_id == 0x141 and f.data[0] == 0xA2]
        assert sent_to_1[-1] == ma.SpeedControl(speed_dps=0.0).encode()


@pytest.mark.anyio
async def test_a_speed_loop_stops_its_motor_at_the_edge_of_its_range() -> None:
    async with Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        motor.limits = Limits(position_deg=(-90, 90), clamp=True)
        for _ in range(150):  # 1.5 s at 180 dps: 270 deg without the limit
            await bus.cycle([(motor, ma.SpeedControl(speed_dps=180.0))])
            await anyio.sleep(0.01)
        status = await motor.read_status2()
        assert 90.0 < status.angle_deg < 100.0 and abs(status.speed_dps) < 5.0
        assert motor.metrics().limit_clamped > 50


def test_the_blocking_api_sets_and_meets_a_motor_s_limits() -> None:
    from servobus import sync

    with sync.Bus(SimTransport(devices=[MyActuatorMotor(1)]), limits=Limits(current_a=1)) as bus:
        motor = bus.motor(ma.FAMILY, 1)
        assert motor.limits == Limits(current_a=1)
        with pytest.raises(LimitExceeded, match=r"TorqueControl\.current_a=2"):
            motor.torque_control(current_a=2.0)
        motor.limits = Limits(speed_dps=10)
        motor.torque_control(current_a=2.0)
        with pytest.raises(LimitExceeded, match="speed_dps 10"):
            motor.speed_control(speed_dps=100.0)


# ---- what the review found: stops, single-turn angles, frames for several motors, bounds, modes ----


@pytest.mark.anyio
async def test_a_safe_command_is_never_limited_and_the_safe_stop_goes_out() -> None:
    from servobus.cli._connect import sim_devices

    async with Bus(SimTransport(devices=sim_devices("hollow", (1,), fd=True))) as bus:
        motor = bus.motor(ho.FAMILY, 1, link="canfd")
        motor.limits = Limits(position_deg=(10, 90))  # the stop frame's position is 0
        stop = motor.codec.safe_command("stop")
        assert motor.limited(stop) is stop
        await motor.request(ho.FdCommand(position_deg=45.0, mode=ho.ControlMode.POSITION, run=True, kp=10))
    assert bus.safe_sent == (motor,) and bus.safe_acknowledged == (motor,)
    assert motor.metrics().limit_refused == 0


def test_a_single_turn_angle_is_not_where_the_motor_is() -> None:
    step = ma.IncrementalPositionControl(angle_deg=300.0, max_speed_dps=100)
    limits = Limits(position_deg=(-720, 720))
    within_turn = ma.SingleTurnAngleReply(angle_deg=140.0)
    with pytest.raises(LimitExceeded, match="not known yet"):
        limits.apply(step, within_turn)
    at_500 = ma.MultiTurnAngleReply(angle_deg=500.0)
    with pytest.raises(LimitExceeded, match="to 800 deg from 500"):
        limits.apply(step, at_500)
    assert angle_of(lk.SingleTurnAngleReply(angle_deg=10.0)) is None


@pytest.mark.anyio
async def test_a_frame_for_several_motors_meets_each_motor_s_own_limit_asked_or_not() -> None:
    from servobus.cli._connect import sim_devices

    sniffer = Sniffer()
    devices = [*sim_devices("lk", (1, 2, 3, 4), "V2_35"), sniffer]
    async with Bus(SimTransport(devices=devices)) as bus:
        motors = [bus.motor(lk.FAMILY, i, revision="V2_35") for i in (1, 2, 3, 4)]
        motors[2].limits = Limits(current_a=1.0, clamp=True)  # motor 3, not asked below
        command = lk.MultiMotorTorque(motor_type=lk.MotorType.MG, currents_a=(2.0, -2.0, 8.0, 0.5))
        await bus.broadcast(command, motors[:2])
        sent = [f for _, f in sniffer.seen if f.arbitration_id == 0x280]
        expected = lk.MultiMotorTorque(motor_type=lk.MotorType.MG, currents_a=(2.0, -2.0, 1.0, 0.5))
        frame = lk.FAMILY.broadcast(expected, [m.codec for m in motors[:2]]).frame
        assert [bytes(f.data) for f in sent] == [bytes(frame.data)]
        motors[2].limits = Limits(current_a=1.0)
        with pytest.raises(LimitExceeded, match="motor 3"):
            await bus.broadcast(command, motors[:2])
        motors[2].limits = None
        motors[0].limits = Limits(current_a=3.0)  # its own slot only: slot 3's 8 A is not its
        await bus.broadcast(command, motors[:2])


def test_a_bound_or_a_setting_is_never_a_motor_driven_out_of_its_range() -> None:
    limits = Limits(position_deg=(-90, 90), acceleration_dps_s=5000)
    at_95 = ma.StatusReply(temperature_c=25, current_a=0.0, speed_dps=0.0, angle_deg=95.0)
    accel = ma.WriteAcceleration(index=ma.AccelIndex.POSITION_ACCELERATION, acceleration_dps_s=500)
    assert limits.apply(accel, at_95) is accel
    back = ho.Setpoint(position_deg=45.0, speed_rad_s=2.0, kp=100, kd=1, current_a=3.0)  # its speed: a bound
    assert (
        limits.apply(back, ho.NormalReply(motor_id=1, position_deg=95.0, speed_rad_s=0.0, current_a=0.0))
        is back
    )


def test_a_position_its_motor_ignores_is_not_checked() -> None:
    limits = Limits(position_deg=(10, 90))
    velocity = ho.Setpoint(position_deg=0.0, speed_rad_s=1.0, kp=0, kd=0, current_a=3.0)
    assert limits.apply(velocity) is velocity  # kp = 0: a speed set-point
    mit = ma.MotionCommand(position_rad=0.0, velocity_rad_s=1.0, kp=0, kd=1, torque_ff_nm=0)
    assert limits.apply(mit) is mit
    with pytest.raises(LimitExceeded, match="position_rad=0"):
        limits.apply(dataclasses.replace(mit, kp=5))
    torque = ho.FdCommand(position_deg=0.0, current_raw=100, mode=ho.ControlMode.TORQUE, run=True)
    assert limits.apply(torque) is torque
    with pytest.raises(LimitExceeded, match="position_deg=0"):
        limits.apply(dataclasses.replace(torque, mode=ho.ControlMode.POSITION))


def test_no_planning_is_beyond_an_acceleration_limit_and_a_raw_current_limit_is_not_open() -> None:
    open_ended = ma.WriteAcceleration(index=ma.AccelIndex.POSITION_ACCELERATION, acceleration_dps_s=None)
    with pytest.raises(LimitExceeded, match="acceleration_dps_s=none"):
        Limits(acceleration_dps_s=5000).apply(open_ended)
    raw = lk.SpeedControl(speed_dps=10.0, motor_type=lk.MotorType.MH, iq_limit_counts=100)
    assert Limits(current_a=1.0).apply(raw) is raw
    assert Limits(current_a=1.0, clamp=True).apply(raw) is raw
    counts = lk.MultiMotorTorque(motor_type=lk.MotorType.MH, iq_counts=(10, 900, 0, 0))
    with pytest.raises(LimitExceeded, match="iq_counts"):
        Limits(fields={"iq_counts": (-500, 500)}).apply(counts)

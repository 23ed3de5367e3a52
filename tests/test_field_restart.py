"""A motor that restarts (issue [field] case 2): a brownout of 300 ms while a loop commands 720 dps.

The motor is silent, then comes back in its power-on state. The watchdog marks it offline and online
again, as it did before; now the Bus also finds out that it restarted, from the evidence its family
declares (MyActuator: the run time, 0xB1, went back; LK: the multi-turn angle, 0x92, folded to one
turn; hollow: the position folded to one turn), and reports it: a ``"restarted"`` MotorStatus within
250 ms of the motor's return, the ``restarts`` counter, ``motor.restarted_at``, one warning. A motor
that was only cut off (a cable pulled and put back) is not reported. The simulator's brownout is
``device.brownout(now_s, duration_s)`` (servobus.sim.power); everything runs in virtual time on both
backends, and once through the simulator's SLCAN adapter on a pty in real time.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import anyio
import pytest

from _backends import BACKENDS
from servobus.bus import Bus, Motor, MotorStatus
from servobus.errors import MotorTimeout
from servobus.frame import Frame
from servobus.protocols import Command, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.transports.sim import SimTransport

CUT_AT_S = 1.0  # the loop has run for a second (the angle is well past one turn)
CUT_S = 0.3  # the brownout, or the cable pulled
RUN_S = 2.0
PERIOD_S = 0.005  # a 200 Hz loop
REPORT_WITHIN_S = 0.25  # the Done-when figure
DPS = 720.0
RAD_S = math.radians(DPS)


class _CablePulled(FaultInjector):
    """A link that carries nothing, either way, from ``start_s`` for ``length_s``: the motor was cut off
    but kept its power (and what it was told)."""

    def __init__(self, start_s: float, length_s: float) -> None:
        super().__init__(FaultPlan())
        self.start_s, self.end_s = start_s, start_s + length_s
        self.lost = 0

    def apply(self, item: Frame | bytes, now_s: float) -> list[tuple[float, Frame | bytes]]:
        if self.start_s <= now_s < self.end_s:
            self.lost += 1
            return []
        return super().apply(item, now_s)


@dataclass
class Family:
    """One family's motor, how to start it, and what its loop sends each tick."""

    make: Callable[[], Any]
    start: Callable[[Motor], list[Command]]
    tick: Callable[[Motor], list[Command]]


def _lk_speed(motor: Motor) -> Command:
    return lk.SpeedControl(speed_dps=DPS, motor_type=motor.codec.model.motor_type, current_limit_a=20.0)


FAMILIES = {
    "myactuator": Family(
        lambda: MyActuatorMotor(1), lambda m: [], lambda m: [ma.SpeedControl(speed_dps=DPS)]
    ),
    # LK's evidence is its multi-turn angle: a loop that reads it each tick keeps it fresh.
    "lk": Family(lambda: LkMotor(1), lambda m: [], lambda m: [_lk_speed(m), lk.ReadMultiTurnAngle()]),
    "hollow": Family(
        lambda: HollowMotor(1),
        lambda m: [ho.SelectMode(mode=ho.ControlMode.VELOCITY), ho.Start()],
        lambda m: [ho.Setpoint(position_deg=0.0, speed_rad_s=RAD_S, kp=0, kd=0, current_a=3.0)],
    ),
}


@dataclass
class Run:
    statuses: list[MotorStatus] = field(default_factory=list)
    motor: Motor | None = None
    bus: Bus | None = None
    device: Any = None
    back_at: float = math.nan  # when the motor had its power (or its cable) back

    def reasons(self) -> list[str]:
        return [s.reason for s in self.statuses]

    def restarted(self) -> list[MotorStatus]:
        return [s for s in self.statuses if s.reason == "restarted"]


def _loop(family: str, *, fault: str, backend: str) -> Run:
    """A 200 Hz loop of the family's command for ``RUN_S``; at ``CUT_AT_S`` the motor browns out
    (``fault="brownout"``) or its cable is pulled (``"cable"``) for ``CUT_S``."""
    spec = FAMILIES[family]
    device = spec.make()
    run = Run(device=device)
    cable = _CablePulled(CUT_AT_S, CUT_S) if fault == "cable" else None

    async def main() -> None:
        link = SimTransport(devices=[device], to_devices=cable, to_host=cable)
        async with Bus(link, safe=None) as bus:
            motor = run.motor = bus.motor(family, 1)
            run.bus = bus
            bus.subscribe_status(run.statuses.append)
            for command in spec.start(motor):
                await motor.request(command)
            start = anyio.current_time()
            cut = False
            while (now := anyio.current_time()) - start < RUN_S:
                if not cut and now - start >= CUT_AT_S:
                    cut = True
                    run.back_at = now + CUT_S
                    if fault == "brownout":
                        device.brownout(now, CUT_S)
                    elif cable is not None:
                        cable.start_s, cable.end_s = now, now + CUT_S
                await bus.cycle([(motor, c) for c in spec.tick(motor)])
                await anyio.sleep(PERIOD_S)

    virtual.run(main(), backend=backend)
    return run


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_a_brownout_is_reported_as_a_restart_within_250_ms_of_the_return(
    family: str, backend: str, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="servobus.bus"):
        run = _loop(family, fault="brownout", backend=backend)
    assert run.device.counters["reboots"] == 1 and run.device.counters["brownouts"] == 1
    reasons = run.reasons()
    assert reasons[0] == "answered" and reasons[-1] == "restarted", reasons
    assert reasons.count("restarted") == 1 and not reasons[1].startswith("answered"), reasons
    (status,) = run.restarted()
    assert status.online is True and status.motor is run.motor
    took_s = status.at - run.back_at
    assert 0 <= took_s <= REPORT_WITHIN_S, f"{family}: reported {took_s * 1000:.1f} ms after the return"
    print(f"\n{family} ({backend}): restart reported {took_s * 1000:.1f} ms after the motor's return")
    assert run.motor is not None and run.bus is not None
    assert run.motor.metrics().restarts == 1 and run.bus.metrics().restarts == 1
    assert run.motor.restarted_at is not None and run.motor.restarted_at >= run.back_at
    logged = [r.getMessage() for r in caplog.records if "restarted" in r.getMessage()]
    assert len(logged) == 1 and repr(run.motor) in logged[0], logged


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_a_motor_only_cut_off_is_not_reported_as_restarted(family: str, backend: str) -> None:
    run = _loop(family, fault="cable", backend=backend)
    assert run.device.counters["reboots"] == 0
    reasons = run.reasons()
    assert reasons[0] == "answered" and reasons[-1] == "answered" and len(reasons) == 3, reasons
    assert run.restarted() == []
    assert run.motor is not None and run.motor.metrics().restarts == 0
    assert run.motor.restarted_at is None


def test_a_restart_soon_after_another_is_reported_again() -> None:
    """After a reported restart the motor's run time is known from its return: a second brownout
    a second later is a restart too (and the first is not reported twice)."""
    device = MyActuatorMotor(1)

    async def main() -> list[str]:
        statuses: list[MotorStatus] = []
        async with Bus(SimTransport(devices=[device]), safe=None) as bus:
            motor = bus.motor("myactuator", 1)
            bus.subscribe_status(statuses.append)
            start = anyio.current_time()
            cuts = [1.0, 2.0]
            while (now := anyio.current_time()) - start < 3.0:
                if cuts and now - start >= cuts[0]:
                    cuts.pop(0)
                    device.brownout(now, CUT_S)
                await bus.cycle([(motor, ma.SpeedControl(speed_dps=DPS))])
                await anyio.sleep(PERIOD_S)
            assert motor.metrics().restarts == 2
        return [s.reason for s in statuses]

    reasons = virtual.run(main())
    assert reasons.count("restarted") == 2 and reasons[-1] == "restarted", reasons


# ---- the recipe (docs/restarts.md): the user decides what to send again ----


def test_the_recipe_sends_the_set_point_again_on_restarted() -> None:
    """A one-shot speed command, a brownout, and the documented recipe: subscribe to the status and
    send the set-point again when the motor restarted. Without it the motor stays at rest."""
    ran: dict[bool, float] = {}
    for recipe in (False, True):
        device = MyActuatorMotor(1)

        async def main(recipe: bool = recipe, device: MyActuatorMotor = device) -> float:
            async with Bus(SimTransport(devices=[device]), safe=None) as bus, anyio.create_task_group() as tg:
                motor = bus.motor(ma.FAMILY, 1)
                set_point = ma.SpeedControl(speed_dps=DPS)

                def on_status(status: MotorStatus) -> None:  # (a plain function: it starts a task)
                    if status.reason == "restarted":
                        tg.start_soon(status.motor.request, set_point)

                if recipe:
                    bus.subscribe_status(on_status)
                await motor.request(set_point)
                await anyio.sleep(1.0)
                device.brownout(anyio.current_time(), CUT_S)
                for _ in range(100):  # the loop only reads (the motor is polled)
                    with contextlib.suppress(Exception):
                        await motor.read_status2()
                    await anyio.sleep(PERIOD_S)
                reply = await motor.read_status2()
                return reply.speed_dps

        ran[recipe] = virtual.run(main())
    assert ran[False] == 0.0, ran  # restarted: output off, and nothing said so before
    assert ran[True] == pytest.approx(DPS, abs=5.0), ran


# ---- the simulator's side: the power-on state, on the C path and the Python path alike ----


@pytest.mark.parametrize("c_path", [True, False], ids=["C network", "Python network"])
def test_a_brownout_leaves_a_myactuator_motor_in_its_power_on_state(c_path: bool) -> None:
    from servobus.sim.network import SimCanNetwork

    device = MyActuatorMotor(1)
    device.rom.save_multi_turn = False  # 0x20 index 4 off: single-turn mode, the count lost at a start

    async def main() -> tuple[Any, ...]:
        network = None if c_path else SimCanNetwork([device])
        link = SimTransport(devices=[device]) if c_path else SimTransport(network=network)
        async with Bus(link, safe=None) as bus:
            motor = bus.motor(ma.FAMILY, 1)
            await motor.speed_control(speed_dps=DPS)
            await anyio.sleep(1.45)
            before = await motor.read_multi_turn_angle()
            device.brownout(anyio.current_time(), CUT_S)
            with pytest.raises(MotorTimeout):
                await motor.read_status2(timeout_s=0.05)
            await anyio.sleep(CUT_S)
            return (
                before,
                await motor.read_multi_turn_angle(),
                await motor.read_run_time(),
                await motor.read_status2(),
                await motor.read_run_mode(),
            )

    before, after, run_time, status, mode = virtual.run(main())
    assert before.angle_deg > 720.0
    assert 0.0 <= after.angle_deg < 360.0  # the multi-turn angle folded to one turn
    assert run_time.run_time_ms <= 0.06 * 1000  # the run time restarted at the return
    assert status.speed_dps == 0.0  # the output off (the brake holds it)
    assert mode.mode is ma.RunMode.POSITION_LOOP  # the power-up mode (the sim's reading of §4.27)
    assert device.counters["unpowered"] >= 1 and device.counters["reboots"] == 1


# ---- a real transport path: the simulator's SLCAN adapter on a pty, in real time ----


@pytest.mark.anyio
async def test_a_restart_is_reported_through_slcan_on_a_pty() -> None:
    from servobus.sim.attach import serve_slcan
    from servobus.sim.network import SimCanNetwork
    from servobus.sim.pty import PtyPort
    from servobus.transports import SlcanTransport
    from transports._anyio_help import needs_bus_on, serving

    device = MyActuatorMotor(1)
    network = SimCanNetwork([device])
    port = PtyPort()
    statuses: list[MotorStatus] = []
    needs_bus_on()
    try:
        with anyio.fail_after(10):
            async with (
                serving(serve_slcan(network, port)),
                Bus(SlcanTransport(port.path, bitrate=1_000_000), safe=None, probe_interval_s=0.05) as bus,
            ):
                motor = bus.motor(ma.FAMILY, 1)
                bus.subscribe_status(statuses.append)
                for _ in range(40):
                    await bus.cycle([(motor, ma.SpeedControl(speed_dps=DPS))], timeout_s=0.5)
                    await anyio.sleep(PERIOD_S)
                device.brownout(network.now_s, CUT_S)
                cut_at = anyio.current_time()
                while not any(s.reason == "restarted" for s in statuses):
                    await bus.cycle([(motor, ma.SpeedControl(speed_dps=DPS))], timeout_s=0.05)
                    await anyio.sleep(PERIOD_S)
                took_s = anyio.current_time() - cut_at - CUT_S
                assert motor.metrics().restarts == 1
    finally:
        port.close()
    reasons = [s.reason for s in statuses]
    assert reasons[0] == "answered" and reasons[-1] == "restarted", reasons
    assert took_s <= 1.0, took_s  # (real time, a shared machine: generous)

"""The fault soak (tests/_soak.py) for a few virtual seconds in every run, 10 virtual minutes with
``-m slow`` (or ``python bench/reliability.py soak``), and the one fault the in-process bus cannot
give: a stalled serial port, through a real pty.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import time
import tty

import pytest

import _soak
from _serving import serving
from servobus.bus import Bus
from servobus.errors import MotorTimeout, TransportError
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.rs485 import decode_rs485_request
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.sim.attach import serve_rs485
from servobus.sim.device import SerialEmission
from servobus.sim.pty import PtyPort
from servobus.transports import SerialTransport

FAULT_KINDS = {
    f"{direction}_{kind}"
    for direction in ("to_host", "to_devices")
    for kind in ("drop", "corrupt", "duplicate", "delay")
} | {"motor_reboot", "motor_silent", "adapter_unplug", "motor_left_to_trip", "motor_comm_echoed"}


def _check(result: _soak.SoakResult) -> None:
    summary = result.summary()
    print(f"\nsoak: {summary}")
    assert result.problems() == []
    assert set(result.faults) >= FAULT_KINDS, FAULT_KINDS - set(result.faults)
    # Counters add up: made = replied + timed out + cancelled + failed, and the Bus says the same.
    out, counts = result.outcomes, result.bus_counts
    ended = ("replied", "timed_out", "cancelled", "failed", "skipped", "not_executed")
    assert result.made == sum(out[name] for name in ended)
    assert (
        counts["requests"] == counts["replies"] + counts["timeouts"] + counts["cancelled"] + counts["failed"]
    )
    # cycle() did not wait for an offline or busy motor's command: not sent, or sent as a probe
    skipped = counts["skipped_offline"] + counts["skipped_busy"]
    assert counts["requests"] + skipped == result.made and out["skipped"] == skipped + counts["probes"]
    assert counts["replies"] >= out["replied"] and counts["timeouts"] >= out["timed_out"]
    assert out["cancelled"] > 0 and out["failed"] > 0 and out["timed_out"] > 0
    # Bounded: no more pending than one tick and one single request per bus; the scheduler's tables
    # hold at most a few entries per motor and command, but its late and duplicate windows (keyed by
    # the value an echo wrote, so new keys keep coming) at most twice the requests of one late
    # window (1 s: a tick's and a single request's worth at tick_hz).
    plan = result.plan
    assert result.max_pending <= plan.motors_per_bus + 1
    windows = {"late_keys", "replied_keys"}
    assert max(n for name, n in result.max_tables.items() if name not in windows) <= 8 * plan.motors_per_bus
    assert max(result.max_tables[name] for name in windows) <= 64 + 2 * plan.tick_hz * (
        plan.motors_per_bus + 1
    )
    # The silent motor went offline and came back; the unplugged bus answered again.
    silent = [e for e in result.offline_events if e[0] == "bus 1 motor 5"]
    assert [online for _, _, online, _ in silent][-2:] == [False, True]
    assert result.unplug_recovery_s and max(result.unplug_recovery_s) < 1.0
    # [field]: every trip was seen (its 0xF1 frames counted by name) and every echo that reached the
    # host failed its request (not_executed, part of failed), never a reply (the mismatch check);
    # the second controller's requests took their place in its motors' order (contended).
    assert counts["comm_tripped"] > 0 and out["not_executed"] > 0
    assert counts["not_executed"] >= out["not_executed"]
    assert counts["contended"] > 0


@pytest.mark.slow  # ~36 s: out of the default suite, a step of its own in CI (.ci/run)
def test_soak_32_motors_4_buses_a_few_virtual_seconds() -> None:
    result = _soak.run(minutes=0.1, seed=7, warmup_s=1.0, checkpoint_s=1.0, reboot_every_s=1.5)
    _check(result)
    assert result.faults["motor_reboot"] >= 2


@pytest.mark.slow
def test_soak_32_motors_4_buses_10_virtual_minutes() -> None:
    _check(_soak.run(minutes=10, seed=2024, warmup_s=60.0, memory="rss"))


# ---- a stalled serial port, under a Bus ----

STALE_S = 0.2


class Heard:
    """A MyActuator RS485 motor that notes when each request reached it (on the loop's clock)."""

    def __init__(self, motor: MyActuatorRs485Motor) -> None:
        self.inner = motor
        self.name = motor.name
        self.heard: list[tuple[float, bytes]] = []
        self._loop = asyncio.get_running_loop()

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        self.heard.append((self._loop.time(), data))
        return self.inner.receive_bytes(data, now_s)

    def poll(self, now_s: float) -> list[SerialEmission]:
        return self.inner.poll(now_s)

    def next_deadline_s(self) -> float | None:
        return self.inner.next_deadline_s()


def _fill(fd: int) -> None:
    for _ in range(3):  # the kernel moves what it holds towards the master's side: fill until full
        with contextlib.suppress(BlockingIOError):
            while True:
                os.write(fd, bytes(4096))
        time.sleep(0.02)


async def _stalled_port_run(*, cycle: bool) -> tuple[list[float], dict[str, int], int]:
    """A Bus over an RS485 line whose port is stalled (the pty's buffer full, nobody reading) for
    7.5 x STALE_S while requests keep coming, then read again by a simulated motor. Returns the age
    of every request when it reached the motor, the outcomes, and the replies after the stall."""
    port = PtyPort()
    slave = os.open(port.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(slave)
    _fill(slave)
    loop = asyncio.get_running_loop()
    made: dict[int, float] = {}
    outcomes: dict[str, int] = {"replied": 0, "timed_out": 0, "failed": 0}
    device = Heard(MyActuatorRs485Motor(MyActuatorMotor(1)))
    transport = SerialTransport(
        port.path, mode="myactuator", baud=1_000_000, stale_after_s=STALE_S, reopen=False
    )
    token = 0

    def command() -> ma.WriteEncoderZero:
        nonlocal token
        token += 1
        made[token] = loop.time()
        return ma.WriteEncoderZero(offset_counts=token)

    async def one(motor_request: object) -> None:
        try:
            await motor_request  # type: ignore[misc]
            outcomes["replied"] += 1
        except MotorTimeout:
            outcomes["timed_out"] += 1
        except TransportError:
            outcomes["failed"] += 1

    try:
        async with transport, Bus(transport, safe=None) as bus:
            motors = [bus.motor("myactuator", i, link="rs485") for i in (1, 2, 3, 4)]
            running = True

            async def requests() -> None:
                while running:
                    if cycle:
                        results = await bus.cycle([(m, command()) for m in motors], timeout_s=0.05)
                        for r in results:
                            kind = type(r)
                            if kind is ma.Echo:
                                outcomes["replied"] += 1
                            else:
                                outcomes["timed_out" if kind is MotorTimeout else "failed"] += 1
                    else:
                        await one(motors[0].request(command(), timeout_s=0.05))
                    await asyncio.sleep(0.005)

            task = asyncio.ensure_future(requests())
            # Stalled while the requests keep coming; a cycle of 4 takes 4 x STALE_S then (each frame
            # goes stale in turn), so the stall ends while the second cycle's last frame waits.
            await asyncio.sleep(7.5 * STALE_S)
            async with serving(serve_rs485([device], port, baud=1_000_000)):  # the port is read again
                await asyncio.sleep(0.5)  # while they still come
                running = False
                await task
                before = outcomes["replied"]
                for _ in range(20):
                    await one(motors[0].request(command(), timeout_s=0.2))
                await asyncio.sleep(0.1)
            after = outcomes["replied"] - before
    finally:
        os.close(slave)
        port.close()
    ages = []
    for at, data in device.heard:
        with contextlib.suppress(Exception):
            _, request = decode_rs485_request(data)
            if isinstance(request, ma.WriteEncoderZero):
                ages.append(at - made[request.offset_counts])
    return ages, outcomes, after


@pytest.mark.asyncio
async def test_a_stalled_serial_port_under_a_bus_delivers_no_stale_command_and_recovers() -> None:
    """One request at a time (``motor.request``): while the port is stalled each fails as not sent
    (stale) or times out; none reaches the motor later than ``stale_after_s`` after it was made
    (slack: the pty and the simulator share this loop); after the stall the motor answers again."""
    ages, outcomes, after = await _stalled_port_run(cycle=False)
    print(
        f"\nages at the motor: max {max(ages) * 1e3:.1f} ms of {len(ages)}; {outcomes}; {after} replies after"
    )
    assert ages and max(ages) < STALE_S + 0.05
    assert outcomes["failed"] + outcomes["timed_out"] > 0
    assert after >= 18


@pytest.mark.asyncio
async def test_a_stalled_serial_port_under_cycles_delivers_no_stale_command() -> None:
    ages, outcomes, after = await _stalled_port_run(cycle=True)
    print(
        f"\nages at the motor: max {max(ages) * 1e3:.1f} ms of {len(ages)}; {outcomes}; {after} replies after"
    )
    assert ages and max(ages) < STALE_S + 0.05


# ---- CAN double reception, alone ----


def _twice_received(
    family: str, device: object, commands: list[object]
) -> tuple[list[object], dict[str, int]]:
    """Send ``commands`` in turn to a motor that receives every request frame twice (CAN double
    reception: the sender retransmits a frame the receivers had already taken, and the motor answers
    both); return each request's result and the bus's counters."""
    from servobus.sim import virtual
    from servobus.sim.faults import FaultInjector, FaultPlan
    from servobus.sim.network import SimCanNetwork
    from servobus.transports import SimTransport

    async def scenario() -> tuple[list[object], dict[str, int]]:
        network = SimCanNetwork([device], to_devices=FaultInjector(FaultPlan(duplicate=1.0)))  # type: ignore[list-item]
        async with SimTransport(network) as transport, Bus(transport, safe=None) as bus:
            motor = bus.motor(family, 1)
            requests = [motor.request(c, timeout_s=0.05) for c in commands]  # type: ignore[arg-type]
            results = await asyncio.gather(*requests, return_exceptions=True)
            await asyncio.sleep(0.1)
            return results, bus.stats()

    return virtual.run(scenario())


def test_a_write_the_motor_received_twice_never_answers_the_next_write_with_its_echo() -> None:
    writes = [ma.WriteEncoderZero(offset_counts=-k) for k in (1, 2, 3)]
    results, counts = _twice_received("myactuator", MyActuatorMotor(1), writes)
    assert [r.command for r in results] == writes  # type: ignore[attr-defined]
    assert counts["replies"] == 3 and counts["duplicate"] == 3  # each second echo, counted


def test_an_lk_parameter_write_received_twice_never_answers_the_next_one() -> None:
    from servobus.protocols import lk
    from servobus.protocols.lk.sim.device import LkMotor

    writes = [lk.WriteControlParam(param=lk.ControlParam.SPEED_LIMIT, value=v) for v in (9000, 9100, 9200)]
    results, counts = _twice_received("lk", LkMotor(1), writes)
    assert [r.value for r in results] == [9000, 9100, 9200]  # type: ignore[attr-defined]
    assert counts["replies"] == 3 and counts["duplicate"] == 3

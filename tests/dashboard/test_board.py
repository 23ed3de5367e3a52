"""The dashboard's board: what the page is shown of a Bus, its motors, frames and a Loop, and what it
costs the control loop (nothing decoded, copied or encoded per frame: only when a page asks)."""

from __future__ import annotations

import json
from typing import Any

import anyio
import pytest

from servobus.bus import Bus
from servobus.dashboard import Board
from servobus.dashboard._board import FIGURES_EVERY_S
from servobus.errors import MotorTimeout
from servobus.loop import Loop
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.tools.logs import FrameDecoder
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio


def _rows(board: Board) -> dict[str, dict[str, Any]]:
    update = json.loads(board.update())
    return {row["key"]: row for row in update["motors"]}


async def test_every_motor_is_shown_with_its_latest_reply_its_set_point_and_its_frames_decoded() -> None:
    board = Board()
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]
    async with Bus(board.tap(SimTransport(devices=devices, name="arm")), safe=None) as bus:
        board.watch(bus)
        motors = [bus.motor("myactuator", i) for i in (1, 2, 3)]
        assert sorted(_rows(board)) == ["arm/1", "arm/2", "arm/3"]  # known before any reply
        await bus.cycle([(m, ma.SpeedControl(speed_dps=30.0 * m.motor_id)) for m in motors])
        await anyio.sleep(0.2)
        await bus.cycle([(m, ma.SpeedControl(speed_dps=30.0 * m.motor_id)) for m in motors])
        await anyio.sleep(FIGURES_EVERY_S)  # (the counters and frames are made again twice a second)
        update = json.loads(board.update())
    rows = {row["key"]: row for row in update["motors"]}
    two = rows["arm/2"]
    assert (two["bus"], two["family"], two["id"], two["status"]) == ("arm", "myactuator", 2, "online")
    assert two["reply"] == "StatusReply" and two["fields"]["speed_dps"] == pytest.approx(60.0, abs=2)
    assert two["temperature_c"] == two["fields"]["temperature_c"] and two["fault"] == []
    assert two["setpoint"] == {"name": "SpeedControl", "fields": {"speed_dps": 60.0}}
    frames = {(f["dir"], f["id"]): f for f in update["buses"][0]["frames"]}
    assert frames["tx", "0x142"]["name"] == "SpeedControl (motor 2)"
    assert frames["rx", "0x242"]["name"] == "StatusReply (motor 2)"
    assert frames["tx", "0x142"]["count"] == 2 and frames["rx", "0x242"]["data"].startswith("A2 ")
    figures = update["buses"][0]
    assert figures["name"] == "arm" and figures["requests"] == 6 and figures["replies"] == 6


async def test_the_hot_path_decodes_nothing_and_an_update_is_made_once_per_period(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    decoded: list[int] = []
    real = FrameDecoder.decode
    monkeypatch.setattr(FrameDecoder, "decode", lambda self, frame: decoded.append(1) or real(self, frame))
    board = Board(update_hz=2.0)
    async with Bus(board.tap(SimTransport(devices=[MyActuatorMotor(1)])), safe=None) as bus:
        board.watch(bus)
        motor = bus.motor("myactuator", 1)
        for _ in range(50):
            await motor.read_status2()
        assert decoded == []  # 100 frames through the tap and the subscriber: nothing decoded yet
        first = board.update()
        assert decoded  # the page's update decodes the frames it shows, once per identifier
        again = board.update()
        assert again is first  # within the period: the same text for every page
        await anyio.sleep(0.55)
        assert board.update() is not first


async def test_a_fault_the_bus_keeps_and_a_silent_motor_are_shown() -> None:
    board = Board()
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    transport = SimTransport(devices=devices)
    async with Bus(transport, safe=None, offline_after_misses=1) as bus:
        board.watch(bus, name="b")
        one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
        await one.read_status1()
        await two.read_status1()
        devices[0].inject_error(ma.ErrorFlags.OVER_VOLTAGE, anyio.current_time())
        await one.read_status1()
        devices[1].unresponsive = True
        with pytest.raises(MotorTimeout):  # (the watchdog marks it offline at once: one miss)
            await two.read_status1(timeout_s=0.02)
        rows = _rows(board)
    assert rows["b/1"]["fault"] == ["OVER_VOLTAGE"] and rows["b/1"]["status"] == "online"
    assert rows["b/2"]["status"] == "offline" and "missed" in rows["b/2"]["reason"]


async def test_a_loop_s_figures_are_shown() -> None:
    board = Board()
    async with Bus(SimTransport(devices=[MyActuatorMotor(1)]), safe=None) as bus:
        board.watch(bus)
        motor = bus.motor("myactuator", 1)
        loop = Loop(200)
        board.watch_loop(loop)
        async with loop:
            async for tick in loop.ticks(20):
                tick.command(motor, ma.ReadStatus2())
        update = json.loads(board.update())
    (figures,) = update["loops"]
    assert figures["hz"] == 200 and figures["ticks"] == 20 and figures["commands_sent"] >= 18
    assert figures["late_p99_s"] is not None and figures["state_age_p99_s"] is not None
    assert update["buses"][0]["frames"] == []  # no tap: the replies only (no frames, no set-points)
    assert update["motors"][0]["setpoint"] is None and update["motors"][0]["reply"] == "StatusReply"


def test_a_bad_rate_and_a_bus_watched_twice_are_refused() -> None:
    with pytest.raises(ValueError, match="update_hz"):
        Board(update_hz=0)

    class Named:
        name = "x"

        def subscribe(self, callback: Any) -> None: ...

        def subscribe_status(self, callback: Any) -> None: ...

    board = Board()
    board.watch(Named())
    with pytest.raises(ValueError, match="'x' is on the board already"):
        board.watch(Named())


async def test_a_reply_s_age_counts_from_when_it_came_not_from_when_a_page_looked() -> None:
    board = Board()
    async with Bus(SimTransport(devices=[MyActuatorMotor(1)]), safe=None) as bus:
        board.watch(bus)
        await bus.motor("myactuator", 1).read_status2()
        await anyio.sleep(0.3)  # no page open meanwhile
        (row,) = _rows(board).values()
    assert row["age_s"] >= 0.29 and row["status"] == "online"


def test_the_boards_short_way_to_a_messages_numbers_is_the_long_ways() -> None:
    """The board's fast path to a message's numbers gives what message_values gives, finite."""
    import dataclasses
    import inspect

    from servobus.dashboard._board import _finite, _numbers
    from servobus.protocols import hollow, lk
    from servobus.protocols import myactuator as ma
    from servobus.tools.logs import message_values

    samples: list[Any] = [
        ma.StatusReply(temperature_c=25, current_a=0.5, speed_dps=3.0, angle_deg=2.0),  # (an enum field)
        ma.AbsolutePositionControl(angle_deg=3.0, max_speed_dps=500.0),
        ma.Status1Reply(  # (a flag field: the motor's faults)
            temperature_c=30,
            mos_temperature_c=31,
            brake_released=True,
            voltage_v=48.0,
            errors=ma.ErrorFlags.OVER_VOLTAGE,
        ),
    ]
    for module in (ma, hollow, lk):
        for cls in vars(module).values():
            if inspect.isclass(cls) and dataclasses.is_dataclass(cls):
                try:
                    samples.append(cls())
                except TypeError:  # (a message with required fields)
                    continue
    assert len(samples) > 20
    for message in samples:
        short, long = _numbers(message), _finite(message_values(message))
        assert list(short.items()) == list(long.items()), message
    assert _numbers(samples[0]) == {
        "temperature_c": 25,
        "current_a": 0.5,
        "speed_dps": 3.0,
        "angle_deg": 2.0,
    }

"""The dashboard's app (through httpx's ASGI transport, on the Bus's own loop): the page, its data, and
the only commands it knows, stop and off, refused unless allowed."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator, Sequence

import anyio
import httpx
import pytest
from starlette.applications import Starlette
from starlette.routing import Mount

from servobus.bus import Bus, Motor
from servobus.dashboard import Dashboard, Watched
from servobus.loop import Loop
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.plant import Off, PositionControl, SpeedControl
from servobus.transports.sim import SimTransport

pytestmark = pytest.mark.anyio

JSON = {"content-type": "application/json"}


class _Running:
    """Three simulated motors turning at 90 dps, a Dashboard watching their Bus, a client of its app."""

    def __init__(
        self, dash: Dashboard, bus: Bus, motors: list[Motor], devices: list[MyActuatorMotor]
    ) -> None:
        self.dash, self.bus, self.motors, self.devices = dash, bus, motors, devices
        self.client = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=dash.app()), base_url="http://127.0.0.1"
        )


async def _running(dash: Dashboard) -> AsyncIterator[_Running]:
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]
    async with Bus(dash.tap(SimTransport(devices=devices)), safe=None) as bus:
        dash.watch(bus, name="sim")
        motors = [bus.motor("myactuator", i) for i in (1, 2, 3)]
        await bus.cycle([(m, ma.SpeedControl(speed_dps=90.0)) for m in motors])
        running = _Running(dash, bus, motors, devices)
        async with running.client:
            yield running


async def test_the_page_its_scripts_and_its_data_are_served() -> None:
    async for run in _running(Dashboard()):
        page = await run.client.get("/")
        assert page.status_code == 200 and "servobus dashboard" in page.text
        for name in ("dashboard.js", "uPlot.iife.js", "uPlot.min.css", "LICENSE-uPlot.txt"):
            assert (await run.client.get(f"/static/{name}")).status_code == 200, name
        info = (await run.client.get("/api/info")).json()
        assert info["commands"] is False and info["update_hz"] == 30.0
        snapshot = (await run.client.get("/api/snapshot")).json()
        assert [m["key"] for m in snapshot["motors"]] == ["sim/1", "sim/2", "sim/3"]
        assert {m["setpoint"]["name"] for m in snapshot["motors"]} == {"SpeedControl"}


async def test_read_only_refuses_every_stop_and_the_motors_keep_turning() -> None:
    async for run in _running(Dashboard()):
        for body in ({"motors": "all"}, {"motors": ["sim/1"], "kind": "off"}):
            answer = await run.client.post("/api/stop", json=body)
            assert answer.status_code == 403 and "--allow-commands" in answer.json()["error"]
        assert all(isinstance(d.control, SpeedControl) for d in run.devices)
        assert run.bus.commanded == tuple(run.motors)  # (the cycle's), nothing more was sent:
        assert run.bus.metrics().requests == 3


async def test_allowed_a_stop_holds_one_motor_and_off_cuts_all_and_the_application_is_told_first() -> None:
    told: list[list[str]] = []

    def on_stop(motors: Sequence[Watched]) -> None:
        told.append([w.key for w in motors])

    async for run in _running(Dashboard(allow_commands=True, on_stop=on_stop)):
        assert (await run.client.get("/api/info")).json()["commands"] is True
        answer = await run.client.post("/api/stop", json={"motors": ["sim/2"]})
        assert answer.status_code == 200, answer.text
        assert answer.json() == {"acknowledged": ["sim/2"], "not_acknowledged": []}
        assert isinstance(run.devices[1].control, PositionControl)  # 0x81: holds where it is
        assert isinstance(run.devices[0].control, SpeedControl)
        answer = await run.client.post("/api/stop", json={"motors": "all", "kind": "off"})
        assert sorted(answer.json()["acknowledged"]) == ["sim/1", "sim/2", "sim/3"]
        assert all(isinstance(d.control, Off) for d in run.devices)  # 0x80: output off
        assert told == [["sim/2"], ["sim/1", "sim/2", "sim/3"]]


async def test_bad_commands_are_answered_with_why_and_send_nothing() -> None:
    async for run in _running(Dashboard(allow_commands=True)):
        cases = [
            (dict(content="motors=all", headers={"content-type": "application/x-www-form-urlencoded"}), 415),
            (dict(content="{", headers=JSON), 400),
            (dict(json={"motors": "sim/1"}), 400),
            (dict(json={"motors": ["sim/1"], "kind": "explode"}), 400),
            (dict(json={"motors": ["sim/9"]}), 404),
        ]
        for request, status in cases:
            answer = await run.client.post("/api/stop", **request)  # type: ignore[arg-type]
            assert answer.status_code == status, (request, answer.text)
            assert answer.json()["error"]
        assert (await run.client.get("/api/stop")).status_code == 405
        assert run.bus.metrics().requests == 3 and all(
            isinstance(d.control, SpeedControl) for d in run.devices
        )


async def test_mounted_on_an_application_of_ones_own_the_page_finds_its_parts() -> None:
    async for run in _running(Dashboard()):
        outer = Starlette(routes=[Mount("/dashboard", run.dash.app())])
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=outer), base_url="http://h") as client:
            bare = await client.get("/dashboard")
            assert bare.status_code in (307, 308) and bare.headers["location"].endswith("/dashboard/")
            page = await client.get("/dashboard/")
            assert page.status_code == 200 and 'src="static/dashboard.js"' in page.text  # (relative)
            assert (await client.get("/dashboard/static/dashboard.js")).status_code == 200
            update = json.loads((await client.get("/dashboard/api/snapshot")).text)
            assert len(update["motors"]) == 3


async def test_a_stop_is_not_undone_by_the_set_point_a_loop_was_to_send_next() -> None:
    """The page's stop comes between two ticks: the set-point the last tick gave would leave at the
    next deadline, after the stop, and set the motor turning again; the Dashboard drops it."""
    stopped: set[int] = set()
    dash = Dashboard(allow_commands=True, on_stop=lambda ws: stopped.update(w.motor_id for w in ws))
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]
    async with Bus(dash.tap(SimTransport(devices=devices)), safe=None) as bus:
        dash.watch(bus, name="sim")
        motors = [bus.motor("myactuator", i) for i in (1, 2, 3)]
        loop = Loop(200)
        dash.watch_loop(loop)
        client = httpx.AsyncClient(transport=httpx.ASGITransport(app=dash.app()), base_url="http://h")
        async with loop, client, anyio.create_task_group() as group:

            async def control() -> None:  # the application: 60 dps to every motor not stopped
                async for tick in loop:
                    for motor in motors:
                        if motor.motor_id not in stopped:
                            tick.command(motor, ma.SpeedControl(speed_dps=60.0))

            group.start_soon(control)
            for key, device in (("sim/1", devices[0]), ("sim/2", devices[1])):
                await anyio.sleep(0.1 + 0.0013 * len(stopped))  # (a press at another phase of the tick)
                assert isinstance(device.control, SpeedControl)
                answer = await client.post("/api/stop", json={"motors": [key]})
                assert answer.json()["acknowledged"] == [key]
                await anyio.sleep(0.05)
                assert isinstance(device.control, PositionControl), (key, device.control)
            assert isinstance(devices[2].control, SpeedControl)
            group.cancel_scope.cancel()


async def test_a_stop_request_too_large_or_malformed_is_refused() -> None:
    async for run in _running(Dashboard(allow_commands=True)):
        big = {"motors": ["sim/1"] * 5000}
        assert (await run.client.post("/api/stop", json=big)).status_code == 413
        for body in ({"motors": ["sim/1"], "kind": []}, {"motors": [1]}, ["sim/1"]):
            answer = await run.client.post("/api/stop", json=body)
            assert answer.status_code == 400, (body, answer.text)
        assert run.bus.metrics().requests == 3  # nothing sent

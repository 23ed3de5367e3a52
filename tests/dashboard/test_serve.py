"""Serving the dashboard for real (hypercorn on a socket, asyncio and trio): the live stream, who may
open the page and who may press stop, and where it may listen; and a Bus on a python-can adapter
(the virtual interface, simulated motors behind it) seen through it."""

from __future__ import annotations

import base64
import contextlib
import json
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import can
import httpx
import pytest

from servobus.bus import Bus
from servobus.dashboard import Access, Dashboard, InsecureListen, listening_socket, serving
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_python_can
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import PositionControl, SpeedControl
from servobus.transports import CanTransport

pytestmark = pytest.mark.anyio


def _basic(user: str, password: str) -> dict[str, str]:
    return {"authorization": "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()}


async def _updates(client: httpx.AsyncClient, count: int) -> list[dict[str, Any]]:
    """The first ``count`` updates of the page's event stream."""
    got: list[dict[str, Any]] = []
    async with client.stream("GET", "api/events") as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        event = None
        async for line in stream.aiter_lines():
            if line.startswith("event:"):
                event = line.split(":", 1)[1].strip()
            elif line.startswith("data:") and event == "update":
                got.append(json.loads(line.split(":", 1)[1]))
                if len(got) == count:
                    break
    return got


@contextlib.asynccontextmanager
async def _served(dash: Dashboard, access: Access | None = None) -> AsyncIterator[str]:
    with listening_socket("127.0.0.1", 0, access=access) as sock:
        async with serving(dash, sock, access=access) as url:
            yield url


async def test_a_bus_on_a_python_can_adapter_is_streamed_live_and_a_commander_stops_a_motor(
    tmp_path: Path,
) -> None:
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    channel = f"dashboard-{time.monotonic_ns()}"
    users = tmp_path / "users.txt"
    users.write_text("# who may look\nalice:wonder\nbob:builder\n")
    access = Access.from_file(users, ["alice"])
    stopped: set[int] = set()
    dash = Dashboard(allow_commands=True, on_stop=lambda ws: stopped.update(w.motor_id for w in ws))
    sim_side = can.Bus(interface="virtual", channel=channel)
    try:
        with anyio.fail_after(20):
            async with anyio.create_task_group() as group:
                group.start_soon(lambda: serve_python_can(SimCanNetwork(devices), sim_side))
                transport = CanTransport("virtual", channel, ignore_config=True)
                async with Bus(dash.tap(transport), safe=None) as bus:
                    dash.watch(bus, name="can")
                    motors = [bus.motor("myactuator", i) for i in (1, 2)]
                    async with _served(dash, access) as url, anyio.create_task_group() as application:
                        application.start_soon(_turn, bus, motors, stopped)
                        await _look(url)
                        application.cancel_scope.cancel()
                group.cancel_scope.cancel()
    finally:
        sim_side.shutdown()
    assert isinstance(devices[0].control, PositionControl) and isinstance(devices[1].control, SpeedControl)


async def _look(url: str) -> None:
    """A reader sees the motors live and may not stop them; a commander stops motor 1; a stranger
    is asked to log in."""
    async with httpx.AsyncClient(base_url=url, headers=_basic("bob", "builder")) as bob:
        await anyio.sleep(0.3)  # (up to speed)
        updates = await _updates(bob, 12)  # (0.4 s: the frame view is in one every 0.25 s)
        first, last = updates[0], updates[-1]
        assert last["t"] > first["t"] and [m["key"] for m in last["motors"]] == ["can/1", "can/2"]
        assert last["motors"][0]["fields"]["speed_dps"] == pytest.approx(45, abs=2)
        framed = [u["buses"][0]["frames"] for u in updates if "frames" in u["buses"][0]]
        assert 1 <= len(framed) <= 3, len(framed)
        names = {(f["dir"], f["name"]) for f in framed[-1]}
        assert ("tx", "SpeedControl (motor 1)") in names and ("rx", "StatusReply (motor 2)") in names
        assert (await bob.get("api/info")).json()["commands"] is False  # a reader
        refused = await bob.post("api/stop", json={"motors": "all"})
        assert refused.status_code == 403 and "may only read" in refused.text
    async with httpx.AsyncClient(base_url=url, headers=_basic("alice", "wonder")) as alice:
        assert (await alice.get("api/info")).json()["commands"] is True
        done = await alice.post("api/stop", json={"motors": ["can/1"]})
        assert done.json() == {"acknowledged": ["can/1"], "not_acknowledged": []}
        await anyio.sleep(0.1)  # (the application's loop goes on, without motor 1)
    async with httpx.AsyncClient(base_url=url) as nobody:
        asked = await nobody.get("")
        assert asked.status_code == 401 and asked.headers["www-authenticate"].startswith("Basic")
        assert (await nobody.get("", headers=_basic("alice", "wrong"))).status_code == 401
        assert (await nobody.get("", headers={"authorization": "Basic !!"})).status_code == 401


async def _turn(bus: Bus, motors: list[Any], stopped: set[int]) -> None:
    """The application's own loop: 45 dps to every motor the page did not stop, 100 times a second."""
    async for _ in bus.ticks(100):
        await bus.cycle([(m, ma.SpeedControl(speed_dps=45.0)) for m in motors if m.motor_id not in stopped])


async def test_on_loopback_a_page_must_name_this_host() -> None:
    """A page of another site whose name was rebound to 127.0.0.1 sends its own Host: refused."""
    dash = Dashboard()
    async with _served(dash) as url, httpx.AsyncClient(base_url=url) as client:
        assert (await client.get("api/info")).status_code == 200
        port = url.rsplit(":", 1)[1].strip("/")
        for host in (f"localhost:{port}", f"127.0.0.1:{port}"):
            assert (await client.get("api/info", headers={"host": host})).status_code == 200
        evil = await client.get("api/info", headers={"host": f"evil.example:{port}"})
        assert evil.status_code == 421


def test_beyond_loopback_it_listens_only_with_users_or_when_told_insecure(tmp_path: Path) -> None:
    with pytest.raises(InsecureListen, match=r"0\.0\.0\.0 without users"):
        listening_socket("0.0.0.0", 0)
    users = tmp_path / "users"
    users.write_text("ann:pw\n")
    for sock in (
        listening_socket("0.0.0.0", 0, access=Access.from_file(users)),
        listening_socket("0.0.0.0", 0, insecure=True),
        listening_socket("localhost", 0),
        listening_socket("127.0.0.1", 0),
    ):
        with sock:
            assert sock.getsockname()[1] > 0


def test_a_users_file_is_checked(tmp_path: Path) -> None:
    bad = tmp_path / "users"
    for text, error in (
        ("ann\n", "users:1: expected user:password"),
        ("", "no users"),
        ("ann:\n", "users:1"),
    ):
        bad.write_text(text)
        with pytest.raises(ValueError, match=error):
            Access.from_file(bad)
    bad.write_text("ann:pw\n")
    with pytest.raises(ValueError, match="--commander bob: not in the users file"):
        Access.from_file(bad, ["bob"])
    access = Access.from_file(bad, ["ann"])
    assert access.check(_basic("ann", "pw")["authorization"]) == "ann"
    assert access.check(_basic("ann", "pw2")["authorization"]) is None
    assert access.check(_basic("zed", "pw")["authorization"]) is None
    assert access.check("Bearer x") is None and access.check(None) is None


def test_on_another_loopback_address_its_own_name_is_accepted() -> None:
    from servobus.dashboard._serve import guarded

    seen: list[int] = []

    async def app(scope: Any, receive: Any, send: Any) -> None:
        seen.append(1)

    async def ask(host: str) -> int:
        sent: list[dict[str, Any]] = []

        async def send(message: Any) -> None:
            sent.append(message)

        scope = {"type": "http", "headers": [(b"host", host.encode())]}
        await guarded(app, access=None, loopback="127.0.0.2")(scope, None, send)  # type: ignore[arg-type]
        return int(sent[0]["status"]) if sent else 200

    async def main() -> list[int]:
        return [await ask(h) for h in ("127.0.0.2:8765", "localhost:1", "127.0.0.3:8765", "evil:8765")]

    assert anyio.run(main) == [200, 200, 421, 421] and len(seen) == 2


def test_the_auth_scheme_is_case_blind_and_a_password_of_another_length_is_refused(tmp_path: Path) -> None:
    users = tmp_path / "users"
    users.write_text("ann:secret\n")
    access = Access.from_file(users)
    token = base64.b64encode(b"ann:secret").decode()
    assert access.check(f"basic {token}") == "ann" and access.check(f"BASIC  {token}") == "ann"
    assert access.check("Basic " + base64.b64encode(b"ann:secret-and-more").decode()) is None


async def test_pages_beyond_the_most_streamed_are_answered_503_and_a_closed_one_frees_its_place() -> None:
    dash = Dashboard(max_pages=1)
    async with _served(dash) as url, httpx.AsyncClient(base_url=url) as client:
        async with client.stream("GET", "api/events") as first:
            assert first.status_code == 200
            await first.aiter_lines().__anext__()  # (streaming)
            second = await client.get("api/events")
            assert second.status_code == 503 and "1 pages are open already" in second.json()["error"]
        assert len(await _updates(client, 1)) == 1  # the first one closed: a place again

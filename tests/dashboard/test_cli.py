"""``servobus dashboard`` as a command: its refusals (one line, exit 2, nothing opened), a missing extra,
and the page of a bridge's bus (``--remote``): read-only unless allowed, live as the bridge publishes."""

from __future__ import annotations

import contextlib
import json
import re
import select
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from _ports import free_port as _free_port
from cli._bus_cli import SERVOBUS, one_line

URL = re.compile(r"^servobus dashboard: (http://127\.0\.0\.1:\d+/) \(")


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--listen", "nowhere"], "expected HOST:PORT"),
        (["--listen", "127.0.0.1:99999"], "expected HOST:PORT"),
        (["--listen", "0.0.0.0:0"], "refusing to listen on 0.0.0.0 without users"),
        (["--tls-cert", "{users}"], "--tls-cert and --tls-key go together"),
        (["--commander", "ann"], "--commander names a user of --users"),
        (["--users", "{users}", "--commander", "ann"], "read-only without --allow-commands"),
        (
            ["--users", "{users}", "--commander", "zed", "--allow-commands"],
            "--commander zed: not in the users",
        ),
        (["--users", "{bad}"], "expected user:password"),
        (["--hz", "0"], "--hz"),
        (["--users", "{users}", "--allow-commands"], "name who may press stop (--commander NAME)"),
        (["--tls-cert", "{users}", "--tls-key", "{users}"], "--tls-cert"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, args: list[str], says: str
) -> None:
    (tmp_path / "users").write_text("ann:pw\n")
    (tmp_path / "bad").write_text("ann\n")
    given = [a.format(users=tmp_path / "users", bad=tmp_path / "bad") for a in args]
    assert says in one_line(capsys, ["dashboard", "--sim", "2", *given])


def test_a_port_in_use_is_one_line_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        assert "in use" in one_line(
            capsys, ["dashboard", "--sim", "1", "--listen", f"127.0.0.1:{port}"], code=1
        )


def test_without_the_extra_it_is_one_line_naming_it(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "starlette", None)  # (import starlette raises ModuleNotFoundError)
    for name in [n for n in sys.modules if n.startswith(("servobus.dashboard", "starlette."))]:
        monkeypatch.delitem(sys.modules, name)
    said = one_line(capsys, ["dashboard", "--sim", "1"], code=1)
    assert "the dashboard needs starlette: pip install 'servobus[dashboard]'" in said


# ---- a bridge's bus ----


@contextlib.contextmanager
def _process(args: list[str], first: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """``servobus ARGS`` in its own process, once its first line (starting with ``first``) is out;
    stopped with SIGTERM at the end (killed if it does not go)."""
    process = subprocess.Popen([*SERVOBUS, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        ready, _, _ = select.select([process.stdout], [], [], 30)
        line = process.stdout.readline().strip() if ready else ""
        assert line.startswith(first), (line, process.poll(), process.stderr and process.stderr.read())
        yield process, line
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def _get(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=10) as answer:
        return json.load(answer)


def _post(url: str, body: dict[str, Any]) -> tuple[int, Any]:
    request = urllib.request.Request(
        url, data=json.dumps(body).encode(), headers={"content-type": "application/json"}, method="POST"
    )
    try:
        with urllib.request.urlopen(request, timeout=10) as answer:
            return answer.status, json.load(answer)
    except urllib.error.HTTPError as error:
        return error.code, json.load(error)


def _until(check: Any, seconds: float = 10.0) -> Any:
    end = time.monotonic() + seconds
    while True:
        got = check()
        if got or time.monotonic() > end:
            return got
        time.sleep(0.1)


def _turning(url: str) -> bool:
    """Motor 2 turns at about 90 dps, as the page shows it."""
    return bool(_get(url + "api/snapshot")["motors"][1]["fields"].get("speed_dps", 0) > 80)


def test_the_page_of_a_bridge_s_bus_shows_its_motors_live_and_stops_only_when_allowed() -> None:
    pytest.importorskip("zenoh")
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    remote = ["--remote", "n/sim1", "--endpoint", endpoint]
    bridge = ["bridge", "--sim", "3", "--node", "n", "--listen", endpoint]
    page = ["dashboard", *remote, "--listen", "127.0.0.1:0"]
    with _process(bridge, "serving"), _process(page, "servobus dashboard:") as (_, line):
        match = URL.match(line)
        assert match, line
        url = match.group(1)
        rows = _get(url + "api/snapshot")["motors"]
        assert [r["key"] for r in rows] == ["n/sim1/1", "n/sim1/2", "n/sim1/3"]
        assert _until(lambda: all(r["reply"] for r in _get(url + "api/snapshot")["motors"]))  # read
        assert _post(url + "api/stop", {"motors": "all"})[0] == 403  # read-only: refused
        # another client turns motor 2: the states the bridge publishes show it
        speed = ["speed", *remote, "--ids", "2", "--speed-dps", "90", "--duration", "20"]
        turner = subprocess.Popen([*SERVOBUS, *speed], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            assert _until(lambda: _turning(url), 15)
        finally:
            turner.kill()
            turner.wait()
    with (
        _process(bridge, "serving"),
        _process([*page, "--allow-commands"], "servobus dashboard:") as (_, line),
    ):
        url = URL.match(line).group(1)  # type: ignore[union-attr]
        # a stop sent before the page has heard from the bridge is honestly not acknowledged: wait for it
        assert _until(lambda: all(r["reply"] for r in _get(url + "api/snapshot")["motors"]))
        status, done = _post(url + "api/stop", {"motors": ["n/sim1/1"]})
        assert status == 200 and done == {"acknowledged": ["n/sim1/1"], "not_acknowledged": []}
        # another client holds motor 2: the bridge refuses the page its stop; the others are stopped
        turner = subprocess.Popen([*SERVOBUS, *speed], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            assert _until(lambda: _turning(url), 15)
            status, done = _post(url + "api/stop", {"motors": "all"})
            assert status == 200, done
            assert sorted(done["acknowledged"]) == ["n/sim1/1", "n/sim1/3"], done
            assert done["not_acknowledged"] == ["n/sim1/2"], done
        finally:
            turner.kill()
            turner.wait()


# ---- what it sends ----


def _spinning(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Have ``--sim`` build motors already turning at 30 dps (commanded before the dashboard came)."""
    import servobus.cli._connect as connect
    from servobus.protocols import myactuator as ma

    made: list[Any] = []
    build = connect.sim_devices

    def devices(family: str, ids: tuple[int, ...], revision: str | None = None) -> list[Any]:
        found = build(family, ids, revision)
        for device in found:
            device.handle(ma.SpeedControl(speed_dps=30.0), 0.0)
        made.extend(found)
        return found

    monkeypatch.setattr(connect, "sim_devices", devices)
    return made


def test_reading_only_it_never_commands_a_motor_not_even_on_the_way_out(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from servobus.cli import main
    from servobus.sim.plant import PositionControl, SpeedControl

    devices = _spinning(monkeypatch)
    args = ["dashboard", "--sim", "2", "--still", "--duration", "0.5", "--listen", "127.0.0.1:0"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert URL.match(out.splitlines()[0]) and "read-only" in out
    assert len(devices) == 2 and all(isinstance(d.control, SpeedControl) for d in devices)
    assert all(d.counters["received"] >= 10 for d in devices)  # (read, at --hz)
    # moving them (the default with --sim), the dashboard commanded them: stopped on the way out
    devices.clear()
    assert main(args[:3] + args[4:]) == 0
    assert len(devices) == 2 and all(isinstance(d.control, PositionControl) for d in devices)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_sigterm_with_a_page_open_ends_it_cleanly_and_stops_the_motors_it_moved(backend: str) -> None:
    import http.client

    args = [*SERVOBUS, "dashboard", "--sim", "2", "--listen", "127.0.0.1:0", "--backend", backend]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None and process.stderr is not None
        ready, _, _ = select.select([process.stdout], [], [], 30)
        match = URL.match(process.stdout.readline() if ready else "")
        assert match, process.poll()
        host, port = match.group(1).split("//")[1].strip("/").split(":")
        page = http.client.HTTPConnection(host, int(port), timeout=10)
        page.request("GET", "/api/events")
        stream = page.getresponse()
        assert stream.status == 200 and stream.readline().startswith(b"event: update")  # a page open
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=15) == 0
        err = process.stderr.read()
        assert err.splitlines() == [
            "servobus dashboard: stopped by SIGTERM; stop sent to myactuator motors 1, 2 on sim"
        ]
        page.close()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()

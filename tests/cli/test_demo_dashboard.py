"""``servobus demo --dashboard``: the dashboard of the demo's buses and loop, served while it runs.

Its URL is the first line (stderr with ``--json``); the page and its API answer while the demo runs,
read-only; it listens on this host only (a wider address is refused, pointing to ``servobus
dashboard``); the demo's own lines and summary are those of a demo without it.
"""

from __future__ import annotations

import json
import selectors
import socket
import subprocess
import sys
import threading
import time
from typing import IO

import httpx
import pytest

from cli._bus_cli import SERVOBUS, one_line, run
from servobus.cli.demo import DASHBOARD_AT, demo

SMALL = ["--motors", "6", "--hz", "200"]


def _line(stream: IO[str], timeout_s: float) -> str:
    """The next line of ``stream``, waited for at most ``timeout_s``."""
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        if not selector.select(timeout_s):
            raise AssertionError(f"no line within {timeout_s} s")
    return stream.readline()


def _url(line: str) -> str:
    assert line.startswith("servobus dashboard: http://127.0.0.1:"), line
    assert "read-only" in line
    return line.split()[2]


def test_the_page_and_its_api_answer_while_the_demo_runs() -> None:
    process = subprocess.Popen(
        [*SERVOBUS, "demo", "--duration", "4", *SMALL, "--dashboard", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        url = _url(_line(process.stdout, 20))
        with httpx.Client(base_url=url, timeout=5) as client:
            page = client.get("/")
            assert page.status_code == 200 and 'id="motors"' in page.text
            assert client.get("/api/info").json()["commands"] is False
            deadline = time.monotonic() + 5
            while True:  # (the first snapshot may come before the loop's first tick)
                snapshot = client.get("/api/snapshot").json()
                loops = snapshot["loops"]
                if (loops and loops[0]["ticks"] > 0) or time.monotonic() > deadline:
                    break
                time.sleep(0.1)
            assert [m["key"] for m in snapshot["motors"]] == [f"bus 1/{i}" for i in range(1, 7)]
            assert all(m["status"] == "online" and m["reply"] == "StatusReply" for m in snapshot["motors"])
            assert loops[0]["hz"] == 200 and loops[0]["ticks"] > 0
            assert any(f["name"].startswith("StatusReply (motor") for f in snapshot["buses"][0]["frames"])
            with client.stream("GET", "/api/events") as events:
                lines = events.iter_lines()
                assert next(line for line in lines if line.startswith("event:")) == "event: update"
                assert json.loads(next(lines).removeprefix("data: "))["motors"]
            # read-only: the page's stop is refused, the demo goes on moving its motors
            stop = client.post("/api/stop", json={"motors": "all", "kind": "stop"})
            assert stop.status_code == 403
        process.wait(timeout=30)
        out = process.stdout.read()  # (the lines after the URL: some were read with it, into the buffer)
    finally:
        process.kill()
        process.wait()
    assert process.returncode == 0
    assert out.startswith("servobus demo: 6 simulated myactuator motor(s) on 1 simulated CAN bus, 200 Hz")
    assert "\nerrors      0 " in out


def test_a_page_still_open_at_the_end_is_closed_cleanly() -> None:
    """The demo ends its page's update stream before its server stops: no stream cut by force (which
    printed asyncio's traceback of a cancelled connection), and the page's stream ends."""
    process = subprocess.Popen(
        [*SERVOBUS, "demo", "--duration", "2", *SMALL, "--json", "--dashboard", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    got: list[str] = []

    def page(url: str) -> None:
        with httpx.Client(timeout=10) as client, client.stream("GET", url + "api/events") as events:
            got.extend(line for line in events.iter_lines() if line.startswith("event:"))

    try:
        assert process.stderr is not None
        reader = threading.Thread(target=page, args=(_url(_line(process.stderr, 20)),), daemon=True)
        reader.start()
        out, err = process.communicate(timeout=30)
        reader.join(timeout=10)
    finally:
        process.kill()
        process.wait()
    assert process.returncode == 0 and json.loads(out)["errors"] == 0
    assert got and not reader.is_alive()  # (updates came, then the stream ended)
    assert "Traceback" not in err and "CancelledError" not in err, err


def test_json_stays_one_document_and_the_summary_is_the_demos(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["demo", "--duration", "0.5", *SMALL, "--json"]
    out, err = run(capsys, [*args, "--dashboard", "127.0.0.1:0"])
    _url(err.splitlines()[0])
    served = json.loads(out)
    plain = json.loads(run(capsys, args)[0])
    assert served.keys() == plain.keys()
    assert served["errors"] == 0 and served["pairs"] == 6 * served["ticks"]


def test_the_text_lines_are_the_demos_after_the_url(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["demo", "--duration", "0.3", *SMALL]
    served = run(capsys, [*args, "--dashboard", "127.0.0.1:0"])[0].splitlines()
    plain = run(capsys, args)[0].splitlines()
    _url(served[0])
    assert served[1:3] == plain[:2]  # the demo's header lines, word for word

    def labels(lines: list[str]) -> list[str]:  # (a "why" line comes when the rate was not kept)
        return [line.split()[0] for line in lines if not line.startswith("why ")]

    assert labels(served[3:]) == labels(plain[2:])


def test_bare_dashboard_serves_on_the_default_loopback_port() -> None:
    context = demo.make_context("demo", ["--dashboard", "--duration", "1"])
    assert context.params["dashboard_at"] == DASHBOARD_AT == "127.0.0.1:8765"
    assert demo.make_context("demo", ["--duration", "1"]).params["dashboard_at"] is None


@pytest.mark.parametrize("where", ["0.0.0.0:0", "192.0.2.1:8765", "[::]:0"])
def test_beyond_this_host_is_refused(capsys: pytest.CaptureFixture[str], where: str) -> None:
    err = one_line(capsys, ["demo", "--duration", "0.1", "--dashboard", where])
    assert "--dashboard" in err and "this host only" in err and "servobus dashboard" in err


def test_not_an_address_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    err = one_line(capsys, ["demo", "--duration", "0.1", "--dashboard", "localhost"])
    assert "--dashboard" in err and "HOST:PORT" in err


def test_a_taken_port_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        err = one_line(capsys, ["demo", "--duration", "0.1", "--dashboard", f"127.0.0.1:{port}"], code=1)
    assert f"127.0.0.1:{port}" in err


def test_a_missing_extra_is_one_line(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in list(sys.modules):
        if name == "servobus.dashboard" or name.startswith(("servobus.dashboard.", "starlette")):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "starlette", None)
    err = one_line(capsys, ["demo", "--duration", "0.1", "--dashboard"], code=1)
    assert "pip install 'servobus[dashboard]'" in err

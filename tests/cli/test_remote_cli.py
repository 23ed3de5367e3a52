"""``servobus bridge`` and the ``--remote`` commands: a bridge of simulated buses in its own process,
and status, scan, monitor, set-points and one-shots through it, with the local commands' output; a
bridge that would listen beyond loopback without access control, ``--remote`` with a local bus, and
a bridge that is not there are one line and an exit code, at once."""

from __future__ import annotations

import contextlib
import json
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from _ports import free_port as _free_port
from cli._bus_cli import SERVOBUS, one_line, run, run_json

pytest.importorskip("zenoh")

NODE = "n"


@pytest.fixture(scope="module")
def bridge() -> Iterator[tuple[str, str]]:
    """``servobus bridge --sim 8 --buses 2`` in its own process: (its endpoint, its first line).
    Stopped with SIGTERM at the end: exit 0, and a line on stderr."""
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    args = ["bridge", "--sim", "8", "--buses", "2", "--node", NODE, "--listen", endpoint]
    process = subprocess.Popen([*SERVOBUS, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        ready, _, _ = select.select([process.stdout], [], [], 20)
        first = process.stdout.readline().strip() if ready else ""
        assert first.startswith("serving"), (first, process.poll())
        yield endpoint, first
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=20)
        assert process.returncode == 0, err
        assert f"servobus bridge: {NODE} stopped by SIGTERM" in err, err
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def _remote(endpoint: str, bus: str = "sim1") -> list[str]:
    return ["--remote", f"{NODE}/{bus}", "--endpoint", endpoint]


def test_the_bridge_says_what_it_serves_where(bridge: tuple[str, str]) -> None:
    endpoint, first = bridge
    assert first == f"serving {NODE}/sim1 (4 motors), {NODE}/sim2 (4 motors) on {endpoint}"


def test_status_through_the_bridge_reads_every_motor_of_the_bus(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str]
) -> None:
    endpoint, _ = bridge
    rows = run_json(capsys, ["status", *_remote(endpoint)])
    assert [r["id"] for r in rows] == [1, 2, 3, 4]
    assert all(r["temperature_c"] == 25 and r["voltage_v"] > 0 and r["error"] is None for r in rows)
    out, _ = run(capsys, ["status", *_remote(endpoint, "sim2"), "--ids", "2,3"])
    assert "angle_deg" in out and "voltage_v" in out


def test_scan_through_the_bridge_lists_its_motors(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str]
) -> None:
    endpoint, _ = bridge
    rows = run_json(capsys, ["scan", *_remote(endpoint, "sim2")])
    assert [r["id"] for r in rows] == [1, 2, 3, 4]
    assert all(r["family"] == "myactuator" and r["model"] and r["firmware"] for r in rows), rows


def test_a_move_through_the_bridge_arrives_and_the_bridge_stops_the_motor_after(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str]
) -> None:
    endpoint, _ = bridge
    move = ["move", *_remote(endpoint), "--ids", "2", "--angle-deg", "20", "--duration", "5"]
    rows = run_json(capsys, move)
    assert [r["id"] for r in rows] == [2] and abs(rows[0]["angle_deg"] - 20) <= 1, rows
    speed = ["speed", *_remote(endpoint), "--ids", "3", "--speed-dps", "90", "--duration", "0.5"]
    rows = run_json(capsys, speed)
    assert rows[0]["speed_dps"] == pytest.approx(90, abs=5), rows
    time.sleep(0.2)  # (the bridge's safe stop for the client that left)
    after = {r["id"]: r for r in run_json(capsys, ["status", *_remote(endpoint)])}
    assert abs(after[2]["angle_deg"] - 20) <= 1.5 and after[3]["speed_dps"] == 0, after


def test_a_one_shot_through_the_bridge_gets_its_reply(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str]
) -> None:
    endpoint, _ = bridge
    rows = run_json(capsys, ["stop", *_remote(endpoint, "sim2"), "--ids", "1"])
    assert rows[0]["sent"] == ["MotorStop"] and rows[0]["error"] is None and rows[0]["replies"][0], rows


def test_monitor_through_the_bridge_prints_the_states_it_publishes(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str]
) -> None:
    endpoint, _ = bridge
    args = ["monitor", *_remote(endpoint), "--ids", "1,4", "--duration", "0.3", "--json"]
    out, _ = run(capsys, args)
    lines = [json.loads(line) for line in out.splitlines()]
    assert {line["id"] for line in lines} == {1, 4} and all("angle_deg" in line for line in lines)


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--sim", "2"], "--remote and --sim"),
        (["-i", "virtual", "-c", "x"], "--remote and --interface, --channel"),
    ],
)
def test_remote_with_a_local_bus_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], said: str
) -> None:
    err = one_line(capsys, ["status", "--remote", f"{NODE}/sim1", *args])
    assert said in err


def test_commanding_options_a_remote_set_point_cannot_honour_are_refused(
    capsys: pytest.CaptureFixture[str],
) -> None:
    remote = ["--remote", f"{NODE}/sim1", "--endpoint", f"tcp/127.0.0.1:{_free_port()}"]
    assert "--read-only" in one_line(capsys, ["move", *remote, "--angle-deg", "5", "--read-only"])
    assert "--keep" in one_line(capsys, ["speed", *remote, "--speed-dps", "5", "--keep"])
    assert "NODE/BUS" in one_line(capsys, ["status", "--remote", "nobus"])
    assert "--remote" in one_line(capsys, ["status", "--sim", "1", "--endpoint", "tcp/127.0.0.1:1"])


def test_no_bridge_there_is_one_line_and_exit_1_at_once(capsys: pytest.CaptureFixture[str]) -> None:
    start = time.monotonic()
    args = ["status", "--remote", f"{NODE}/sim1", "--endpoint", f"tcp/127.0.0.1:{_free_port()}"]
    err = one_line(capsys, args, code=1)
    assert "no bridge reachable" in err
    assert time.monotonic() - start < 6


def test_a_bridge_beyond_loopback_without_access_control_refuses_to_start() -> None:
    """One line, exit 2, before any bus or socket is opened (it would serve forever otherwise)."""
    args = ["bridge", "--sim", "1", "--listen", "tcp/0.0.0.0:7447"]
    done = subprocess.run([*SERVOBUS, *args], capture_output=True, text=True, timeout=30)
    assert done.returncode == 2 and done.stdout == "", done
    assert len(done.stderr.splitlines()) == 1 and "refusing to listen on tcp/0.0.0.0:7447" in done.stderr


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--sim", "4", "--buses", "5"], "5 buses for 4 motors"),
        (["--sim", "4", "--buses", "2", "--ids", "1-4"], "--ids with --buses"),
        (["--sim", "2", "--node", "_x"], "--node"),
        (["--sim", "2", "--commander", "alice"], "no authentication"),
    ],
)
def test_bad_bridge_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], said: str
) -> None:
    assert said in one_line(capsys, ["bridge", *args])


def test_the_default_endpoint_is_the_security_modules() -> None:
    """The CLI names it without importing Zenoh (it loads without the [remote] extra)."""
    from servobus.cli import _remote
    from servobus.cli import bridge as bridge_cli
    from servobus.remote.security import DEFAULT_ENDPOINT

    assert _remote._default() == bridge_cli.DEFAULT_ENDPOINT == DEFAULT_ENDPOINT


@pytest.mark.parametrize(
    "args", [["status", "--remote", f"{NODE}/sim1"], ["bridge", "--sim", "1"], ["status", "--sim", "1"]]
)
def test_without_zenoh_remote_is_one_line_naming_the_extra_and_local_commands_still_run(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, args: list[str]
) -> None:
    monkeypatch.setitem(sys.modules, "zenoh", None)  # (import zenoh raises ImportError)
    for name in [n for n in sys.modules if n == "servobus.remote" or n.startswith("servobus.remote.")]:
        monkeypatch.delitem(sys.modules, name)
    if args[0] == "status" and "--sim" in args:
        run(capsys, args)
    else:
        assert "pip install 'servobus[remote]'" in one_line(capsys, args, code=1)


@pytest.mark.parametrize(
    "args",
    [
        ["torque", "--ids", "4", "--current-a", "0.1", "--duration", "0.2"],
        ["mit", "--ids", "4", "--position-rad", "0.2", "--kp", "5", "--kd", "0.5", "--duration", "0.2"],
        ["off", "--ids", "4"],
        ["brake", "--ids", "4", "--lock"],
    ],
)
def test_the_other_commands_run_through_the_bridge(
    capsys: pytest.CaptureFixture[str], bridge: tuple[str, str], args: list[str]
) -> None:
    endpoint, _ = bridge
    rows = run_json(capsys, [args[0], *_remote(endpoint, "sim2"), *args[1:]])
    assert [r["id"] for r in rows] == [4] and rows[0]["error"] is None, rows


@contextlib.contextmanager
def _bridge(*args: str) -> Iterator[str]:
    """A bridge of its own (``servobus bridge ARGS``, a free loopback port): its endpoint."""
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    process = subprocess.Popen(
        [*SERVOBUS, "bridge", *args, "--listen", endpoint],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        ready, _, _ = select.select([process.stdout], [], [], 20)
        assert ready and process.stdout.readline().startswith("serving"), process.poll()
        yield endpoint
    finally:
        process.terminate()
        process.wait(timeout=20)


def test_with_users_a_commander_commands_a_reader_reads_and_a_wrong_password_is_one_line(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    users = tmp_path / "users.txt"
    users.write_text("alice:secret\nbob:pw\n")
    args = ["--sim", "2", "--node", NODE, "--users", str(users), "--commander", "alice", "--reader", "bob"]
    with _bridge(*args) as endpoint:
        remote = _remote(endpoint)
        alice = ["--user", "alice", "--password", "secret"]
        move = ["move", *remote, *alice, "--ids", "1", "--angle-deg", "10", "--duration", "3"]
        rows = run_json(capsys, move)
        assert abs(rows[0]["angle_deg"] - 10) <= 1, rows
        monkeypatch.setenv("SERVOBUS_REMOTE_USER", "bob")  # (from the environment)
        monkeypatch.setenv("SERVOBUS_REMOTE_PASSWORD", "pw")
        assert [r["id"] for r in run_json(capsys, ["status", *remote])] == [1, 2]
        err = one_line(capsys, ["stop", *remote, "--ids", "1"], code=1)
        assert "access control refused it" in err
        monkeypatch.setenv("SERVOBUS_REMOTE_PASSWORD", "wrong")
        assert "credentials were refused" in one_line(capsys, ["status", *remote], code=1)

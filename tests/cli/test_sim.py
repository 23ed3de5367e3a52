"""``servobus sim``: the simulator's pty server under the servobus command (its own argument handling):
the first line is the pty to open and motors answer there; bad arguments are one line, exit 2;
``--link`` never touches a file it did not create."""

from __future__ import annotations

import asyncio
import dataclasses
import subprocess
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from cli._bus_cli import SERVOBUS, one_line, pty_simulators, run, run_json
from servobus import _plugins
from servobus.bus import Bus
from servobus.protocols import ENTRY_POINT_GROUP, get_family
from servobus.protocols import hollow as ho
from servobus.sim import __main__ as server
from servobus.transports.slcan import SlcanTransport


def test_served_motors_answer_the_cli_through_the_pty(capsys: pytest.CaptureFixture[str]) -> None:
    with pty_simulators() as start:
        path = start("--family", "lk", "--motors", "2", "--first-id", "9")
        rows = run_json(
            capsys, ["status", "--family", "lk", "-i", "servobus-slcan", "-c", path, "--ids", "9,10"]
        )
    assert [r["id"] for r in rows] == [9, 10] and all(r["error"] is None for r in rows)


def test_link_is_made_and_removed(tmp_path: Path) -> None:
    link = tmp_path / "can0"
    with pty_simulators() as start:
        assert start("--family", "myactuator", "--link", str(link)) == str(link)
        assert link.is_symlink()
    assert not link.exists()


def test_link_never_replaces_an_existing_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    taken = tmp_path / "taken"
    taken.write_text("mine")
    err = one_line(capsys, ["sim", "--family", "myactuator", "--link", str(taken)])
    assert "already exists" in err and taken.read_text() == "mine"


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["sim", "--family", "nope"], "--family"),
        (["sim"], "--family"),
        (["sim", "--family", "lk", "--rs485"], "--rs485"),
        (["sim", "--family", "myactuator", "--motors", "0"], "--motors"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args)


def test_help_has_examples_and_the_simulator_options(capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = run(capsys, ["sim", "--help"])
    assert "Examples:" in out and "servobus sim --family myactuator" in out and "--first-id" in out


def test_the_console_script_exits_with_the_servers_status() -> None:
    done = subprocess.run([*SERVOBUS, "sim", "--family", "nope"], capture_output=True, text=True, timeout=30)
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1


def test_can_fd_motors_answer_can_fd_frames_through_the_slcan_pty() -> None:
    """``--fd`` reaches the family's simulator part: its motors answer 16-byte CAN FD requests."""

    async def poll(path: str) -> list[object]:
        async with Bus(SlcanTransport(path, fd=True, data_bitrate=5_000_000)) as bus:
            motors = [bus.motor("hollow", i, link="canfd") for i in (1, 2)]
            return list(await asyncio.gather(*(m.request(ho.FdCommand()) for m in motors)))

    with pty_simulators() as start:
        path = start("--family", "hollow", "--motors", "2", "--fd")
        replies = asyncio.run(poll(path))
    assert [type(r) for r in replies] == [ho.FdReply, ho.FdReply]


#: a family a plug-in registers, without a simulator part (its codec is LK's under another name)
BARE = dataclasses.replace(get_family("lk"), name="bare", parts={}, package=None)


@pytest.fixture
def bare(monkeypatch: pytest.MonkeyPatch) -> None:
    """:data:`BARE` registered under ``servobus.families`` by entry point, as a plug-in would be."""
    found = [EntryPoint("bare", f"{__name__}:BARE", ENTRY_POINT_GROUP)]
    monkeypatch.setattr(_plugins, "entry_points", lambda group: found if group == ENTRY_POINT_GROUP else [])


@pytest.mark.usefixtures("bare")
def test_a_plug_in_family_is_offered_and_one_without_a_simulator_is_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    err = one_line(capsys, ["sim", "--family", "bare"])
    assert err.startswith("servobus.sim: error: --family bare: the bare family has no sim part"), err
    assert server.main(["--family", "nope"]) == 2  # (python -m servobus.sim exits with it)
    assert "'bare'" in capsys.readouterr().err  # the choices listed with the refusal

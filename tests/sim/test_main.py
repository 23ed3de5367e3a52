"""``python -m servobus.sim``: the first line is a path any tool can open, and motors answer there."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import can
import can.interfaces.slcan
import pytest
import serial

from servobus.protocols import hollow, myactuator
from servobus.protocols.hollow.codec import request_frame
from servobus.protocols.myactuator.rs485 import decode_rs485, encode_rs485

Start = Callable[[Sequence[str]], str]  # starts the simulator with these arguments, returns its path


@pytest.fixture
def simulator() -> Iterator[Start]:
    processes: list[subprocess.Popen[str]] = []

    def start(args: Sequence[str]) -> str:
        process = subprocess.Popen(
            [sys.executable, "-m", "servobus.sim", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        processes.append(process)
        assert process.stdout is not None
        path = process.stdout.readline().strip()
        assert path.startswith("/"), (
            f"first line was {path!r}; stderr: {process.stderr.read() if not path else ''}"
        )
        return path

    yield start
    for process in processes:
        process.terminate()
        process.wait(timeout=5)


def test_slcan_hollow_motors_answer_python_can(simulator: Start) -> None:
    path = simulator(["--family", "hollow", "--motors", "4", "--slcan"])
    bus = can.Bus(interface="slcan", channel=path, bitrate=1_000_000, sleep_after_open=0)
    try:
        for motor_id in (1, 4):
            frame = request_frame(motor_id, hollow.Start())
            bus.send(can.Message(arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=False))
            reply = bus.recv(timeout=2.0)
            assert reply is not None and reply.arbitration_id == hollow.DEFAULT_HOST_ID
            decoded = hollow.decode_reply(reply.arbitration_id, bytes(reply.data))
            assert isinstance(decoded, hollow.NormalReply) and decoded.motor_id == motor_id
    finally:
        bus.shutdown()


def test_slcan_lk_v235_motors_reply_on_the_request_id(simulator: Start) -> None:
    path = simulator(["--family", "lk", "--motors", "2", "--revision", "V2_35"])
    bus = can.Bus(interface="slcan", channel=path, bitrate=1_000_000, sleep_after_open=0)
    try:
        bus.send(can.Message(arbitration_id=0x142, data=[0x9C] + [0] * 7, is_extended_id=False))
        reply = bus.recv(timeout=2.0)
    finally:
        bus.shutdown()
    assert reply is not None and reply.arbitration_id == 0x142 and reply.data[0] == 0x9C


def test_rs485_hollow_converter_answers_a_serial_port(simulator: Start) -> None:
    path = simulator(["--family", "hollow", "--motors", "2", "--rs485"])
    with serial.Serial(path, 1_000_000, timeout=2.0) as port:
        port.write(hollow.TransparentRequest(motor_id=2).encode())
        reply = hollow.TransparentReply.decode(port.read(21))
    assert reply.reply.slave_id == 2


@pytest.mark.parametrize("baud", [115_200, 1_000_000])
def test_rs485_myactuator_motors_answer_a_serial_port(simulator: Start, baud: int) -> None:
    path = simulator(["--family", "myactuator", "--motors", "3", "--rs485", "--baud", str(baud)])
    with serial.Serial(path, baud, timeout=2.0) as port:
        port.write(encode_rs485(3, myactuator.ReadStatus2()))
        motor_id, data = decode_rs485(port.read(13))
    assert motor_id == 3 and isinstance(myactuator.decode_reply(0x243, data), myactuator.StatusReply)


def run_simulator(args: Sequence[str], cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run the simulator to completion (for arguments it must refuse before serving anything)."""
    return subprocess.run(
        [sys.executable, "-m", "servobus.sim", *args],
        capture_output=True,
        text=True,
        timeout=30,
        cwd=cwd,
    )


def assert_refused(result: subprocess.CompletedProcess[str], *naming: str) -> None:
    """Exit status 2, nothing on stdout, and exactly one stderr line: the error, naming the problem."""
    lines = result.stderr.splitlines()
    assert result.returncode == 2, result.stderr
    assert result.stdout == ""
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("servobus.sim: error: ")
    for text in naming:
        assert text in lines[0]


REFUSED = {
    # issue 14: each of these ended in a traceback (or served a line that could not work)
    "first id outside myactuator's ids": (
        ["--family", "myactuator", "--first-id", "99"],
        ["--first-id 99", "1..32"],
    ),
    "unknown revision": (["--family", "myactuator", "--revision", "V9"], ["--revision V9", "V4_3", "V4_4"]),
    "negative baud": (["--family", "myactuator", "--rs485", "--baud", "-5"], ["--baud -5", "115200"]),
    "baud not on the myactuator line": (
        ["--family", "myactuator", "--rs485", "--baud", "9600"],
        ["--baud 9600", "2500000"],
    ),
    "lk has no rs485": (["--family", "lk", "--rs485"], ["--rs485", "--slcan"]),
    # the id range, per family, first id and last
    "too many myactuator motors": (["--family", "myactuator", "--motors", "40"], ["--motors 40", "1..32"]),
    "last lk id past 32": (
        ["--family", "lk", "--first-id", "30", "--motors", "4"],
        ["--first-id 30 --motors 4", "30..33", "1..32"],
    ),
    "lk id 0": (["--family", "lk", "--first-id", "0"], ["--first-id 0", "1..32"]),
    "hollow id past 100": (["--family", "hollow", "--first-id", "101"], ["--first-id 101", "0..100"]),
    "hollow motors past 100": (
        ["--family", "hollow", "--first-id", "0", "--motors", "102"],
        ["--motors 102", "0..100"],
    ),
    "hollow modbus broadcast address": (
        ["--family", "hollow", "--rs485", "--modbus", "--first-id", "0"],
        ["--first-id 0", "--modbus", "1..100"],
    ),
    "no motors": (["--family", "hollow", "--motors", "0"], ["--motors 0"]),
    "negative motors": (["--family", "lk", "--motors", "-3"], ["--motors -3"]),
    # contradictory flags
    "slcan and rs485": (["--family", "myactuator", "--slcan", "--rs485"], ["--rs485", "--slcan"]),
    "baud without rs485": (["--family", "myactuator", "--baud", "1000000"], ["--baud", "--rs485"]),
    "baud on the hollow converter": (
        ["--family", "hollow", "--rs485", "--baud", "1000000"],
        ["--baud", "converter"],
    ),
    "modbus without rs485": (["--family", "hollow", "--modbus"], ["--modbus", "--rs485"]),
    "modbus on myactuator": (["--family", "myactuator", "--rs485", "--modbus"], ["--modbus", "myactuator"]),
    "fd with rs485": (["--family", "hollow", "--rs485", "--fd"], ["--fd", "--rs485"]),
    "fd on lk": (["--family", "lk", "--fd"], ["--fd", "lk"]),
    # what argparse itself refuses is one line too
    "unknown family": (["--family", "bogus"], ["--family", "bogus"]),
    "no family": (["--motors", "2"], ["--family"]),
    "not a number": (["--family", "hollow", "--baud", "fast"], ["--baud", "fast"]),
}


@pytest.mark.parametrize("args, naming", list(REFUSED.values()), ids=list(REFUSED))
def test_bad_arguments_exit_2_with_one_line(args: list[str], naming: list[str]) -> None:
    assert_refused(run_simulator(args), *naming)


@pytest.mark.parametrize(
    "args",
    [
        ["--family", "lk", "--revision", "v2.35"],  # as the family's revision() reads it
        ["--family", "myactuator", "--revision", "v4_3", "--first-id", "29", "--motors", "4"],
        ["--family", "hollow", "--revision", "ho_series", "--first-id", "0", "--motors", "101"],
        ["--family", "hollow", "--rs485", "--modbus", "--first-id", "100"],
        ["--family", "myactuator", "--rs485", "--baud", "2500000"],
    ],
    ids=["lk-v2.35", "myactuator-ids-29-32", "hollow-ids-0-100", "hollow-modbus-100", "myactuator-2.5M"],
)
def test_arguments_at_the_limits_are_served(simulator: Start, args: list[str]) -> None:
    assert simulator(args).startswith("/dev/")


def test_link_never_overwrites_an_existing_file(tmp_path: Path) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    notes.chmod(0o640)
    result = run_simulator(["--family", "hollow", "--link", "notes.txt"], cwd=tmp_path)
    assert_refused(result, "--link notes.txt", "already exists")
    assert not notes.is_symlink() and notes.read_text() == "my notes\n"
    assert stat.S_IMODE(notes.stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # no .new or other leftovers


def test_link_never_replaces_an_existing_symlink(tmp_path: Path) -> None:
    link = tmp_path / "motor"
    link.symlink_to("/dev/null")
    assert_refused(run_simulator(["--family", "lk", "--link", str(link)]), f"--link {link}", "/dev/null")
    assert os.readlink(link) == "/dev/null"


@pytest.mark.parametrize("folder", ["missing", "file"])
def test_link_in_a_missing_folder_is_refused(tmp_path: Path, folder: str) -> None:
    (tmp_path / "file").write_text("")
    link = tmp_path / folder / "motor"
    assert_refused(run_simulator(["--family", "myactuator", "--link", str(link)]), f"--link {link}")
    assert not (tmp_path / "missing").exists() and (tmp_path / "file").read_text() == ""


def start_linked(link: Path) -> subprocess.Popen[str]:
    process = subprocess.Popen(
        [sys.executable, "-m", "servobus.sim", "--family", "hollow", "--link", str(link)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    assert process.stdout.readline().strip() == str(link)
    return process


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP], ids=["TERM", "INT", "HUP"])
def test_link_is_created_and_removed_on_exit(tmp_path: Path, stop: signal.Signals) -> None:
    link = tmp_path / "motor"
    process = start_linked(link)
    try:
        assert os.readlink(link).startswith("/dev/pts/")
        bus = can.Bus(interface="slcan", channel=str(link), bitrate=1_000_000, sleep_after_open=0)
        bus.shutdown()
    finally:
        process.send_signal(stop)
        assert process.wait(timeout=10) == 0
    assert not os.path.lexists(link)


@pytest.mark.parametrize("replacement", ["symlink", "file"])
def test_link_replaced_meanwhile_is_left_alone(tmp_path: Path, replacement: str) -> None:
    link = tmp_path / "motor"
    process = start_linked(link)
    try:
        new = tmp_path / "motor.other"
        if replacement == "symlink":
            new.symlink_to("/dev/null")
        else:
            new.write_text("someone else's")
        new.replace(link)
    finally:
        process.terminate()
        assert process.wait(timeout=10) == 0
    if replacement == "symlink":
        assert os.readlink(link) == "/dev/null"
    else:
        assert link.read_text() == "someone else's"

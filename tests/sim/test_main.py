"""``python -m servobus.sim``: the first line is a path any tool can open, and motors answer there."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence

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


def test_bad_arguments_are_refused() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "servobus.sim", "--family", "hollow", "--motors", "40"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert result.returncode == 2 and "--motors 40 is outside 1..32" in result.stderr

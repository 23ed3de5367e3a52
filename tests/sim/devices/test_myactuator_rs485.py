"""The RS485 front of the simulated MyActuator motor: sans-IO framing rules, then a real pty line.

Spec §1.2 (frame, CRC-16/MODBUS), §1.3 (0xCD broadcast: each motor answers with its own id), §4.36
(no 0xB6 on RS485). The pty tests serve 32 motors with ``serve_rs485`` and talk to them with pyserial.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
import serial

from _serving import serving
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.ids import RS485_BROADCAST_ID
from servobus.protocols.myactuator.rs485 import decode_rs485_reply, encode_rs485
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.sim.attach import serve_rs485
from servobus.sim.plant import Brake, SpeedControl
from servobus.sim.pty import PtyPort

from ._myactuator import TURNAROUND


def _front(motor_id: int, **kwargs: Any) -> MyActuatorRs485Motor:
    return MyActuatorRs485Motor(MyActuatorMotor(motor_id, **kwargs))


def _reply(front: MyActuatorRs485Motor, frame: bytes, at: float) -> tuple[int, Any]:
    (out,) = front.receive_bytes(frame, at)
    assert out.ready_s == pytest.approx(at + TURNAROUND, abs=1e-12)
    return decode_rs485_reply(out.data, revision=front.motor.revision)


# ---- sans-IO ----


def test_split_and_joined_input_is_framed_like_a_wire() -> None:
    front = _front(3)
    request = encode_rs485(3, ma.ReadStatus2())
    assert front.receive_bytes(request[:5], 0.0) == []
    # The rest of the first frame, a whole second one and the start of noise, in one chunk.
    out = front.receive_bytes(request[5:] + request + b"\x00\x3e", 0.001)
    assert [decode_rs485_reply(o.data)[0] for o in out] == [3, 3]
    assert front.counters["frames"] == 2 and front.motor.counters["replied"] == 2


def test_only_own_id_and_broadcast_are_answered_broadcast_with_own_id() -> None:
    front = _front(7)
    assert front.receive_bytes(encode_rs485(8, ma.ReadStatus2()), 0.0) == []
    assert front.counters["ignored_id"] == 1
    motor_id, reply = _reply(front, encode_rs485(RS485_BROADCAST_ID, ma.SpeedControl(speed_dps=40.0)), 0.0)
    assert motor_id == 7 and isinstance(reply, ma.StatusReply)
    assert isinstance(front.motor.plant.control, SpeedControl)


def test_corrupt_crc_gets_no_reply_and_is_counted() -> None:
    front = _front(1)
    good = encode_rs485(1, ma.ReadStatus1())
    bad = good[:-1] + bytes([good[-1] ^ 0x01])
    assert front.receive_bytes(bad, 0.0) == []
    assert front.counters["crc_errors"] == 1 and front.motor.counters["accepted"] == 0
    assert len(front.receive_bytes(good, 0.01)) == 1


def test_active_reply_is_not_supported_on_rs485() -> None:
    """§4.36: "Only valid for CAN version, 485 version does not support this function"."""
    front = _front(1)
    enable = ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=10).encode()
    assert front.receive_bytes(encode_rs485(1, enable), 0.0) == []
    assert front.counters["rs485_unsupported"] == 1 and front.motor.streams == {}
    assert front.next_deadline_s() is None
    assert isinstance(
        _reply(front, encode_rs485(1, ma.ReadStatus2()), 0.1)[1], ma.StatusReply
    )  # still answers


def test_comm_protection_trips_on_rs485_and_error_reports_are_not_sent() -> None:
    front = _front(1)
    _reply(front, encode_rs485(1, ma.SetCommTimeout(timeout_ms=100)), 0.0)
    _reply(front, encode_rs485(1, ma.FunctionControl.error_reporting(True)), 0.0)
    _reply(front, encode_rs485(1, ma.SpeedControl(speed_dps=40.0)), 0.01)
    assert front.next_deadline_s() == pytest.approx(0.11)
    assert front.poll(0.11) == []
    assert isinstance(front.motor.plant.control, Brake) and front.motor.counters["comm_timeouts"] == 1
    front.motor.inject_error(ma.ErrorFlags.LOW_VOLTAGE, 0.2)
    assert front.poll(0.2) == [] and front.counters["spontaneous_dropped"] == 1


def test_v43_id_setting_uses_0xcd_both_ways() -> None:
    front = _front(1, revision=ma.Revision.V4_3)
    motor_id, echo = _reply(front, encode_rs485(RS485_BROADCAST_ID, ma.SetCanId(motor_id=5)), 0.0)
    assert motor_id == RS485_BROADCAST_ID and echo == ma.Echo(command=ma.SetCanId(motor_id=5))
    front.motor.reboot(0.1)
    motor_id, read = _reply(front, encode_rs485(RS485_BROADCAST_ID, ma.ReadCanId()), 0.2)
    assert motor_id == RS485_BROADCAST_ID and read == ma.CanIdReply(motor_id=5, layout=ma.CanIdLayout.DATA7)
    assert front.receive_bytes(encode_rs485(1, ma.ReadStatus2()), 0.3) == []  # now id 5


# ---- 32 motors on a real pty line ----


def _line_session(path: str, baud: int) -> dict[str, Any]:
    """One host: a request to each motor in turn, a broadcast, and a corrupted frame."""
    found: dict[str, Any] = {}
    with serial.Serial(path, baud, timeout=2.0) as host:
        found["single"] = []
        for motor_id in range(1, 33):
            host.write(encode_rs485(motor_id, ma.ReadStatus2()))
            found["single"].append(decode_rs485_reply(host.read(13)))
        host.write(encode_rs485(RS485_BROADCAST_ID, ma.ReadMultiTurnAngle()))
        stream = host.read(32 * 13)
        found["broadcast"] = [decode_rs485_reply(stream[i : i + 13]) for i in range(0, len(stream), 13)]
        bad = bytearray(encode_rs485(5, ma.ReadStatus1()))
        bad[6] ^= 0xFF  # a data byte hit by noise: the CRC no longer matches
        host.write(bytes(bad))
        host.timeout = 0.2
        found["corrupt"] = host.read(13)
        host.timeout = 2.0
        host.write(encode_rs485(5, ma.ReadStatus1()))
        found["after"] = decode_rs485_reply(host.read(13))
    return found


@pytest.mark.asyncio
@pytest.mark.parametrize("baud", [115_200, 1_000_000])
async def test_thirty_two_rs485_motors_on_one_pty_line(baud: int) -> None:
    fronts = [_front(i) for i in range(1, 33)]
    port = PtyPort()
    async with serving(serve_rs485(fronts, port, baud=baud)):
        found = await asyncio.to_thread(_line_session, port.path, baud)
    port.close()
    assert [(i, type(r)) for i, r in found["single"]] == [(i, ma.StatusReply) for i in range(1, 33)]
    # §1.3: every motor answers the broadcast with its own id; the line serializes the replies.
    assert sorted(i for i, _ in found["broadcast"]) == list(range(1, 33))
    assert all(isinstance(r, ma.MultiTurnAngleReply) for _, r in found["broadcast"])
    assert found["corrupt"] == b""
    assert found["after"][0] == 5 and isinstance(found["after"][1], ma.Status1Reply)
    assert [f.counters["crc_errors"] for f in fronts] == [1] * 32  # every motor heard and dropped it
    assert all(f.motor.counters["replied"] == (3 if f.motor.motor_id == 5 else 2) for f in fronts)

"""The simulated 485 -> CANFD converter (servobus.protocols.hollow.sim.converter) against hollow.md §9.

Request bytes go in whole, byte by byte, and corrupted; replies are checked byte for byte against
the manual's examples where it prints them, and decoded with the family codec otherwise.
"""

from __future__ import annotations

import itertools
from typing import Any

import pytest

from _spec import hexbytes, load_vectors
from servobus.core import crc16_modbus
from servobus.frame import Frame
from servobus.protocols.hollow import (
    ControlMode,
    FdCommand,
    FdReply,
    ModbusException,
    ModbusFunction,
    ModbusRead,
    ModbusReadReply,
    ModbusWrite,
    ModbusWriteAck,
    TransparentReply,
    TransparentRequest,
)
from servobus.protocols.hollow.codec import request_frame
from servobus.protocols.hollow.rs485 import decode_modbus_reply, encode_transparent
from servobus.protocols.hollow.sim.converter import (
    DEFAULT_CONVERTER_TURNAROUND_S,
    ConverterMode,
    HollowConverter,
)
from servobus.protocols.hollow.sim.device import DEFAULT_TURNAROUND_S, HollowMotor
from servobus.sim.device import SerialEmission
from servobus.sim.plant import PlantParams
from servobus.timing import frame_time_s, uart_time_s

VECTORS = {v["id"]: v for v in load_vectors("hollow")}
H12, H13 = hexbytes(VECTORS["H12"]["data"]), hexbytes(VECTORS["H13"]["data_reconstructed"])
H14, H15, H16 = (hexbytes(VECTORS[k]["data"]) for k in ("H14", "H15", "H16"))
MODBUS_SILENCE_S = 3.5 * 10 / 19200  # 1.82 ms at 8N1 (§9.5)


def _manual_motor(**kwargs: Any) -> HollowMotor:
    """Motor 1 as in the manual's reply example [H13]/[H21]: 34 counts, 30 °C, stopped."""
    motor = HollowMotor(1, fd_enabled=True, plant_params=PlantParams(ambient_c=30.0), **kwargs)
    motor.plant.position_deg = 34 * 360.0 / (1 << 20)
    return motor


def _feed_bytewise(converter: HollowConverter, data: bytes, start_s: float) -> list[SerialEmission]:
    """One byte per character time, as on the wire; returns what the converter wrote."""
    out: list[SerialEmission] = []
    for i, byte in enumerate(data):
        out += converter.receive_bytes(bytes([byte]), start_s + (i + 1) * converter.char_time_s)
    return out


def _corrupt(frame: bytes) -> bytes:
    return frame[:-1] + bytes([frame[-1] ^ 0x01])


# ---- transparent mode (§9.4) ----


def test_transparent_request_h12_gets_the_manual_reply_h13_after_the_exchange() -> None:
    converter = HollowConverter([_manual_motor()])
    assert converter.baud == 1_000_000
    (emission,) = converter.receive_bytes(H12, 0.5)
    assert emission.data == H13
    # CAN side: the 16-byte request to id 1 and the reply on the host id, FD with BRS (A28).
    can_request = request_frame(1, FdCommand())
    can_reply = Frame(arbitration_id=0x64, data=H13[1:17], is_fd=True, bitrate_switch=True)
    expected = (
        0.5
        + DEFAULT_CONVERTER_TURNAROUND_S
        + frame_time_s(can_request, 1_000_000, 5_000_000)
        + DEFAULT_TURNAROUND_S
        + frame_time_s(can_reply, 1_000_000, 5_000_000)
    )
    assert emission.ready_s == pytest.approx(expected, abs=1e-12)


def test_transparent_request_fed_byte_by_byte_is_answered_on_its_last_byte() -> None:
    converter = HollowConverter([_manual_motor()])
    out = []
    for i, byte in enumerate(H12):
        now = i * 1e-5
        emissions = converter.receive_bytes(bytes([byte]), now)
        assert (emissions != []) == (i == len(H12) - 1)
        out += emissions
    assert [e.data for e in out] == [H13]
    assert out[0].ready_s > (len(H12) - 1) * 1e-5


def test_transparent_request_with_a_bad_crc_gets_nothing_and_is_counted() -> None:
    motor = _manual_motor()
    converter = HollowConverter([motor])
    assert converter.receive_bytes(_corrupt(H12), 0.0) == []
    assert _feed_bytewise(converter, _corrupt(H12), 0.01) == []
    assert converter.counters["crc_errors"] >= 1 and converter.counters["frames"] == 0
    assert motor.counters["received"] == 0  # nothing reached the CAN side
    # The de-framer resynchronises: the next good frame is answered.
    assert [e.data for e in converter.receive_bytes(H12, 0.02)] == [H13]


def test_transparent_forwards_the_payload_unchecked_and_the_motor_decides() -> None:
    motor = HollowMotor(1, fd_enabled=True)
    converter = HollowConverter([motor])
    bad_mode = bytes(11) + b"\x03" + bytes(4)  # Mode Sel 3 does not exist (§7.2)
    assert converter.receive_bytes(encode_transparent(1, bad_mode), 0.0) == []
    assert motor.counters["undecodable"] == 1
    assert converter.counters["motor_timeout"] == 1


def test_transparent_request_to_an_absent_or_unresponsive_motor_gets_nothing() -> None:
    motor = HollowMotor(1, fd_enabled=True)
    converter = HollowConverter([motor])
    assert converter.receive_bytes(TransparentRequest(motor_id=2).encode(), 0.0) == []
    assert converter.counters["no_motor"] == 1
    motor.unresponsive = True
    assert converter.receive_bytes(TransparentRequest(motor_id=1).encode(), 0.1) == []
    assert converter.counters["motor_timeout"] == 1


def test_transparent_replies_of_several_motors_do_not_overlap_on_the_half_duplex_line() -> None:
    motors = [HollowMotor(i, fd_enabled=True) for i in (1, 2, 3)]
    converter = HollowConverter(motors)
    burst = b"".join(
        TransparentRequest(motor_id=i, command=FdCommand(mode=ControlMode.VELOCITY)).encode()
        for i in (1, 2, 3)
    )
    out = converter.receive_bytes(burst, 0.0)
    replies = [TransparentReply.decode(e.data) for e in out]
    assert [r.motor_id for r in replies] == [1, 2, 3]
    assert all(r.reply.mode is ControlMode.VELOCITY and r.header_id == 0x64 for r in replies)
    frame_s = uart_time_s(21, 1_000_000)
    for earlier, later in itertools.pairwise(out):
        assert later.ready_s >= earlier.ready_s + frame_s - 1e-12


# ---- Modbus RTU mode (§9.5) ----


def test_modbus_write_h14_gets_the_manual_ack_h15_after_the_motor_replied() -> None:
    motor = _manual_motor()
    converter = HollowConverter([motor], mode=ConverterMode.MODBUS)
    assert converter.baud == 19_200
    assert converter.silence_s == pytest.approx(MODBUS_SILENCE_S)
    (ack,) = converter.receive_bytes(H14, 1.0)
    assert ack.data == H15
    assert ack.ready_s >= 1.0 + MODBUS_SILENCE_S  # the RTU inter-frame gap (§9.5)
    assert motor.counters["replied"] == 1  # forwarded to the motor first

    # 0x03 then returns that cached CAN FD reply: the same 16 bytes as [H21].
    (read,) = converter.receive_bytes(H16, 1.1)
    reply = decode_modbus_reply(read.data)
    assert isinstance(reply, ModbusReadReply) and len(read.data) == 37
    assert reply.reply.encode() == hexbytes(VECTORS["H21"]["data"])
    assert read.ready_s == pytest.approx(1.1 + MODBUS_SILENCE_S, abs=1e-12)
    assert motor.counters["replied"] == 1  # a read makes no CAN exchange


def test_modbus_read_before_any_write_returns_zeros() -> None:
    converter = HollowConverter([HollowMotor(1, fd_enabled=True)], mode=ConverterMode.MODBUS)
    (read,) = converter.receive_bytes(H16, 0.0)
    reply = decode_modbus_reply(read.data)
    assert isinstance(reply, ModbusReadReply) and reply.slave_id == 1
    assert reply.reply == FdReply(slave_id=0)  # §9.5 recommendation: zeros if nothing is cached


def test_modbus_write_moves_the_motor_it_addresses() -> None:
    motors = [HollowMotor(i, fd_enabled=True) for i in (4, 5)]
    converter = HollowConverter(motors, mode=ConverterMode.MODBUS)
    run = FdCommand(mode=ControlMode.VELOCITY, velocity_rpm=30.0, current_raw=2000, run=True)
    assert [e.data for e in converter.receive_bytes(ModbusWrite(slave_id=5, command=run).encode(), 0.0)] == [
        ModbusWriteAck(slave_id=5).encode()
    ]
    assert [e.data for e in converter.receive_bytes(ModbusWrite(slave_id=5, command=run).encode(), 1.0)] == [
        ModbusWriteAck(slave_id=5).encode()
    ]
    (read,) = converter.receive_bytes(ModbusRead(slave_id=5).encode(), 1.1)
    reply = decode_modbus_reply(read.data)
    assert isinstance(reply, ModbusReadReply)
    assert (reply.reply.slave_id, reply.reply.running) == (5, True)
    assert reply.reply.velocity_rpm == pytest.approx(30.0, rel=0.02)
    assert motors[0].counters["received"] == 0 and not motors[0].enabled


@pytest.mark.parametrize("frame", [H14, H16], ids=["write", "read"])
def test_modbus_requests_fed_byte_by_byte_and_corrupted(frame: bytes) -> None:
    converter = HollowConverter([_manual_motor()], mode=ConverterMode.MODBUS)
    whole = [e.data for e in converter.receive_bytes(frame, 0.0)]
    bytewise = [e.data for e in _feed_bytewise(converter, frame, 0.1)]
    assert whole == bytewise and len(whole) == 1
    assert _feed_bytewise(converter, _corrupt(frame), 0.2) == []
    assert converter.counters["crc_errors"] == 1
    # After 3.5 characters of silence the partial bytes are dropped and the next frame is clean.
    deadline = converter.next_deadline_s()
    if deadline is not None:
        assert converter.poll(deadline) == []
    assert converter.next_deadline_s() is None
    assert len(converter.receive_bytes(frame, 0.3)) == 1


def test_modbus_replies_to_a_burst_are_written_one_after_the_other() -> None:
    """Reads need no CAN exchange, so their replies are ready together; the line still sends one at
    a time (RS-485 is half duplex)."""
    motors = [HollowMotor(i, fd_enabled=True) for i in (1, 2)]
    converter = HollowConverter(motors, mode=ConverterMode.MODBUS)
    burst = ModbusRead(slave_id=1).encode() + ModbusRead(slave_id=2).encode()
    first, second = converter.receive_bytes(burst, 0.0)
    assert first.ready_s == pytest.approx(MODBUS_SILENCE_S)
    assert second.ready_s == pytest.approx(first.ready_s + uart_time_s(len(first.data), 19_200))
    assert [decode_modbus_reply(e.data).slave_id for e in (first, second)] == [1, 2]


def test_a_stray_byte_is_flushed_after_the_modbus_silence() -> None:
    converter = HollowConverter([HollowMotor(1, fd_enabled=True)], mode=ConverterMode.MODBUS)
    assert converter.receive_bytes(b"\x01", 0.0) == []
    assert converter.next_deadline_s() == pytest.approx(MODBUS_SILENCE_S)
    assert converter.poll(MODBUS_SILENCE_S / 2) == []  # not yet
    assert converter.poll(MODBUS_SILENCE_S) == []
    assert converter.next_deadline_s() is None
    assert converter.counters["discarded_bytes"] == 1
    assert len(converter.receive_bytes(H16, 0.01)) == 1


def _with_crc16(body: bytes) -> bytes:
    return body + crc16_modbus(body).to_bytes(2, "little")


def test_modbus_requests_outside_the_register_map_get_exceptions() -> None:
    converter = HollowConverter([HollowMotor(1, fd_enabled=True)], mode=ConverterMode.MODBUS)
    wrong_start = _with_crc16(bytes([1, 0x03, 0x00, 0x01, 0x00, 0x10]))
    (out,) = converter.receive_bytes(wrong_start, 0.0)
    assert ModbusException.decode(out.data) == ModbusException(
        slave_id=1, function=ModbusFunction.READ_HOLDING_REGISTERS, exception_code=0x02
    )
    high_byte = bytearray(H14[:-2])
    high_byte[7] = 0x01  # register 0's high byte must be 0x00 (§9.5)
    (out,) = converter.receive_bytes(_with_crc16(bytes(high_byte)), 0.1)
    assert ModbusException.decode(out.data) == ModbusException(
        slave_id=1, function=ModbusFunction.WRITE_MULTIPLE_REGISTERS, exception_code=0x03
    )
    assert converter.counters["exceptions"] == 2


def test_modbus_silence_for_absent_motors_broadcasts_and_unresponsive_motors() -> None:
    motor = HollowMotor(1, fd_enabled=True)
    converter = HollowConverter([motor], mode=ConverterMode.MODBUS)
    assert converter.receive_bytes(ModbusRead(slave_id=2).encode(), 0.0) == []
    broadcast = _with_crc16(bytes([0, 0x03, 0, 0, 0, 0x10]))
    assert converter.receive_bytes(broadcast, 0.1) == []
    motor.unresponsive = True
    assert converter.receive_bytes(H14, 0.2) == []  # the ack waits for a reply that never comes
    assert (converter.counters["no_motor"], converter.counters["broadcast"]) == (1, 1)
    assert converter.counters["motor_timeout"] == 1


def test_the_module_takes_only_can_fd_motors_with_distinct_ids() -> None:
    with pytest.raises(ValueError, match="classic"):
        HollowConverter([HollowMotor(1)])
    with pytest.raises(ValueError, match="already"):
        HollowConverter([HollowMotor(1, fd_enabled=True), HollowMotor(1, fd_enabled=True)])
    with pytest.raises(ValueError, match="host id"):
        HollowConverter([HollowMotor(1, fd_enabled=True, host_id=0x100)])

"""RS-485 converter framing: transparent CRC32 frames and Modbus RTU (hollow.md §9.4, §9.5), through the
C core's de-framers."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.core import HollowTransparentDeframer, ModbusRtuDeframer, crc16_modbus, crc32_ieee
from servobus.errors import ProtocolError
from servobus.protocols import Message
from servobus.protocols.hollow import (
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
from servobus.protocols.hollow.rs485 import (
    decode_modbus_reply,
    decode_modbus_request,
    decode_transparent,
    encode_transparent,
)

from .._contract import decodes_or_protocol_error
from ._strategies import fd_commands, fd_replies

motor_ids = st.integers(0, 100)
slave_ids = st.integers(1, 100)

transparent_requests = st.builds(TransparentRequest, motor_id=motor_ids, command=fd_commands())
transparent_replies = st.builds(TransparentReply, header_id=st.integers(0, 255), reply=fd_replies())
modbus_requests = st.one_of(
    st.builds(ModbusWrite, slave_id=slave_ids, command=fd_commands()),
    st.builds(ModbusRead, slave_id=slave_ids),
)
modbus_replies = st.one_of(
    st.builds(ModbusWriteAck, slave_id=slave_ids),
    st.builds(ModbusReadReply, slave_id=slave_ids, reply=fd_replies()),
    st.builds(
        ModbusException,
        slave_id=slave_ids,
        function=st.sampled_from(ModbusFunction),
        exception_code=st.integers(0, 255),
    ),
)


def _with_crc16(body: bytes) -> bytes:
    return body + crc16_modbus(body).to_bytes(2, "little")


def _with_crc32(body: bytes) -> bytes:
    return body + crc32_ieee(body).to_bytes(4, "little")


# ---- transparent ----


@given(transparent_requests)
def test_transparent_request_round_trip(request: TransparentRequest) -> None:
    frame = request.encode()
    assert len(frame) == 21 and frame[0] == request.motor_id
    assert frame[1:17] == request.command.encode()
    assert TransparentRequest.decode(frame, model=request.command.model) == TransparentRequest.decode(
        request.encode(), model=request.command.model
    )
    decoded = TransparentRequest.decode(frame, model=request.command.model)
    assert decoded.encode() == frame and decoded.motor_id == request.motor_id


@given(transparent_replies)
def test_transparent_reply_round_trip(reply: TransparentReply) -> None:
    frame = reply.encode()
    decoded = TransparentReply.decode(frame, model=reply.reply.model)
    assert decoded.encode() == frame
    assert (decoded.header_id, decoded.motor_id) == (reply.header_id, reply.reply.slave_id)


def test_transparent_framing_helpers() -> None:
    frame = encode_transparent(1, bytes(16))
    assert frame.hex(" ").upper().endswith("FE 3A 49 4E")
    assert decode_transparent(frame) == (1, bytes(16))
    with pytest.raises(ValueError, match="payload has 8 bytes, expected 16"):
        encode_transparent(1, bytes(8))
    with pytest.raises(ValueError, match=r"address=256 is outside \[0, 255\]"):
        encode_transparent(256, bytes(16))
    with pytest.raises(ProtocolError, match="CRC32 mismatch"):
        decode_transparent(frame[:-1] + b"\x00")
    with pytest.raises(ProtocolError, match="expected 21 data bytes, got 20"):
        decode_transparent(frame[:-1])
    with pytest.raises(ProtocolError, match=r"motor_id=101 is outside \[0, 100\]"):
        TransparentRequest.decode(encode_transparent(101, bytes(16)))


@given(st.lists(st.one_of(transparent_requests, transparent_replies), min_size=1, max_size=5))
def test_transparent_frames_fed_byte_by_byte_come_back(messages: list[Message]) -> None:
    frames = [m.encode() for m in messages]
    deframer = HollowTransparentDeframer()
    out: list[bytes] = []
    for byte in b"".join(frames):
        out += deframer.feed(bytes([byte]))
    out += deframer.idle()
    assert out == frames
    for message, frame in zip(messages, out, strict=True):
        kind = type(message)
        model = message.command.model if isinstance(message, TransparentRequest) else message.reply.model  # type: ignore[attr-defined]
        assert kind.decode(frame, model=model).encode() == frame  # type: ignore[attr-defined]


@given(st.binary(max_size=120), st.lists(transparent_replies, max_size=3), st.binary(max_size=30))
def test_random_transparent_streams_give_frames_or_protocol_errors(
    noise: bytes, replies: list[TransparentReply], tail: bytes
) -> None:
    deframer = HollowTransparentDeframer()
    frames = deframer.feed(noise + b"".join(r.encode() for r in replies) + tail) + deframer.idle()
    for frame in frames:
        decodes_or_protocol_error(TransparentReply.decode, frame)
        decodes_or_protocol_error(TransparentRequest.decode, frame)


@given(st.binary(min_size=17, max_size=17))
def test_transparent_bodies_with_a_valid_crc_decode_or_raise(body: bytes) -> None:
    frame = _with_crc32(body)
    assert decode_transparent(frame) == (body[0], body[1:])
    decodes_or_protocol_error(TransparentRequest.decode, frame)
    decodes_or_protocol_error(TransparentReply.decode, frame)


@given(st.binary(max_size=25))
def test_random_bytes_to_transparent_decoders(data: bytes) -> None:
    decodes_or_protocol_error(TransparentRequest.decode, data)
    decodes_or_protocol_error(TransparentReply.decode, data)


# ---- Modbus RTU ----


@given(modbus_requests)
def test_modbus_request_round_trip(request: ModbusWrite | ModbusRead) -> None:
    frame = request.encode()
    assert frame[:2] == bytes([request.slave_id, request.FUNCTION])
    model = request.command.model if isinstance(request, ModbusWrite) else None
    decoded = decode_modbus_request(frame, model=model) if model else decode_modbus_request(frame)
    assert decoded.encode() == frame
    if isinstance(request, ModbusWrite):
        assert len(frame) == 41 and frame[7:39:2] == bytes(16)  # high bytes 0x00
        assert frame[8:40:2] == request.command.encode()
    else:
        assert decoded == request and len(frame) == 8


@given(modbus_replies)
def test_modbus_reply_round_trip(reply: ModbusWriteAck | ModbusReadReply | ModbusException) -> None:
    frame = reply.encode()
    model = reply.reply.model if isinstance(reply, ModbusReadReply) else None
    decoded = decode_modbus_reply(frame, model=model) if model else decode_modbus_reply(frame)
    assert decoded.encode() == frame
    if isinstance(reply, ModbusReadReply):
        assert len(frame) == 37 and frame[4:36:2] == reply.reply.encode()
    else:
        assert decoded == reply


def test_modbus_exception_frame() -> None:
    frame = ModbusException(
        slave_id=1, function=ModbusFunction.READ_HOLDING_REGISTERS, exception_code=2
    ).encode()
    assert frame[:3] == bytes([0x01, 0x83, 0x02]) and len(frame) == 5
    with pytest.raises(ProtocolError, match="Modbus function: unknown value 4"):
        decode_modbus_reply(_with_crc16(bytes([1, 0x84, 2])))


def test_modbus_read_reply_ignores_register_high_bytes() -> None:
    # Replies are decoded leniently: the high byte of each register should be 0x00 and is ignored.
    good = ModbusReadReply(slave_id=1, reply=FdReply(slave_id=1, temperature_c=31)).encode()
    body = bytearray(good[:-2])
    body[3] = 0xAA
    decoded = decode_modbus_reply(_with_crc16(bytes(body)))
    assert decoded == decode_modbus_reply(good)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda b: b.__setitem__(7, 0x01), "high byte is not 0x00"),
        (lambda b: b.__setitem__(6, 0x1F), "byte count is not 32"),
        (lambda b: b.__setitem__(3, 0x01), "only registers 0x0000..0x000F"),
        (lambda b: b.__setitem__(5, 0x0F), "only registers 0x0000..0x000F"),
        (lambda b: b.__setitem__(0, 0x00), r"slave_id=0 is outside \[1, 100\]"),
        (lambda b: b.__setitem__(7 + 2 * 11 + 1, 0x07), "Mode Sel: unknown value 7"),  # register 11
    ],
)
def test_modbus_write_request_is_strict(mutate: object, message: str) -> None:
    body = bytearray(ModbusWrite(slave_id=1, command=FdCommand()).encode()[:-2])
    mutate(body)  # type: ignore[operator]
    with pytest.raises(ProtocolError, match=message):
        decode_modbus_request(_with_crc16(bytes(body)))


def test_modbus_crc_and_function_errors() -> None:
    frame = ModbusRead(slave_id=1).encode()
    with pytest.raises(ProtocolError, match="CRC16 mismatch"):
        decode_modbus_request(frame[:-1] + bytes([frame[-1] ^ 1]))
    with pytest.raises(ProtocolError, match="unsupported function"):
        decode_modbus_request(_with_crc16(bytes([1, 0x06, 0, 0, 0, 1])))
    with pytest.raises(ProtocolError, match="unsupported function"):
        decode_modbus_reply(_with_crc16(bytes([1, 0x06, 0, 0, 0, 1])))
    with pytest.raises(ProtocolError, match="too short"):
        decode_modbus_reply(b"\x01")
    with pytest.raises(ValueError, match=r"slave_id=0 is outside \[1, 100\]"):
        ModbusRead(slave_id=0)
    with pytest.raises(ValueError, match="is not an FdCommand"):
        ModbusWrite(slave_id=1, command=FdReply(slave_id=1))  # type: ignore[arg-type]


@given(st.lists(modbus_requests, min_size=1, max_size=4))
def test_modbus_requests_fed_byte_by_byte_come_back(requests: list[ModbusWrite | ModbusRead]) -> None:
    frames = [r.encode() for r in requests]
    deframer = ModbusRtuDeframer(direction="requests")
    out: list[bytes] = []
    for byte in b"".join(frames):
        out += deframer.feed(bytes([byte]))
    out += deframer.idle()
    assert out == frames
    for frame in out:
        decoded = decodes_or_protocol_error(decode_modbus_request, frame, model=_model_of(requests, frame))
        assert decoded is not None


def _model_of(requests: list[ModbusWrite | ModbusRead], frame: bytes):  # type: ignore[no-untyped-def]
    for request in requests:
        if isinstance(request, ModbusWrite) and request.encode() == frame:
            return request.command.model
    from servobus.protocols.hollow import DEFAULT_MODEL

    return DEFAULT_MODEL


@given(st.lists(modbus_replies, min_size=1, max_size=4))
def test_modbus_replies_fed_byte_by_byte_come_back(
    replies: list[ModbusWriteAck | ModbusReadReply | ModbusException],
) -> None:
    frames = [r.encode() for r in replies]
    deframer = ModbusRtuDeframer(direction="replies")
    out: list[bytes] = []
    for byte in b"".join(frames):
        out += deframer.feed(bytes([byte]))
    out += deframer.idle()
    assert out == frames
    for reply, frame in zip(replies, out, strict=True):
        model = reply.reply.model if isinstance(reply, ModbusReadReply) else None
        decoded = decode_modbus_reply(frame, model=model) if model else decode_modbus_reply(frame)
        assert decoded.encode() == frame


@given(
    st.sampled_from(["requests", "replies", "both"]),
    st.binary(max_size=120),
    st.lists(st.one_of(modbus_requests, modbus_replies), max_size=3),
)
def test_random_modbus_streams_give_frames_or_protocol_errors(
    direction: str, noise: bytes, messages: list[Message]
) -> None:
    deframer = ModbusRtuDeframer(direction=direction)  # type: ignore[arg-type]
    frames = deframer.feed(noise + b"".join(m.encode() for m in messages)) + deframer.idle()
    for frame in frames:
        decodes_or_protocol_error(decode_modbus_request, frame)
        decodes_or_protocol_error(decode_modbus_reply, frame)


@given(st.binary(max_size=45))
def test_random_bytes_to_modbus_decoders(data: bytes) -> None:
    decodes_or_protocol_error(decode_modbus_request, data)
    decodes_or_protocol_error(decode_modbus_reply, data)


@given(st.integers(0, 255), st.sampled_from([0x03, 0x10, 0x83, 0x90, 0x06]), st.binary(max_size=40))
def test_random_modbus_bodies_with_a_valid_crc_decode_or_raise(
    slave: int, function: int, rest: bytes
) -> None:
    frame = _with_crc16(bytes([slave, function]) + rest)
    decodes_or_protocol_error(decode_modbus_request, frame)
    decodes_or_protocol_error(decode_modbus_reply, frame)

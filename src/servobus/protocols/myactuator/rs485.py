"""MyActuator RS485 standard frames: ``3E ID 08 DATA[0..7] CRC16L CRC16H`` (myactuator-v4.md §1.2).

The 8 DATA bytes are the CAN payload unchanged, so every command and reply encodes through its own
``encode()``; this module adds the frame around it. CRC-16/MODBUS (C core, ``crc16_modbus``) over bytes
0..10, sent low byte first. The variant is **not verified against the manuals**, which print the CRC
symbolically; it is the MODBUS convention and what third-party code uses (§1.2, §9 item 1).

ID byte: a motor id 1..32, or :data:`RS485_BROADCAST_ID` (0xCD) for every motor; motors reply with
their own id (0x79 replies keep 0xCD, §4.38). A byte stream is cut into frames by
``servobus.core.MyActuatorRs485Deframer``; :func:`decode_rs485` checks one frame.

Not on RS485: 0xB6 active reply ("485 version does not support it", §4.36) and the CAN motion mode
(RS485 motion mode is its own frame, :mod:`.rs485_motion`).
"""

from __future__ import annotations

from servobus.core import MyActuatorRs485Deframer, crc16_modbus
from servobus.errors import ProtocolError
from servobus.protocols._message import Command, Message, Reply
from servobus.protocols.myactuator import commands as cmd
from servobus.protocols.myactuator._layout import PAYLOAD_SIZE, MyActuatorMessage
from servobus.protocols.myactuator.codec import (
    DEFAULT_REVISION,
    check_available,
    decode_standard_reply,
    decode_standard_request,
)
from servobus.protocols.myactuator.ids import ID_SETTING_CODE, MOTOR_IDS, RS485_BROADCAST_ID
from servobus.protocols.myactuator.motion import MotionCommand, MotionReply
from servobus.protocols.myactuator.revision import Revision

__all__ = [
    "RS485_BROADCAST_ID",
    "RS485_FRAME_SIZE",
    "RS485_HEADER",
    "decode_rs485",
    "decode_rs485_reply",
    "decode_rs485_request",
    "encode_rs485",
    "rs485_deframer",
]

RS485_HEADER = 0x3E
RS485_FRAME_SIZE = 3 + PAYLOAD_SIZE + 2


def _check_id_byte(motor_id: int) -> None:
    if isinstance(motor_id, bool) or not isinstance(motor_id, int):
        raise ValueError(f"motor_id={motor_id!r} is not an integer")
    if motor_id not in MOTOR_IDS and motor_id != RS485_BROADCAST_ID:
        raise ValueError(f"motor_id={motor_id!r} is outside [1, 32] and is not the broadcast 0xCD")


def encode_rs485(motor_id: int, payload: bytes | Message, *, revision: Revision | None = None) -> bytes:
    """The 13-byte RS485 frame carrying ``payload`` to (or from) ``motor_id``.

    Args:
        motor_id: 1..32, or 0xCD (broadcast; also the ID byte of every 0x79 frame).
        payload: a command or reply object, or its 8 data bytes as-is.
        revision: when given, a command the revision does not have is refused.

    Returns:
        ``3E ID 08 DATA[0..7] CRC16L CRC16H``.

    Raises:
        ValueError: bad id byte, payload not 8 bytes, a message with no RS485 form (0xB6, motion mode),
            0x79 to an id other than 0xCD, or a command ``revision`` does not have.
    """
    _check_id_byte(motor_id)
    if isinstance(payload, Message):
        if isinstance(payload, cmd.ActiveReply):
            raise ValueError("0xB6 active reply is CAN only: RS485 does not support it (§4.36)")
        if isinstance(payload, MotionCommand | MotionReply):
            raise ValueError("CAN motion mode has no RS485 standard frame; use rs485_motion")
        if isinstance(payload, cmd.SetCanId | cmd.ReadCanId) and motor_id != RS485_BROADCAST_ID:
            raise ValueError(f"0x79 is sent with ID byte 0xCD, not {motor_id} (§4.38)")
        if revision is not None and isinstance(payload, MyActuatorMessage):
            check_available(payload, revision)
        data = payload.encode()
    else:
        data = bytes(payload)
    if len(data) != PAYLOAD_SIZE:
        raise ValueError(f"payload has {len(data)} bytes; RS485 standard frames carry {PAYLOAD_SIZE}")
    body = bytes((RS485_HEADER, motor_id, PAYLOAD_SIZE)) + data
    return body + crc16_modbus(body).to_bytes(2, "little")


def decode_rs485(frame: bytes) -> tuple[int, bytes]:
    """Check one RS485 standard frame and split it.

    Returns:
        ``(id byte, DATA[0..7])``.

    Raises:
        ProtocolError: wrong size, header, length byte or CRC, or an id byte neither 1..32 nor 0xCD.
    """
    frame = bytes(frame)
    if len(frame) != RS485_FRAME_SIZE:
        raise ProtocolError(f"RS485 frame: expected {RS485_FRAME_SIZE} bytes, got {len(frame)}", raw=frame)
    if frame[0] != RS485_HEADER:
        raise ProtocolError(f"RS485 frame: header 0x{frame[0]:02X} is not 0x3E", raw=frame)
    if frame[2] != PAYLOAD_SIZE:
        raise ProtocolError(f"RS485 frame: length byte {frame[2]} is not {PAYLOAD_SIZE}", raw=frame)
    motor_id = frame[1]
    if motor_id not in MOTOR_IDS and motor_id != RS485_BROADCAST_ID:
        raise ProtocolError(f"RS485 frame: id byte 0x{motor_id:02X} is neither 1..32 nor 0xCD", raw=frame)
    crc = crc16_modbus(frame[:-2])
    if frame[-2:] != crc.to_bytes(2, "little"):
        expected = crc.to_bytes(2, "little").hex(" ").upper()
        raise ProtocolError(
            f"RS485 frame: CRC {frame[-2:].hex(' ').upper()} should be {expected}",
            raw=frame,
            motor_id=motor_id,
        )
    return motor_id, frame[3:-2]


def decode_rs485_request(frame: bytes, *, revision: Revision = DEFAULT_REVISION) -> tuple[int, Command]:
    """Decode an RS485 request frame (device side).

    Returns:
        ``(id byte, command)``; id byte 0xCD is a broadcast (or a 0x79 frame).

    Raises:
        ProtocolError: as :func:`decode_rs485`, or the data does not decode as a request of ``revision``
            (including 0x79 with an id byte other than 0xCD, and 0xB6, which RS485 does not have).
    """
    motor_id, data = decode_rs485(frame)
    if data[0] == cmd.ActiveReply.CODE:
        raise ProtocolError("0xB6 active reply is CAN only", raw=frame, motor_id=motor_id, command=data[0])
    message = decode_standard_request(data, revision, id_setting_allowed=motor_id == RS485_BROADCAST_ID)
    return motor_id, message


def decode_rs485_reply(frame: bytes, *, revision: Revision = DEFAULT_REVISION) -> tuple[int, Reply]:
    """Decode an RS485 reply frame (host side).

    Returns:
        ``(motor id, reply)``; 0x79 replies carry id byte 0xCD.

    Raises:
        ProtocolError: as :func:`decode_rs485`, id byte 0xCD on anything but 0x79 (motors reply with
            their own id), or the data does not decode as a reply of ``revision``.
    """
    motor_id, data = decode_rs485(frame)
    if motor_id == RS485_BROADCAST_ID and data[0] != ID_SETTING_CODE:
        raise ProtocolError("RS485 replies carry the motor's own id (0xCD only for 0x79)", raw=frame)
    return motor_id, decode_standard_reply(data, revision)


def rs485_deframer() -> MyActuatorRs485Deframer:
    """A stream de-framer for this protocol's RS485 standard frames (DATA length fixed at 8)."""
    return MyActuatorRs485Deframer(max_data_len=PAYLOAD_SIZE)

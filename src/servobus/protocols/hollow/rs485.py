"""RS-485 framing of the 485 -> CANFD converter (hollow.md §9.4, §9.5) and the hollow encoder (§12).

Both modes carry the 16 CAN FD bytes of §7.2/§7.3, so their typed frames wrap
:class:`~servobus.protocols.hollow.commands_fd.FdCommand` and
:class:`~servobus.protocols.hollow.replies.FdReply`. ``encode()`` returns the whole serial frame.

* **Transparent** (1 Mbaud): ``ID | 16 bytes | CRC-32/ISO-HDLC over the first 17, LSB first``, 21
  bytes, no header. A request's ID is the target motor; a reply's is the CAN id it was received on
  (the host id, 0x64) - the motor is named by the payload's Slave ID byte.
* **Modbus RTU** (19200 baud): function 0x10 writes and 0x03 reads holding registers
  0x0000..0x000F, one CAN FD byte in the low byte of each (high byte 0x00), CRC-16/MODBUS low byte
  first. Only full 16-register transfers from 0x0000 exist in the manual; anything else is refused.

Byte streams are cut into frames by :class:`servobus.core.HollowTransparentDeframer` and
:class:`servobus.core.ModbusRtuDeframer` (which check the CRCs); the decoders here check them again,
so they also take frames from anywhere else.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, ClassVar, Self

from servobus.core import crc16_modbus, crc32_ieee
from servobus.errors import ProtocolError
from servobus.protocols._message import Command, Message, Reply
from servobus.protocols.hollow._checks import build, check_int, decode_enum, require_size, to_enum
from servobus.protocols.hollow._packed import OnLinks
from servobus.protocols.hollow.commands_fd import FD_PAYLOAD_SIZE, FdCommand
from servobus.protocols.hollow.ids import DEFAULT_HOST_ID, check_modbus_slave_id, check_motor_id
from servobus.protocols.hollow.model import DEFAULT_MODEL, HollowModel
from servobus.protocols.hollow.replies import FdReply

__all__ = [
    "MODBUS_REGISTER_COUNT",
    "MODBUS_REGISTER_START",
    "TRANSPARENT_FRAME_SIZE",
    "ModbusException",
    "ModbusFunction",
    "ModbusRead",
    "ModbusReadReply",
    "ModbusWrite",
    "ModbusWriteAck",
    "TransparentReply",
    "TransparentRequest",
    "decode_modbus_reply",
    "decode_modbus_request",
    "decode_transparent",
    "encode_transparent",
]

TRANSPARENT_FRAME_SIZE = 21  # §9.4: ID + 16 + CRC32
_TRANSPARENT_CRC_SPAN = 1 + FD_PAYLOAD_SIZE

MODBUS_REGISTER_START = 0x0000  # §9.5: holding registers 40001..40016
MODBUS_REGISTER_COUNT = 16
_MODBUS_BYTE_COUNT = 2 * MODBUS_REGISTER_COUNT
_EXCEPTION_SIZE = 5
_EXCEPTION_BIT = 0x80


class ModbusFunction(IntEnum):
    """The only two function codes the converter supports (§9.5)."""

    READ_HOLDING_REGISTERS = 0x03
    WRITE_MULTIPLE_REGISTERS = 0x10


# ---- transparent mode (§9.4) ----


def encode_transparent(address: int, payload: bytes) -> bytes:
    """One transparent frame: ``address | payload | CRC32 LSB first``.

    Args:
        address: byte 0: the target motor id (request) or the CAN id of a forwarded reply.
        payload: the 16 CAN FD bytes.

    Raises:
        ValueError: ``address`` outside 0..255 or ``payload`` not 16 bytes.
    """
    check_int("address", address, 0, 0xFF)
    if len(payload) != FD_PAYLOAD_SIZE:
        raise ValueError(f"payload has {len(payload)} bytes, expected {FD_PAYLOAD_SIZE}")
    body = bytes([address]) + bytes(payload)
    return body + crc32_ieee(body).to_bytes(4, "little")


def decode_transparent(frame: bytes) -> tuple[int, bytes]:
    """Split a transparent frame into (address byte, 16 payload bytes) after checking its CRC32.

    Raises:
        ProtocolError: not 21 bytes, or the CRC does not match.
    """
    require_size(frame, TRANSPARENT_FRAME_SIZE, what="transparent frame")
    body = frame[:_TRANSPARENT_CRC_SPAN]
    if crc32_ieee(body).to_bytes(4, "little") != frame[_TRANSPARENT_CRC_SPAN:]:
        raise ProtocolError("transparent frame: CRC32 mismatch", raw=frame)
    return frame[0], bytes(frame[1:_TRANSPARENT_CRC_SPAN])


class _Carrier(Message):
    """A serial frame around the 16 CAN FD bytes of the message in its attribute ``CARRIES``.

    ``ADDRESS`` names the attribute of the address byte, :meth:`check_address` checks it; the carried
    message must be a ``CARRIED`` (its class decodes the 16 bytes with the model's scales).
    """

    __slots__ = ()
    ADDRESS: ClassVar[str]
    CARRIES: ClassVar[str]
    CARRIED: ClassVar[type[FdCommand] | type[FdReply]]

    @staticmethod
    def check_address(value: Any) -> object:
        """Raise ValueError unless ``value`` is a valid address byte of this frame."""
        raise NotImplementedError

    def __post_init__(self) -> None:
        self.check_address(getattr(self, self.ADDRESS))
        carried = getattr(self, self.CARRIES)
        if not isinstance(carried, self.CARRIED):
            raise ValueError(f"{self.CARRIES}={carried!r} is not an {self.CARRIED.__name__}")

    def carried_bytes(self) -> bytes:
        """The 16 CAN FD bytes carried."""
        payload: bytes = getattr(self, self.CARRIES).encode()
        return payload


class _Transparent(_Carrier):
    """A transparent frame (§9.4): ``address | 16 bytes | CRC32``."""

    __slots__ = ()

    def encode(self) -> bytes:
        return encode_transparent(getattr(self, self.ADDRESS), self.carried_bytes())

    @classmethod
    def decode(cls, frame: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode a 21-byte transparent frame.

        Raises:
            ProtocolError: length, CRC, an address outside the class's range, or 16 bytes that are
                not a valid CAN FD message.
        """
        address, payload = decode_transparent(frame)
        carried = cls.CARRIED.decode(payload, model=model)
        return build(cls, frame, **{cls.ADDRESS: address, cls.CARRIES: carried})


@dataclass(frozen=True, slots=True, kw_only=True)
class TransparentReply(_Transparent, Reply):
    """A CAN FD reply forwarded by the converter in transparent mode [H13], or the hollow encoder's
    answer [H19].

    Attributes:
        header_id: byte 0, the CAN id the reply came on: the host id (0x64) for motors; the
            encoder puts its own id there (A24). 0..255.
        reply: the 16-byte CAN FD reply; its ``slave_id`` names the motor.
    """

    ADDRESS: ClassVar[str] = "header_id"
    CARRIES: ClassVar[str] = "reply"
    CARRIED: ClassVar[type[FdReply]] = FdReply
    header_id: int = DEFAULT_HOST_ID
    reply: FdReply

    @staticmethod
    def check_address(value: Any) -> object:
        check_int("header_id", value, 0, 0xFF)
        return value

    @property
    def motor_id(self) -> int:
        """The motor that sent the reply (the CAN FD Slave ID byte)."""
        return self.reply.slave_id


@dataclass(frozen=True, slots=True, kw_only=True)
class TransparentRequest(_Transparent, OnLinks, Command[TransparentReply]):
    """A CAN FD request to one motor through the converter in transparent mode [H12].

    A whole serial frame: the bound codec's ``rs485`` link sends the :class:`FdCommand` itself and
    adds this framing, so this class travels on no link of its own (``LINKS`` empty).

    Attributes:
        motor_id: the target motor's CAN id (byte 0), 0..100.
        command: the 16-byte CAN FD request (default: the all-zero poll).
    """

    ADDRESS: ClassVar[str] = "motor_id"
    CARRIES: ClassVar[str] = "command"
    CARRIED: ClassVar[type[FdCommand]] = FdCommand

    @staticmethod
    def check_address(value: Any) -> object:
        return check_motor_id(value)

    motor_id: int
    command: FdCommand = field(default_factory=FdCommand)


# ---- Modbus RTU mode (§9.5) ----


def _with_crc16(body: bytes) -> bytes:
    return body + crc16_modbus(body).to_bytes(2, "little")


def _checked_body(frame: bytes, what: str) -> bytes:
    if len(frame) < 4:
        raise ProtocolError(f"{what}: {len(frame)} bytes is too short for a Modbus RTU frame", raw=frame)
    body = frame[:-2]
    if crc16_modbus(body).to_bytes(2, "little") != frame[-2:]:
        raise ProtocolError(f"{what}: CRC16 mismatch", raw=frame, motor_id=frame[0])
    return bytes(body)


_REGISTER_RANGE = MODBUS_REGISTER_START.to_bytes(2, "big") + MODBUS_REGISTER_COUNT.to_bytes(
    2, "big"
)  # start 0x0000, quantity 0x0010


def _registers(payload: bytes) -> bytes:
    return b"".join(bytes([0x00, b]) for b in payload)


class _Modbus(Message):
    """A Modbus RTU frame of the converter: ``slave_id | FUNCTION | ... | CRC-16`` (§9.5).

    ``HEAD`` is what follows the function code: the register range (requests and the write's
    acknowledgement) and/or the byte count; a class that carries CAN FD bytes (``CARRIES``) adds them
    one per register, high byte 0x00. ``WHAT`` names the frame in errors; ``STRICT`` refuses a
    register whose high byte is not 0x00 (requests; replies are decoded leniently).
    """

    __slots__ = ()
    FUNCTION: ClassVar[ModbusFunction]
    HEAD: ClassVar[bytes]
    WHAT: ClassVar[str]
    STRICT: ClassVar[bool] = True
    ADDRESS: ClassVar[str] = "slave_id"

    @staticmethod
    def check_address(value: Any) -> object:
        return check_modbus_slave_id(value)

    def encode(self) -> bytes:
        head = bytes([getattr(self, self.ADDRESS), self.FUNCTION]) + self.HEAD
        if isinstance(self, _Carrier):
            head += _registers(self.carried_bytes())
        return _with_crc16(head)

    @classmethod
    def decode(cls, frame: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode one whole frame of this class (CRC included).

        Raises:
            ProtocolError: length, CRC, function, register range, byte count, slave address, a
                register's high byte (requests), or carried bytes that are not a valid CAN FD message.
        """
        carried = issubclass(cls, _Carrier)
        count = len(cls.HEAD) + (_MODBUS_BYTE_COUNT if carried else 0)
        require_size(frame, 4 + count, what=cls.WHAT)
        body = _checked_body(frame, cls.WHAT)
        _require_function(body, cls.FUNCTION)
        head = body[2 : 2 + len(cls.HEAD)]
        if len(cls.HEAD) >= len(_REGISTER_RANGE) and head[:4] != _REGISTER_RANGE:
            raise ProtocolError(
                f"{cls.WHAT}: only registers 0x0000..0x000F as one transfer are supported",
                raw=body,
                motor_id=body[0],
            )
        if head != cls.HEAD:
            raise ProtocolError(f"{cls.WHAT}: byte count is not 32", raw=frame, motor_id=body[0])
        values: dict[str, Any] = {cls.ADDRESS: body[0]}
        if issubclass(cls, _Carrier):
            registers = body[2 + len(cls.HEAD) :]
            if cls.STRICT and any(registers[0::2]):
                raise ProtocolError(f"{cls.WHAT}: a register's high byte is not 0x00", raw=frame)
            values[cls.CARRIES] = cls.CARRIED.decode(registers[1::2], model=model)
        return build(cls, frame, **values)


class _ModbusCarrier(_Modbus, _Carrier):
    """A Modbus frame that carries the 16 CAN FD bytes in its registers."""

    __slots__ = ()

    def __post_init__(self) -> None:
        _Carrier.__post_init__(self)


class _ModbusShort(_Modbus):
    """A Modbus frame of address, function and head only."""

    __slots__ = ()

    def __post_init__(self) -> None:
        self.check_address(getattr(self, self.ADDRESS))


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusWriteAck(_ModbusShort, Reply):
    """The 0x10 response: slave, function, start 0x0000, quantity 16, CRC [H15].

    Attributes:
        slave_id: the answering address, 1..100.
    """

    FUNCTION: ClassVar[ModbusFunction] = ModbusFunction.WRITE_MULTIPLE_REGISTERS
    HEAD: ClassVar[bytes] = _REGISTER_RANGE
    WHAT: ClassVar[str] = "Modbus write response"
    slave_id: int


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusReadReply(_ModbusCarrier, Reply):
    """The 0x03 response: the 16 CAN FD reply bytes, one per register (§9.5; layout of [H17]).

    Decoding ignores the registers' high bytes (they should be 0x00; lenient, as for every reply).

    Attributes:
        slave_id: the answering address, 1..100.
        reply: the CAN FD reply.
    """

    FUNCTION: ClassVar[ModbusFunction] = ModbusFunction.READ_HOLDING_REGISTERS
    HEAD: ClassVar[bytes] = bytes([_MODBUS_BYTE_COUNT])
    WHAT: ClassVar[str] = "Modbus read response"
    STRICT: ClassVar[bool] = False
    CARRIES: ClassVar[str] = "reply"
    CARRIED: ClassVar[type[FdReply]] = FdReply
    slave_id: int
    reply: FdReply


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusException(Reply):
    """A Modbus exception response: ``slave, function | 0x80, code, CRC``.

    The manual describes none (§9.5 [I]); a simulator answers unsupported requests with one, and a
    host decodes it rather than failing on the bytes.

    Attributes:
        slave_id: the answering address, 1..100.
        function: the function that failed.
        exception_code: the Modbus exception code (1 illegal function, 2 illegal data address, 3
            illegal data value, 4 device failure, ...); any byte is kept.
    """

    slave_id: int
    function: ModbusFunction
    exception_code: int

    def __post_init__(self) -> None:
        check_modbus_slave_id(self.slave_id)
        object.__setattr__(self, "function", to_enum("function", self.function, ModbusFunction))
        check_int("exception_code", self.exception_code, 0, 0xFF)

    def encode(self) -> bytes:
        return _with_crc16(bytes([self.slave_id, self.function | _EXCEPTION_BIT, self.exception_code]))

    @classmethod
    def decode(cls, frame: bytes) -> Self:
        """Decode a 5-byte exception response.

        Raises:
            ProtocolError: length, CRC, a function without the exception bit or unknown, or the
                slave address.
        """
        require_size(frame, _EXCEPTION_SIZE, what="Modbus exception response")
        body = _checked_body(frame, "Modbus exception response")
        if not body[1] & _EXCEPTION_BIT:
            raise ProtocolError("Modbus exception response: function lacks 0x80", raw=frame)
        function = decode_enum("Modbus function", body[1] & ~_EXCEPTION_BIT, ModbusFunction, frame)
        return build(cls, frame, slave_id=body[0], function=function, exception_code=body[2])


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusWrite(_ModbusCarrier, OnLinks, Command[ModbusWriteAck | ModbusException]):
    """Function 0x10: write the 16 CAN FD request bytes to registers 0x0000..0x000F [H14].

    Acknowledged once the motor has answered; a request the converter refuses gets an exception.

    Attributes:
        slave_id: the Modbus address = motor CAN id, 1..100.
        command: the CAN FD request.
    """

    LINKS: ClassVar[tuple[str, ...]] = ("modbus",)
    FUNCTION: ClassVar[ModbusFunction] = ModbusFunction.WRITE_MULTIPLE_REGISTERS
    HEAD: ClassVar[bytes] = _REGISTER_RANGE + bytes([_MODBUS_BYTE_COUNT])
    WHAT: ClassVar[str] = "Modbus write request"
    CARRIES: ClassVar[str] = "command"
    CARRIED: ClassVar[type[FdCommand]] = FdCommand
    slave_id: int
    command: FdCommand = field(default_factory=FdCommand)


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusRead(_ModbusShort, OnLinks, Command[ModbusReadReply | ModbusException]):
    """Function 0x03: read the 16 CAN FD reply bytes from registers 0x0000..0x000F [H16].

    It changes nothing (the converter answers from its cache, §9.5), so it may be resent.

    Attributes:
        slave_id: the Modbus address = motor CAN id, 1..100.
    """

    READ: ClassVar[bool] = True
    LINKS: ClassVar[tuple[str, ...]] = ("modbus",)
    FUNCTION: ClassVar[ModbusFunction] = ModbusFunction.READ_HOLDING_REGISTERS
    HEAD: ClassVar[bytes] = _REGISTER_RANGE
    WHAT: ClassVar[str] = "Modbus read request"
    slave_id: int


def _require_function(body: bytes, function: ModbusFunction) -> None:
    if body[1] != function:
        raise ProtocolError(
            f"expected Modbus function 0x{function:02X}, got 0x{body[1]:02X}",
            raw=body,
            motor_id=body[0],
            command=body[1],
        )


def decode_modbus_request(frame: bytes, *, model: HollowModel = DEFAULT_MODEL) -> ModbusWrite | ModbusRead:
    """Decode a Modbus RTU request frame (device side) by its function code.

    Raises:
        ProtocolError: fewer than 2 bytes, an unsupported function, or the frame's own decoder
            refuses it.
    """
    if len(frame) < 2:
        raise ProtocolError(f"Modbus request: {len(frame)} bytes is too short", raw=frame)
    if frame[1] == ModbusFunction.WRITE_MULTIPLE_REGISTERS:
        return ModbusWrite.decode(frame, model=model)
    if frame[1] == ModbusFunction.READ_HOLDING_REGISTERS:
        return ModbusRead.decode(frame)
    raise ProtocolError(
        "Modbus request: unsupported function", raw=frame, motor_id=frame[0], command=frame[1]
    )


def decode_modbus_reply(
    frame: bytes, *, model: HollowModel = DEFAULT_MODEL
) -> ModbusWriteAck | ModbusReadReply | ModbusException:
    """Decode a Modbus RTU reply frame (host side) by its function code.

    Raises:
        ProtocolError: fewer than 2 bytes, an unsupported function, or the frame's own decoder
            refuses it.
    """
    if len(frame) < 2:
        raise ProtocolError(f"Modbus reply: {len(frame)} bytes is too short", raw=frame)
    if frame[1] == ModbusFunction.WRITE_MULTIPLE_REGISTERS:
        return ModbusWriteAck.decode(frame)
    if frame[1] == ModbusFunction.READ_HOLDING_REGISTERS:
        return ModbusReadReply.decode(frame, model=model)
    if frame[1] & _EXCEPTION_BIT:
        return ModbusException.decode(frame)
    raise ProtocolError("Modbus reply: unsupported function", raw=frame, motor_id=frame[0], command=frame[1])

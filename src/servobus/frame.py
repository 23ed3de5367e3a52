"""Frame: the one type that crosses layers (codecs, scheduler, transports, simulator).

Transports convert to and from python-can's ``Message`` or serial bytes at their edge only.
:meth:`Frame.from_message` reads a ``can.Message``'s attributes (no import of python-can); the
other way, :func:`servobus.transports.can.message_from_frame` builds one at python-can's edge (the
frame layer imports no other servobus layer and no I/O library).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol


class CanMessage(Protocol):
    """What :meth:`Frame.from_message` reads of a python-can ``can.Message`` (the frame layer is
    sans-IO: it never imports python-can)."""

    @property
    def arbitration_id(self) -> int: ...

    @property
    def data(self) -> bytes | bytearray: ...

    @property
    def dlc(self) -> int: ...

    @property
    def is_extended_id(self) -> bool: ...

    @property
    def is_remote_frame(self) -> bool: ...

    @property
    def is_error_frame(self) -> bool: ...

    @property
    def is_fd(self) -> bool: ...

    @property
    def bitrate_switch(self) -> bool: ...

    @property
    def error_state_indicator(self) -> bool: ...

    @property
    def is_rx(self) -> bool: ...

    @property
    def timestamp(self) -> float: ...


__all__ = ["Frame", "classic_request"]

_CLASSIC_MAX = 8
_SERIAL_MAX = 255
_FD_SIZES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


@dataclass(frozen=True, slots=True, kw_only=True, init=False)
class Frame:
    """A CAN or CAN FD frame, or one serial-link message.

    A serial message (``is_serial``) is what a family's framing cuts out of an RS-485 byte stream:
    ``arbitration_id`` is its address byte (0..255) and ``data`` its body, up to 255 bytes, without the
    header, length and CRC the framing adds on the wire. It never goes to a CAN adapter.

    Equality ignores ``timestamp`` and ``is_rx``, so a frame from the simulator compares equal to
    the frame a test expects.

    ``error_state_indicator`` is CAN FD's ESI bit as an adapter reports it (the sender is error
    passive); like ``timestamp`` and ``is_rx`` it is not part of equality.

    ``is_rx`` follows python-can's ``Message.is_rx``: False marks our own transmitted frame coming
    back from an adapter that loops sent frames back. It matters where a reply uses the request's
    own identifier (LK V2.35: request and echo reply both on 0x140+ID), so our own request is never
    taken for the motor's reply.

    Raises:
        ValueError: identifier out of range for its format, or data too long for the frame type.
    """

    arbitration_id: int
    data: bytes = b""
    is_extended_id: bool = False
    is_fd: bool = False
    bitrate_switch: bool = False
    is_serial: bool = False
    timestamp: float = field(default=0.0, compare=False)
    is_rx: bool = field(default=True, compare=False)
    error_state_indicator: bool = field(default=False, compare=False)

    # Every encoded and every received frame is built here, so __init__ is written out: the checks
    # in one pass and the slots set through their descriptors (a frozen dataclass's generated
    # __init__ goes through object.__setattr__ per field, twice as slow).
    def __init__(
        self,
        *,
        arbitration_id: int,
        data: bytes = b"",
        is_extended_id: bool = False,
        is_fd: bool = False,
        bitrate_switch: bool = False,
        is_serial: bool = False,
        timestamp: float = 0.0,
        is_rx: bool = True,
        error_state_indicator: bool = False,
    ) -> None:
        if type(data) is not bytes:
            data = bytes(data)
        if is_serial:
            _check_serial(arbitration_id, data, is_extended_id or is_fd or bitrate_switch)
        else:
            if not 0 <= arbitration_id <= (0x1FFFFFFF if is_extended_id else 0x7FF):
                limit = 0x1FFFFFFF if is_extended_id else 0x7FF
                kind = "extended" if is_extended_id else "standard"
                raise ValueError(
                    f"arbitration_id=0x{arbitration_id:X} outside the {kind} range 0..0x{limit:X}"
                )
            if is_fd:
                if len(data) not in _FD_SIZES:
                    raise ValueError(f"CAN FD data length {len(data)} is not one of {_FD_SIZES}")
            elif len(data) > _CLASSIC_MAX:
                raise ValueError(f"classic CAN data length {len(data)} exceeds 8 bytes")
            elif bitrate_switch:
                raise ValueError("bitrate_switch needs is_fd")
            elif error_state_indicator:
                raise ValueError("error_state_indicator needs is_fd")
        _SET_ID(self, arbitration_id)
        _SET_DATA(self, data)
        _SET_EXTENDED(self, bool(is_extended_id))
        _SET_FD(self, bool(is_fd))
        _SET_BRS(self, bool(bitrate_switch))
        _SET_SERIAL(self, bool(is_serial))
        _SET_TIMESTAMP(self, timestamp)
        _SET_RX(self, bool(is_rx))
        _SET_ESI(self, bool(error_state_indicator))

    @classmethod
    def from_message(cls, message: CanMessage, timestamp: float | None = None) -> Frame:
        """A python-can ``can.Message`` as a Frame: identifier, extended, FD, BRS, ESI, data,
        ``is_rx`` and the timestamp (the message's own unless ``timestamp`` is given).

        Raises:
            ValueError: a remote or error frame (a Frame is neither), a DLC that disagrees with the
                data (python-can's slcan reader builds such messages from short lines), or an
                identifier or length out of range.
        """
        if message.is_remote_frame or message.is_error_frame:
            kind = "remote" if message.is_remote_frame else "error"
            raise ValueError(f"a {kind} frame (id 0x{message.arbitration_id:X}) is not a Frame")
        if message.dlc != len(message.data):
            raise ValueError(f"DLC {message.dlc} but {len(message.data)} data bytes")
        return cls(
            arbitration_id=message.arbitration_id,
            data=bytes(message.data),
            is_extended_id=message.is_extended_id,
            is_fd=message.is_fd,
            bitrate_switch=message.bitrate_switch,
            timestamp=message.timestamp if timestamp is None else timestamp,
            is_rx=message.is_rx,
            error_state_indicator=message.error_state_indicator,
        )

    def __repr__(self) -> str:
        width = 8 if self.is_extended_id else 3
        kinds = (("x", self.is_extended_id), ("f", self.is_fd), ("s", self.is_serial))
        flags = "".join(f for f, on in kinds if on)
        return (
            f"Frame(0x{self.arbitration_id:0{width}X}{flags and ' ' + flags} [{self.data.hex(' ').upper()}])"
        )


_SET_ID = Frame.arbitration_id.__set__  # type: ignore[attr-defined,misc]
_SET_DATA = Frame.data.__set__  # type: ignore[attr-defined,misc]
_SET_EXTENDED = Frame.is_extended_id.__set__  # type: ignore[attr-defined,misc]
_SET_FD = Frame.is_fd.__set__  # type: ignore[attr-defined,misc]
_SET_BRS = Frame.bitrate_switch.__set__  # type: ignore[attr-defined,misc]
_SET_SERIAL = Frame.is_serial.__set__  # type: ignore[attr-defined,misc]
_SET_TIMESTAMP = Frame.timestamp.__set__  # type: ignore[attr-defined,misc]
_SET_RX = Frame.is_rx.__set__  # type: ignore[attr-defined,misc]
_SET_ESI = Frame.error_state_indicator.__set__  # type: ignore[attr-defined,misc]


_NEW = object.__new__


def classic_request(arbitration_id: int, data: bytes) -> Frame:
    """A classic 11-bit frame to send, as a codec's hot path builds it: the codec made the identifier
    and the (at most 8) data bytes valid, so they are not checked again (``Frame()`` checks: twice
    the cost, on every request)."""
    frame: Frame = _NEW(Frame)
    _SET_ID(frame, arbitration_id)
    _SET_DATA(frame, data)
    _SET_EXTENDED(frame, False)
    _SET_FD(frame, False)
    _SET_BRS(frame, False)
    _SET_SERIAL(frame, False)
    _SET_TIMESTAMP(frame, 0.0)
    _SET_RX(frame, False)
    _SET_ESI(frame, False)
    return frame


def _check_serial(address: int, data: bytes, can_flags: bool) -> None:
    if not 0 <= address <= 0xFF:
        raise ValueError(f"arbitration_id=0x{address:X}: a serial message's address is one byte (0..0xFF)")
    if len(data) > _SERIAL_MAX:
        raise ValueError(f"serial message body of {len(data)} bytes exceeds {_SERIAL_MAX}")
    if can_flags:
        raise ValueError("a serial message has no extended id, FD or bit-rate-switch flag")

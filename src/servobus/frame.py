"""Frame: the one type that crosses layers (codecs, scheduler, transports, simulator).

Transports convert to and from python-can's ``Message`` or serial bytes at their edge only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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
        _SET_ID(self, arbitration_id)
        _SET_DATA(self, data)
        _SET_EXTENDED(self, bool(is_extended_id))
        _SET_FD(self, bool(is_fd))
        _SET_BRS(self, bool(bitrate_switch))
        _SET_SERIAL(self, bool(is_serial))
        _SET_TIMESTAMP(self, timestamp)
        _SET_RX(self, bool(is_rx))

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
    return frame


def _check_serial(address: int, data: bytes, can_flags: bool) -> None:
    if not 0 <= address <= 0xFF:
        raise ValueError(f"arbitration_id=0x{address:X}: a serial message's address is one byte (0..0xFF)")
    if len(data) > _SERIAL_MAX:
        raise ValueError(f"serial message body of {len(data)} bytes exceeds {_SERIAL_MAX}")
    if can_flags:
        raise ValueError("a serial message has no extended id, FD or bit-rate-switch flag")

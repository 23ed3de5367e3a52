"""Frame: the one type that crosses layers (codecs, scheduler, transports, simulator).

Transports convert to and from python-can's ``Message`` or serial bytes at their edge only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Frame"]

_CLASSIC_MAX = 8
_FD_SIZES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


@dataclass(frozen=True, slots=True, kw_only=True)
class Frame:
    """A CAN or CAN FD frame (or one serial frame addressed by ``arbitration_id``).

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
    timestamp: float = field(default=0.0, compare=False)
    is_rx: bool = field(default=True, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.data, bytes):
            object.__setattr__(self, "data", bytes(self.data))
        limit = 0x1FFFFFFF if self.is_extended_id else 0x7FF
        if not 0 <= self.arbitration_id <= limit:
            kind = "extended" if self.is_extended_id else "standard"
            raise ValueError(
                f"arbitration_id=0x{self.arbitration_id:X} outside the {kind} range 0..0x{limit:X}"
            )
        if self.is_fd:
            if len(self.data) not in _FD_SIZES:
                raise ValueError(f"CAN FD data length {len(self.data)} is not one of {_FD_SIZES}")
        elif len(self.data) > _CLASSIC_MAX:
            raise ValueError(f"classic CAN data length {len(self.data)} exceeds 8 bytes")
        if self.bitrate_switch and not self.is_fd:
            raise ValueError("bitrate_switch needs is_fd")

    def __repr__(self) -> str:
        width = 8 if self.is_extended_id else 3
        flags = "".join(f for f, on in (("x", self.is_extended_id), ("f", self.is_fd)) if on)
        return (
            f"Frame(0x{self.arbitration_id:0{width}X}{flags and ' ' + flags} [{self.data.hex(' ').upper()}])"
        )

"""What a simulated device is to the rest of the simulator: frames in, timed frames out.

Sans-IO, like the codecs the devices are built on: a device never reads a clock or sleeps. The
network (virtual clock) or an attachment (real clock) passes ``now_s`` in and schedules what comes
back. A device answers a request with frames stamped with the time they are ready to leave (its
turnaround), and may also produce frames on its own (active reply streams, automatic error
reports, protection trips), which the caller collects with :meth:`Device.poll` at or after
:meth:`Device.next_deadline_s`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from servobus.frame import Frame

__all__ = ["Device", "Emission", "SerialDevice", "SerialEmission"]


@dataclass(frozen=True, slots=True)
class Emission:
    """A frame a device wants to send, and when it is ready to leave."""

    ready_s: float
    frame: Frame


class Device(Protocol):
    """A simulated device on a CAN bus (RS485 devices use the same shape with serial frames)."""

    @property
    def name(self) -> str:
        """A label for logs and arbitration sources (unique on its bus)."""
        ...

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s`` (every device sees every frame, as on a wire)."""
        ...

    def poll(self, now_s: float) -> list[Emission]:
        """Spontaneous frames due by ``now_s`` (streams, error reports, timeouts)."""
        ...

    def next_deadline_s(self) -> float | None:
        """When :meth:`poll` next has something to do (None: nothing scheduled)."""
        ...


@dataclass(frozen=True, slots=True)
class SerialEmission:
    """Bytes a serial device wants to write, and when it starts writing them."""

    ready_s: float
    data: bytes


class SerialDevice(Protocol):
    """A simulated device on an RS485 line: bytes in (any chunking), timed bytes out.

    The device de-frames its input itself (with the C core's de-framers), as a real one does, so
    corrupt, split and concatenated input behave as on a wire.
    """

    @property
    def name(self) -> str: ...

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        """Bytes that arrived on the line by ``now_s``."""
        ...

    def poll(self, now_s: float) -> list[SerialEmission]:
        """Spontaneous output due by ``now_s``."""
        ...

    def next_deadline_s(self) -> float | None:
        """When :meth:`poll` next has something to do (None: nothing scheduled)."""
        ...

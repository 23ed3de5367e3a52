"""An in-process half-duplex RS485 line on the event loop's clock, for bus efficiency on virtual time.

The simulator has no in-process serial path: :class:`~servobus.transports.sim.SimTransport` carries CAN
frames only, and :func:`servobus.sim.attach.serve_rs485` needs a pty and real time. This FrameLink joins
a :class:`~servobus.bus.Bus` to the simulator's serial devices (``SerialDevice``: bytes in, timed bytes
out, e.g. :class:`~servobus.protocols.myactuator.sim.rs485.MyActuatorRs485Motor`) with no I/O at all, so
it runs on a virtual-time loop (:func:`servobus.sim.virtual.run`):

* A frame the Bus sends is encoded by the family's framing (the bytes a real port would write) and
  occupies the line from ``max(now, line free)`` for ``uart_time_s(len, baud)`` (8N1). Every device
  hears those bytes when their last one has arrived.
* A device's reply starts when the device says it is ready (its turnaround after the request) or when
  the line is free, whichever is later, and reaches the host ``uart_time_s`` later; the host cuts it
  with the family's own de-framer, as :class:`~servobus.transports.rs485.SerialTransport` does, and the
  frames are handed to the Bus stamped with the loop's time.
* The line's rules are the ones :class:`~servobus.transports.rs485.SerialTransport` declares for the same
  framing and baud rate (an unopened instance is asked): its ``rules`` (half duplex, ``gap_s``: 3.5
  characters, the rest the Bus keeps after each exchange, ``turnaround_s``, ``stale_after_s``). So the
  Bus schedules this line exactly as it schedules a real port.

Every transmission is logged (:attr:`SerialLine.log`: who, start, end, bytes), which is what the
efficiency bound is computed from.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from servobus.frame import Frame
from servobus.protocols._bound import Framing
from servobus.sim.device import SerialDevice, SerialEmission
from servobus.timing import uart_time_s
from servobus.transports.base import Transport
from servobus.transports.rs485 import SerialTransport

__all__ = ["LineUse", "SerialLine"]

_SET_TIMESTAMP: Callable[[Frame, float], None] = Frame.timestamp.__set__  # type: ignore[attr-defined]


@dataclass(frozen=True, slots=True)
class LineUse:
    """One transmission on the line: ``host`` or a device's name, when it started and ended, its bytes."""

    who: str
    start_s: float
    end_s: float
    n_bytes: int


class SerialLine(Transport[Frame, Frame]):
    """A FrameLink: the host on one simulated half-duplex RS485 line with ``devices``.

    Args:
        devices: the serial devices on the line (each hears every byte the host writes).
        framing: the family's framing (``FAMILY.bind(id, link="rs485").framing``).
        baud: the line's rate (8N1).
    """

    name = "sim-rs485"

    def __init__(self, devices: Sequence[SerialDevice], framing: Framing, baud: int) -> None:
        super().__init__()
        declared = SerialTransport("sim-rs485", framing=framing, baud=baud)  # never opened: its rules only
        self.devices = list(devices)
        self.framing = framing
        self.baud = baud
        self.rules = declared.rules  # (the FrameLink contract: half duplex, gap, turnaround, staleness)
        self.char_time_s = declared.char_time_s
        self.log: list[LineUse] = []
        self._deframer = framing.deframer()
        self._free_at = 0.0
        self._loop: asyncio.AbstractEventLoop | None = None  # (its timers are asyncio's call_at)

    async def open(self) -> None:
        await super().open()
        self._loop = asyncio.get_running_loop()

    def send(self, frame: Frame, handle: object = None) -> None:
        loop = self._loop
        assert loop is not None and self.is_open
        if not frame.is_serial:
            raise ValueError(f"{frame!r} is not a serial frame")
        data = self.framing.encode(frame)
        now = loop.time()
        start, end = self._occupy("host", now, len(data))
        self._sent(frame if handle is None else handle, start, frame)
        loop.call_at(end, self._to_devices, data, end)

    def _occupy(self, who: str, ready_s: float, n_bytes: int) -> tuple[float, float]:
        start = max(ready_s, self._free_at)
        end = start + uart_time_s(n_bytes, self.baud)
        self._free_at = end
        self.log.append(LineUse(who, start, end, n_bytes))
        return start, end

    def _to_devices(self, data: bytes, at: float) -> None:
        emissions: list[tuple[SerialEmission, str]] = []
        for device in self.devices:
            emissions += [(e, device.name) for e in device.receive_bytes(data, at)]
        emissions.sort(key=lambda item: item[0].ready_s)  # half-duplex: one after the other
        assert self._loop is not None
        for emission, who in emissions:
            _, end = self._occupy(who, emission.ready_s, len(emission.data))
            self._loop.call_at(end, self._to_host, emission.data)

    def _to_host(self, data: bytes) -> None:
        assert self._loop is not None
        frames = self._deframer.feed(data)
        if not frames:
            return
        now = self._loop.time()
        for frame in frames:
            _SET_TIMESTAMP(frame, now)
        self._deliver(frames)

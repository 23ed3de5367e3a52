"""The simulated 485 -> CANFD converter module in front of CAN FD hollow motors (hollow.md §9).

Implements :class:`~servobus.sim.device.SerialDevice`. The DIP switches choose the RS-485 variant
(§9.1), fixed for the life of the object:

* **transparent** (1 Mbaud, §9.4): ``ID | 16 CAN FD bytes | CRC32``. The module forwards the 16
  bytes, unchecked, as a CAN FD frame to identifier ID, and returns whatever comes back as
  ``CAN id of the reply (the host id) | 16 bytes | CRC32``.
* **Modbus RTU** (19200 baud, §9.5): 0x10 writes the 16 request bytes (one per register) and is
  forwarded; its echo response is sent once the motor's reply has come back, and that reply is
  cached. 0x03 returns the cached reply of the slave, 16 zero bytes if there is none, without a CAN
  exchange: every CAN FD frame carries Run Cmd and Mode Sel, so the module cannot poll a motor
  without commanding it. These are §9.5's recommended simulator rules [I]. A request the frame
  decoder refuses gets a standard exception: 0x02 (illegal data address) for another register
  range, 0x03 (illegal data value) otherwise.

Structure: the module owns its motors in a dict by CAN id (the slave id) and talks to each over a
point-to-point CAN FD link, timed with :func:`~servobus.timing.frame_time_s` at 1 Mbit/s
nominal and 5 Mbit/s data with BRS (A28). It does not share a :class:`~servobus.sim.network.SimCanNetwork`
with other traffic: the module is the only host on its CAN side, one request at a time. A request
is processed when its last byte arrives (``now_s``); its reply starts writing at
``now_s + turnaround_s + CAN request time + the motor's turnaround + CAN reply time``, no earlier
than the Modbus inter-frame silence, and not before the previous reply has finished (half duplex).

Nothing is answered for corrupt input (the C core's de-framers drop it and count CRC errors),
for a slave with no motor behind the module (``no_motor``), or for a motor that did not reply
(``motor_timeout``); a host sees a timeout, as on a real line.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from enum import Enum
from typing import Any

from servobus.core import HollowTransparentDeframer, ModbusRtuDeframer
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.hollow import (
    FdReply,
    ModbusException,
    ModbusFunction,
    ModbusRead,
    ModbusReadReply,
    ModbusWrite,
    ModbusWriteAck,
)
from servobus.protocols.hollow.rs485 import decode_modbus_request, decode_transparent, encode_transparent
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.sim.device import SerialEmission
from servobus.timing import frame_time_s, uart_time_s

__all__ = [
    "DEFAULT_CONVERTER_TURNAROUND_S",
    "MODBUS_BAUD",
    "TRANSPARENT_BAUD",
    "ConverterMode",
    "HollowConverter",
]

TRANSPARENT_BAUD = 1_000_000  # §9.4 [M]
MODBUS_BAUD = 19_200  # §9.5 [M]
# The module's own store-and-forward latency is not stated; 100 µs is a small MCU's UART->CAN hop [I].
DEFAULT_CONVERTER_TURNAROUND_S = 100e-6
_CAN_BITRATE = 1_000_000  # A28
_CAN_DATA_BITRATE = 5_000_000
_MODBUS_SILENCE_CHARS = 3.5  # the RTU inter-frame gap, §9.5
_MAX_HEADER_ID = 0xFF  # the transparent reply's header is one byte
_REGISTER_RANGE = bytes([0x00, 0x00, 0x00, 0x10])
_ILLEGAL_DATA_ADDRESS = 0x02
_ILLEGAL_DATA_VALUE = 0x03


_Behaviour = Callable[["HollowConverter", Any, bytes, float, float], list[SerialEmission]]
_MODBUS_BEHAVIOUR: dict[type[ModbusRead | ModbusWrite], _Behaviour] = {}


def _does(cls: type[ModbusRead | ModbusWrite]) -> Callable[[_Behaviour], _Behaviour]:
    """Register the decorated method as what the module does on a ``cls`` request (the dispatch)."""

    def register(method: _Behaviour) -> _Behaviour:
        _MODBUS_BEHAVIOUR[cls] = method
        return method

    return register


class ConverterMode(Enum):
    """The RS-485 variant the DIP switches select (§9.1): any switch on / all off."""

    TRANSPARENT = "transparent"
    MODBUS = "modbus"


class HollowConverter:
    """The RS-485 -> CAN FD converter module with the CAN FD motors behind it.

    Args:
        motors: the motors on the module's CAN FD side (each ``fd_enabled``, unique ids).
        mode: transparent or Modbus RTU.
        turnaround_s: the module's forwarding latency, added once per request.
        bits_per_byte: UART character length: 10 for 8N1 (the default, A36), 11 with parity.
        name: the device name on its line.

    Raises:
        ValueError: a motor is not in CAN FD mode, replies on a host id that does not fit the
            transparent header byte, or shares its id with another.
    """

    def __init__(
        self,
        motors: Iterable[HollowMotor] = (),
        *,
        mode: ConverterMode = ConverterMode.TRANSPARENT,
        turnaround_s: float = DEFAULT_CONVERTER_TURNAROUND_S,
        bits_per_byte: int = 10,
        name: str = "hollow-converter",
    ) -> None:
        if turnaround_s < 0:
            raise ValueError(f"turnaround_s={turnaround_s!r} must be >= 0")
        self.mode = ConverterMode(mode)
        self.baud = TRANSPARENT_BAUD if self.mode is ConverterMode.TRANSPARENT else MODBUS_BAUD
        self.turnaround_s = turnaround_s
        self.bits_per_byte = bits_per_byte
        self._name = name
        self.motors: dict[int, HollowMotor] = {}
        for motor in motors:
            self.add(motor)
        self._deframer: HollowTransparentDeframer | ModbusRtuDeframer = (
            HollowTransparentDeframer()
            if self.mode is ConverterMode.TRANSPARENT
            else ModbusRtuDeframer(direction="requests")
        )
        self._events: Counter[str] = Counter()
        self._cache: dict[int, bytes] = {}  # Modbus: the last CAN FD reply of each slave
        self._tx_free_s = 0.0  # when the half-duplex line is free for our next reply
        self._can_free_s = 0.0  # when the module's CAN side is free
        self._last_rx_s: float | None = None

    def add(self, motor: HollowMotor) -> None:
        """Put ``motor`` behind the module.

        Raises:
            ValueError: see the class.
        """
        if not motor.fd_enabled:
            raise ValueError(f"motor {motor.motor_id} is in classic CAN mode; the module talks CAN FD (§9.1)")
        if motor.host_id > _MAX_HEADER_ID:
            raise ValueError(f"motor {motor.motor_id} replies on host id {motor.host_id}, above 0xFF (§9.4)")
        if motor.motor_id in self.motors:
            raise ValueError(f"a motor with id {motor.motor_id} is already behind this module")
        self.motors[motor.motor_id] = motor

    @property
    def name(self) -> str:
        """The device name on its line."""
        return self._name

    @property
    def char_time_s(self) -> float:
        """One UART character at :attr:`baud`."""
        return uart_time_s(1, self.baud, bits_per_byte=self.bits_per_byte)

    @property
    def silence_s(self) -> float:
        """The gap that ends a frame: 3.5 characters in Modbus RTU; none in transparent mode,
        whose de-framer synchronises on the CRC (§9.4)."""
        return _MODBUS_SILENCE_CHARS * self.char_time_s if self.mode is ConverterMode.MODBUS else 0.0

    @property
    def counters(self) -> dict[str, int]:
        """Frames and faults by kind: the de-framer's (``frames``, ``crc_errors``,
        ``discarded_bytes``) and the module's own (``no_motor``, ``motor_timeout``,
        ``exceptions``, ``replies``, ``reads``, ``writes``, ``forwarded``, ``broadcast``)."""
        return {
            "frames": self._deframer.frames,
            "crc_errors": self._deframer.crc_errors,
            "discarded_bytes": self._deframer.discarded_bytes,
            **self._events,
        }

    # ---- SerialDevice protocol ----

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        """Bytes that arrived by ``now_s`` (any chunking); replies to the frames they complete."""
        self._last_rx_s = now_s
        return [e for frame in self._deframer.feed(data) for e in self._handle(frame, now_s)]

    def poll(self, now_s: float) -> list[SerialEmission]:
        """Modbus: after 3.5 characters of silence, drop a partial frame (it is noise, §9.5)."""
        deadline = self.next_deadline_s()
        if deadline is None or now_s < deadline:
            return []
        self._last_rx_s = None
        return [e for frame in self._deframer.idle() for e in self._handle(frame, now_s)]

    def next_deadline_s(self) -> float | None:
        """When the line has been quiet long enough to end a pending partial Modbus frame."""
        if self.mode is not ConverterMode.MODBUS or self._last_rx_s is None or not self._deframer.pending:
            return None
        return self._last_rx_s + self.silence_s

    # ---- frames ----

    def _handle(self, frame: bytes, now_s: float) -> list[SerialEmission]:
        if self.mode is ConverterMode.TRANSPARENT:
            return self._transparent(frame, now_s)
        return self._modbus(frame, now_s)

    def _transparent(self, frame: bytes, now_s: float) -> list[SerialEmission]:
        try:
            address, payload = decode_transparent(frame)
        except ProtocolError:  # the de-framer checked the CRC already; kept for safety
            self._events["undecodable"] += 1
            return []
        exchanged = self._exchange(address, payload, now_s)
        if exchanged is None:
            return []
        reply_end_s, reply = exchanged
        # §9.4: forwarded back with ID = the CAN id the reply came on (the host id).
        return self._emit(reply_end_s, encode_transparent(reply.arbitration_id, reply.data))

    def _modbus(self, frame: bytes, now_s: float) -> list[SerialEmission]:
        slave = frame[0]
        if slave == 0:
            # Modbus broadcast: no response by rule, and motor id 0 is avoided (§9.5 [I]).
            self._events["broadcast"] += 1
            return []
        if slave not in self.motors:
            # No motor answers on that id, so the module has nothing to return: silence, as on CAN.
            self._events["no_motor"] += 1
            return []
        earliest_s = now_s + max(self.turnaround_s, self.silence_s)
        try:
            request = decode_modbus_request(frame)
        except ProtocolError:
            if frame[1] not in ModbusFunction._value2member_map_:  # the de-framer passes 0x03, 0x10 only
                self._events["undecodable"] += 1
                return []
            function = ModbusFunction(frame[1])
            code = _ILLEGAL_DATA_ADDRESS if frame[2:6] != _REGISTER_RANGE else _ILLEGAL_DATA_VALUE
            self._events["exceptions"] += 1
            exception = ModbusException(slave_id=slave, function=function, exception_code=code)
            return self._emit(earliest_s, exception.encode())
        return _MODBUS_BEHAVIOUR[type(request)](self, request, frame, now_s, earliest_s)

    @_does(ModbusRead)
    def _modbus_read(
        self, request: ModbusRead, frame: bytes, now_s: float, earliest_s: float
    ) -> list[SerialEmission]:
        self._events["reads"] += 1
        cached = self._cache.get(request.slave_id)
        reply = FdReply.decode(cached) if cached is not None else FdReply(slave_id=0)
        return self._emit(earliest_s, ModbusReadReply(slave_id=request.slave_id, reply=reply).encode())

    @_does(ModbusWrite)
    def _modbus_write(
        self, request: ModbusWrite, frame: bytes, now_s: float, earliest_s: float
    ) -> list[SerialEmission]:
        self._events["writes"] += 1
        # The registers' low bytes are forwarded as they came (the module does not re-encode).
        exchanged = self._exchange(request.slave_id, frame[7:39][1::2], now_s)
        if exchanged is None:
            return []
        reply_end_s, reply_can = exchanged
        self._cache[request.slave_id] = reply_can.data
        return self._emit(max(reply_end_s, earliest_s), ModbusWriteAck(slave_id=request.slave_id).encode())

    def _exchange(self, motor_id: int, payload: bytes, now_s: float) -> tuple[float, Frame] | None:
        """Send ``payload`` to ``motor_id`` over CAN FD; (time the reply was received, reply)."""
        motor = self.motors.get(motor_id)
        if motor is None:
            self._events["no_motor"] += 1
            return None
        request = Frame(arbitration_id=motor_id, data=payload, is_fd=True, bitrate_switch=True)
        start_s = max(now_s + self.turnaround_s, self._can_free_s)
        request_end_s = start_s + frame_time_s(request, _CAN_BITRATE, _CAN_DATA_BITRATE)
        self._events["forwarded"] += 1
        emissions = motor.receive(request, request_end_s)
        self._can_free_s = request_end_s
        if not emissions:
            self._events["motor_timeout"] += 1
            return None
        reply = emissions[0]
        reply_end_s = reply.ready_s + frame_time_s(reply.frame, _CAN_BITRATE, _CAN_DATA_BITRATE)
        self._can_free_s = reply_end_s
        return reply_end_s, reply.frame

    def _emit(self, ready_s: float, data: bytes) -> list[SerialEmission]:
        start_s = max(ready_s, self._tx_free_s)
        self._tx_free_s = start_s + uart_time_s(len(data), self.baud, bits_per_byte=self.bits_per_byte)
        self._events["replies"] += 1
        return [SerialEmission(start_s, data)]

    def __repr__(self) -> str:
        ids = ", ".join(str(i) for i in sorted(self.motors))
        return f"HollowConverter({self.mode.value}, {self.baud} baud, motors=[{ids}])"

"""The RS485 front of a simulated MyActuator motor: ``3E`` frames in, timed ``3E`` replies out.

Implements :class:`~servobus.sim.device.SerialDevice` around a
:class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor`, which keeps all state and acts on the
commands; this module only frames (spec ``myactuator-v4.md`` §1.2, §1.3, §4.38):

* Input is cut into frames by the C core's de-framer (:func:`~servobus.protocols.myactuator.rs485_deframer`),
  so split, joined and corrupt input behave as on a wire: a frame with a bad CRC is dropped and
  counted (``crc_errors``) and gets no reply.
* A frame is taken when its ID byte is the motor's id or 0xCD (broadcast: every motor executes it
  and answers with its own ID byte, §1.3). The replies of several motors to one 0xCD frame are ready
  at the same time; on a shared half-duplex line :func:`~servobus.sim.attach.serve_rs485` writes them
  one after the other. 0x79 (V4.3) arrives with ID byte 0xCD and is answered with ID byte 0xCD, as
  the manual prints it (§4.38); its read reply puts the id in DATA[7] (the RS485 example).
* 0xB6 is not supported on RS485 ("485 version does not support this function", §4.36): ignored,
  counted ``rs485_unsupported``. The motor sends nothing on its own on RS485 [I]: a half-duplex
  master/slave line has no arbitration, so the 0x20 index 3 error reports are dropped
  (``spontaneous_dropped``). The 0xB3 protection still trips (its field is named "CanRecvTime", but
  the manuals do not restrict it to CAN, spec §9 item 30); what is reported of it besides (0xF1
  frames, the echo of the first command after, the motor's ``trip_echo``) was seen on CAN, and is
  switched off here: the next frame after a trip is executed, as the manuals read.
* The ``FE EE`` RS485 motion frame ([000] §6) is not simulated: its CRC32 is unverified, and the
  de-framer drops its bytes as noise.
"""

from __future__ import annotations

from collections import Counter

from servobus.errors import ProtocolError
from servobus.protocols.myactuator import ActiveReply, ReadCanId, SetCanId
from servobus.protocols.myactuator.ids import RS485_BROADCAST_ID
from servobus.protocols.myactuator.rs485 import decode_rs485_request, encode_rs485, rs485_deframer
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.device import SerialEmission

__all__ = ["MyActuatorRs485Motor"]

_ACTIVE_REPLY_CODE = ActiveReply.CODE  # CAN only (§4.36)


class MyActuatorRs485Motor:
    """A MyActuator motor on an RS485 line (implements :class:`~servobus.sim.device.SerialDevice`).

    Args:
        motor: the motor behind this front (its id, revision, turnaround and state).
        name: the device name on its line (default: the motor's name).
    """

    def __init__(self, motor: MyActuatorMotor, *, name: str | None = None) -> None:
        self.motor = motor
        motor.trip_echo = False  # (reported on CAN only; see the module docstring)
        self._name = name or motor.name
        self._deframer = rs485_deframer()
        self._events: Counter[str] = Counter()

    @property
    def name(self) -> str:
        """The device name on its line."""
        return self._name

    @property
    def counters(self) -> dict[str, int]:
        """The de-framer's counts (``frames``, ``crc_errors``, ``discarded_bytes``) and this front's
        (``ignored_id``, ``rs485_unsupported``, ``replies``, ``spontaneous_dropped``).
        What the motor did with the frames is in ``motor.counters``."""
        return {
            "frames": self._deframer.frames,
            "crc_errors": self._deframer.crc_errors,
            "discarded_bytes": self._deframer.discarded_bytes,
            **self._events,
        }

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        """Bytes that arrived on the line by ``now_s``; replies to the frames they complete."""
        return [e for frame in self._deframer.feed(data) for e in self._handle(frame, now_s)]

    def poll(self, now_s: float) -> list[SerialEmission]:
        """Runs the motor's timers (the 0xB3 trip); RS485 motors send nothing on their own."""
        self._events["spontaneous_dropped"] += len(self.motor.spontaneous(now_s))
        return []

    def next_deadline_s(self) -> float | None:
        """When the motor's 0xB3 protection trips, if no frame comes first."""
        return self.motor.protection_deadline_s()

    def _handle(self, frame: bytes, now_s: float) -> list[SerialEmission]:
        motor = self.motor
        motor.advance(now_s)
        id_byte = frame[1]
        if id_byte not in (motor.motor_id, RS485_BROADCAST_ID):
            self._events["ignored_id"] += 1
            return []
        if frame[3] == _ACTIVE_REPLY_CODE:
            self._events["rs485_unsupported"] += 1
            return []
        try:
            _, command = decode_rs485_request(frame, revision=motor.revision)
        except ProtocolError:  # counted by the motor: ``other_revision`` or ``undecodable``
            motor.count_refused_bytes(frame[3:11], rs485=True)
            return []
        reply_id_byte = RS485_BROADCAST_ID if isinstance(command, SetCanId | ReadCanId) else motor.motor_id
        reply = motor.handle(command, now_s, rs485=True)
        if reply is None:
            return []
        self._events["replies"] += 1
        return [SerialEmission(now_s + motor.turnaround_s, encode_rs485(reply_id_byte, reply))]

    def __repr__(self) -> str:
        return f"MyActuatorRs485Motor({self.motor!r})"

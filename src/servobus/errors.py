"""The servobus exception tree.

    ServobusError
     ├── ProtocolError      bytes that cannot be decoded (raw bytes in hex, motor id, command)
     ├── MotorTimeout       no reply in time (also a TimeoutError)
     │    ├── MotorOffline  cycle(): the motor is offline, the tick did not wait for it
     │    └── MotorBusy     cycle(): its last reply is still due, this tick's command was not sent
     ├── MotorStreaming     the motor streams (0xB6) and answers no other request meanwhile
     ├── MotorFault         the motor reported error flags or an error code (decoded), or an event
     │                      frame (0xF1 trip)
     ├── MotorNotExecuted   the motor echoed the request's bytes instead of executing it
     └── TransportError     adapter lost, bus-off, port closed (raised from its cause)
          ├── SendQueueFull  (servobus.transports) a send found the queue (or the adapter's) full
          └── BusOffError    (servobus.transports) the CAN controller is bus-off: sends fail fast

Bad *input* from the caller is not in this tree: an out-of-range setpoint raises ValueError naming
the field, the value and the limit, before any frame is built.
"""

from __future__ import annotations

import enum

__all__ = [
    "MotorBusy",
    "MotorFault",
    "MotorNotExecuted",
    "MotorOffline",
    "MotorStreaming",
    "MotorTimeout",
    "ProtocolError",
    "RequestStateError",
    "ServobusError",
    "TransportError",
]


class ServobusError(Exception):
    """Base class of every error servobus raises about motors, buses and bytes."""


class ProtocolError(ServobusError):
    """Received bytes that do not decode.

    Attributes:
        raw: the offending bytes (shown in hex in the message).
        motor_id: the motor the bytes came from, when known.
        command: the command byte involved, when known.
    """

    def __init__(
        self,
        message: str,
        *,
        raw: bytes = b"",
        motor_id: int | None = None,
        command: int | None = None,
    ) -> None:
        self.message = message
        self.raw = bytes(raw)
        self.motor_id = motor_id
        self.command = command
        details = []
        if motor_id is not None:
            details.append(f"motor {motor_id}")
        if command is not None:
            details.append(f"command 0x{command:02X}")
        if raw:
            details.append(f"raw {self.raw.hex(' ').upper()}")
        super().__init__(f"{message} ({', '.join(details)})" if details else message)

    def with_context(self, *, motor_id: int | None = None, command: int | None = None) -> ProtocolError:
        """A copy that also names ``motor_id``/``command`` (kept where already known), for re-raising.

        Codecs raise without knowing which motor a payload came from; the layer that knows adds it:
        ``raise exc.with_context(motor_id=3) from None``.
        """
        return type(self)(
            self.message,
            raw=self.raw,
            motor_id=self.motor_id if self.motor_id is not None else motor_id,
            command=self.command if self.command is not None else command,
        )


class MotorTimeout(ServobusError, TimeoutError):
    """A motor did not answer within its deadline.

    Attributes:
        diagnosis: what the bus saw instead, when it was asked (a request that timed out): frames
            of another family on the motor's ids, frames on other ids, or no frame at all
            (servobus.diagnosis); also the end of the message. None: not asked.
    """

    def __init__(self, *args: object, diagnosis: str | None = None) -> None:
        super().__init__(*args)
        self.diagnosis = diagnosis


class MotorOffline(MotorTimeout):
    """``Bus.cycle()`` did not wait for this motor: the watchdog marks it offline.

    A tick never waits on a motor that is not answering. Its command is not sent, except at most
    every ``probe_interval_s``, when it goes out as a probe whose reply the tick does not wait for;
    once the motor answers it is online and in the tick again. A MotorTimeout too: no reply.
    """


class MotorBusy(MotorTimeout):
    """``Bus.cycle()`` did not send this motor's command: a reply with the same key is still due
    (its last request timed out and the reply may come late, or another task's request with that
    key is in flight). Sent now, that reply could answer it; waiting would delay the whole tick.
    A MotorTimeout too: no reply this tick.
    """


class MotorStreaming(ServobusError):
    """The motor streams (MyActuator 0xB6) and answers no request but reads of the streamed command
    until the stream is switched off; such a request is refused before it is sent."""


class MotorFault(ServobusError):
    """A motor reported error flags or an error code, or a frame that tells of a fault (MyActuator's
    0xF1: its own communication watchdog, 0xB3, cut the output).

    A family's reply declares which it carries (:class:`~servobus.protocols.Reply`): ``FAULTS``
    names a field of flags (an ``enum.Flag``: several faults at once, 0 none), ``FAULT_CODE`` a
    field of one code (an ``enum.IntEnum`` or an int: one state or fault at a time, the codes in
    ``NO_FAULT_CODES`` being no fault: Damiao's 0 disabled and 1 enabled).

    Attributes:
        flags: the decoded flags (the family's flag enum; unknown bits kept); None for a fault told
            by a code or by an event frame, which carries no flags.
        code: the fault code (the family's IntEnum member, or the int where the enum has no member
            for it); None for a fault told by flags or by an event frame.
        motor_id: the motor that reported them.
    """

    def __init__(
        self,
        message: str,
        *,
        flags: enum.Flag | None = None,
        motor_id: int,
        code: int | None = None,
    ) -> None:
        super().__init__(message)
        self.flags = flags
        self.code = code
        self.motor_id = motor_id


class MotorNotExecuted(ServobusError):
    """The motor answered a command with the command's own bytes and did not execute it.

    A MyActuator motor whose communication watchdog (0xB3) tripped echoes the first command after
    communication resumes, byte for byte, and executes only the next one. The request fails with
    this error, for commands whose real reply cannot be their own bytes (the family declares
    which: a control command's reply carries temperature and measurements), and for any command
    sent while the motor's trip is known. Sending the command again is the remedy; the safe stop
    does so by itself.

    Attributes:
        motor_id: the motor.
        command: the command byte (DATA[0]) echoed, when there is one.
        raw: the echoed bytes.
    """

    def __init__(self, message: str, *, motor_id: int, command: int | None = None, raw: bytes = b"") -> None:
        super().__init__(message)
        self.motor_id = motor_id
        self.command = command
        self.raw = bytes(raw)


class TransportError(ServobusError):
    """The adapter or port failed: unplugged, bus-off, closed."""


class RequestStateError(ServobusError, RuntimeError):
    """A request was moved in a way its life cycle does not allow (``scheduler.TRANSITIONS``): a bug
    in the scheduler's caller, named with the request and both states."""

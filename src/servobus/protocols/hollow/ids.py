"""Identifiers of the hollow family: motor and host ids, and the match keys of design.md's table.

hollow.md §3 and §7.1: a request goes to the motor's id (standard 11-bit for setpoints, special
commands and CAN FD; extended 29-bit with the same number for the mode switch and PI frames). Every
reply goes to the *host id* (console item *h*, default 100 = 0x064), so replies of all motors share
one identifier and carry the motor's id in the payload: D0 in classic CAN (§4.5, §5.3), the Slave ID
byte D15 in CAN FD (§7.3), byte 16 of a transparent RS-485 frame (§9.4), and the slave address of a
Modbus RTU frame (§9.5). The motor answers one request with one reply, so a key of (host id, motor id)
identifies the pending request on CAN, and the slave id alone on the RS-485 converter.
"""

from __future__ import annotations

from servobus.frame import Frame
from servobus.protocols._fields import check_range

__all__ = [
    "DEFAULT_HOST_ID",
    "HOST_IDS",
    "MODBUS_SLAVE_IDS",
    "MOTOR_IDS",
    "check_host_id",
    "check_modbus_slave_id",
    "check_motor_id",
    "modbus_reply_key",
    "modbus_request_key",
    "motor_id_from_reply",
    "reply_id",
    "reply_key",
    "request_id",
    "request_key",
    "transparent_reply_key",
    "transparent_request_key",
]

# §2.4 item g and §3: "Motor CAN id: 0-100, set on the console".
MOTOR_IDS = range(0, 101)
# §2.4 item h gives only the default (100). Any standard identifier can be configured [I]; a motor id
# of 100 then collides with the default host id (§3), which is the user's to avoid.
HOST_IDS = range(0, 0x800)
DEFAULT_HOST_ID = 100
# §9.5: slave address = motor id; address 0 is the Modbus broadcast address, which gets no reply and
# cannot read, so a host addresses motors 1..100 [I].
MODBUS_SLAVE_IDS = range(1, 101)

# Reply payload sizes (§4.5, §5.3, §7.3) and the serial frame sizes (§9.4, §9.5).
_CLASSIC_REPLY_SIZES = (6, 8)
_FD_SIZE = 16
_TRANSPARENT_SIZE = 21


def _check_id(name: str, value: int, ids: range) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name}={value!r} is not an integer")
    check_range(name, value, ids.start, ids.stop - 1)
    return value


def check_motor_id(motor_id: int) -> int:
    """Return ``motor_id`` if it is a valid motor CAN id (0..100, §2.4 item g).

    Raises:
        ValueError: not an integer in 0..100 (the message names the field and the limits).
    """
    return _check_id("motor_id", motor_id, MOTOR_IDS)


def check_host_id(host_id: int) -> int:
    """Return ``host_id`` if it is a standard 11-bit identifier (console item h, default 100).

    Raises:
        ValueError: not an integer in 0..0x7FF.
    """
    return _check_id("host_id", host_id, HOST_IDS)


def check_modbus_slave_id(slave_id: int) -> int:
    """Return ``slave_id`` if it can address one motor over Modbus RTU (1..100, §9.5).

    Raises:
        ValueError: not an integer in 1..100.
    """
    if slave_id == 0 and not isinstance(slave_id, bool):
        raise ValueError(
            "slave_id=0 is outside [1, 100]: 0 is the Modbus broadcast address (§9.5), which every motor "
            "would take and none would answer; broadcast cannot be sent"
        )
    return _check_id("slave_id", slave_id, MODBUS_SLAVE_IDS)


def request_id(motor_id: int) -> int:
    """The arbitration id of every request to ``motor_id`` (standard and extended frames alike, §3).

    Raises:
        ValueError: ``motor_id`` outside 0..100.
    """
    return check_motor_id(motor_id)


def reply_id(host_id: int = DEFAULT_HOST_ID) -> int:
    """The arbitration id every motor replies on: the host id (§3, A12).

    Raises:
        ValueError: ``host_id`` outside 0..0x7FF.
    """
    return check_host_id(host_id)


def motor_id_from_reply(data: bytes, *, is_fd: bool = False) -> int | None:
    """The id of the motor that sent a reply payload, or None if ``data`` is no reply layout.

    Args:
        data: the payload of a frame received on the host id.
        is_fd: the frame is CAN FD (Slave ID in D15) rather than classic CAN (motor id in D0).

    Returns:
        The motor id byte (not range-checked: the decoders do that), or None.
    """
    if is_fd:
        return data[15] if len(data) == _FD_SIZE else None
    return data[0] if len(data) in _CLASSIC_REPLY_SIZES else None


def request_key(motor_id: int, *, host_id: int = DEFAULT_HOST_ID) -> tuple[int, int]:
    """The match key a request to ``motor_id`` waits on: (host id, motor id) (design.md, Matching).

    Raises:
        ValueError: an id out of its range.
    """
    return (check_host_id(host_id), check_motor_id(motor_id))


def reply_key(frame: Frame, *, host_id: int = DEFAULT_HOST_ID) -> tuple[int, int] | None:
    """The match key of a received CAN or CAN FD frame, or None if it is not a reply for us.

    A reply is a standard frame on the host id (§3: replies are standard [I][C]) with a reply layout:
    6 or 8 classic bytes (D0 = motor id) or 16 FD bytes (D15 = Slave ID). Our own transmitted frames
    looped back by an adapter (``is_rx`` False) are never replies, which matters when a motor id
    equals the host id.

    Args:
        frame: the received frame.
        host_id: the host id the motors were configured to reply to.

    Returns:
        (host id, motor id), equal to :func:`request_key` of the request it answers; or None.
    """
    if not frame.is_rx or frame.is_extended_id or frame.arbitration_id != host_id:
        return None
    motor_id = motor_id_from_reply(frame.data, is_fd=frame.is_fd)
    if motor_id is None:
        return None
    return (host_id, motor_id)


def transparent_request_key(motor_id: int) -> int:
    """The match key of a transparent-mode request to ``motor_id``: its slave id (§9.4).

    Raises:
        ValueError: ``motor_id`` outside 0..100.
    """
    return check_motor_id(motor_id)


def transparent_reply_key(frame: bytes) -> int | None:
    """The slave id of a 21-byte transparent reply frame (byte 16 = CAN FD D15, §9.4), else None.

    The header byte is the CAN id the converter received the reply on (the host id, 0x64 by
    default), so it names no motor; the CRC is the decoder's business.
    """
    return frame[16] if len(frame) == _TRANSPARENT_SIZE else None


def modbus_request_key(slave_id: int) -> int:
    """The match key of a Modbus RTU request to ``slave_id``: the slave address (§9.5).

    Raises:
        ValueError: ``slave_id`` outside 1..100.
    """
    return check_modbus_slave_id(slave_id)


def modbus_reply_key(frame: bytes) -> int | None:
    """The slave address of a Modbus RTU reply frame (its first byte), or None for an empty frame."""
    return frame[0] if frame else None

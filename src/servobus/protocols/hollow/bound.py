"""One hollow motor's codec on Frames (protocols/_bound.py's contract): ``FAMILY.bind(3, link="canfd")``.

Links:

* ``"can"``: classic CAN. Set-points and special commands on the motor id (11-bit), the mode switch
  and PI frames on the same number as a 29-bit id; the reply (6 bytes in normal mode, 8 in extended)
  comes on the host id with the motor id in D0.
* ``"canfd"``: the 16-byte CAN FD control frame on the motor id (and the PI frames, 29-bit); the
  reply comes on the host id with the Slave ID in D15.
* ``"rs485"``: the RS-485 -> CANFD converter in transparent mode (§9.4, 1 Mbaud). It carries the
  16-byte FD control frame as it is: a serial Frame's address is the ID byte (the motor id out, the
  host id back), its body the 16 bytes; the framing adds the CRC-32.
* ``"modbus"``: the converter in Modbus RTU mode (§9.5, 19200 baud). An FdCommand is written to
  holding registers 0..15 (function 0x10, answered by an acknowledgement only); the motor's reply
  bytes are read back with ``ModbusRead`` (function 0x03). A serial Frame's address is the slave id,
  its body the function code and what follows, up to the CRC-16.

On CAN and in transparent mode every request is answered once (§3, "one request, one reply") and all
motors reply on the one host id, so a reply's key is (host id, motor id from the payload); the host
id is every hollow motor's shared identifier, and a motor whose own id equals it is refused on a bus
with others. On Modbus the key is (slave id, function).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import Any

from servobus.core import HollowTransparentDeframer, ModbusRtuDeframer, crc16_modbus
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols._bound import (
    EXTENDED,
    KIND_NOT_OURS,
    KIND_REPLY,
    Broadcast,
    CodecBase,
    FrameKind,
    frame_key,
)
from servobus.protocols._family import find_revision
from servobus.protocols._fast import Slow, maker
from servobus.protocols._message import Command, Reply
from servobus.protocols.hollow._packed import OnLinks
from servobus.protocols.hollow.codec import Revision, decode_reply
from servobus.protocols.hollow.commands import HollowCommand, Stop
from servobus.protocols.hollow.commands_fd import (
    FD_PAYLOAD_SIZE,
    FdCommand,
    fd_position_limits_deg,
    fd_velocity_limits_rpm,
)
from servobus.protocols.hollow.ids import (
    DEFAULT_HOST_ID,
    check_host_id,
    check_modbus_slave_id,
    check_motor_id,
)
from servobus.protocols.hollow.model import DEFAULT_MODEL, HollowModel, packers
from servobus.protocols.hollow.replies import FD_TEMPERATURE_LIMITS_C as FD_TEMPERATURE_LIMITS
from servobus.protocols.hollow.replies import ExtendedReply, FdReply, NormalReply, reply_classes
from servobus.protocols.hollow.restart import RESTART
from servobus.protocols.hollow.rs485 import ModbusWrite, decode_modbus_reply, encode_transparent

__all__ = ["LINKS", "HollowCodec", "ModbusFraming", "TransparentFraming", "bind", "broadcast"]

LINKS = ("can", "canfd", "rs485", "modbus")
#: the revisions, the default first (the Family\'s)
REVISIONS = (Revision.HO_SERIES,)
MODBUS_BROADCAST = 0  # §9.5: address 0 reaches every slave and is never answered

#: §3: the motor answers within 500 µs; the converter adds a serial round trip at 1 Mbaud.
DEFAULT_TIMEOUT_S = {"can": 0.01, "canfd": 0.01, "rs485": 0.02, "modbus": 0.1}
#: A command declared ``SLOW`` (none of the manual's is) waits this many times longer.
SLOW_FACTOR = 10.0
#: The payload sizes of the classic-CAN replies (6 in normal mode, 8 in extended mode).
_CLASSIC_SIZES = frozenset(cls.SIZE for cls in reply_classes() if not cls.FD)
_MOTOR_IDS = range(0, 101)
_TEMPERATURE = (-128, 127)


def _classic_decoder(model: HollowModel, extended: bool) -> Callable[[bytes], Any]:
    """Normal (6 B) or extended (8 B) reply through the model's packer, unvalidated; Slow when in doubt."""
    cls = ExtendedReply if extended else NormalReply
    packer = getattr(packers(model), cls.PACKER)
    unpack = packer.unpack
    size = cls.SIZE
    make = maker(cls, ("motor_id", "position_deg", "speed_rad_s", "current_a", "model"))
    v_max, i_max = model.speed_full_scale_rad_s, model.current_full_scale_a
    p_lo, p_hi = packer.scales[1].lo, packer.scales[1].hi
    if not extended:
        p_lo, p_hi = -model.position_full_scale_deg, model.position_full_scale_deg

    def decode(data: bytes) -> Any:
        if len(data) != size or data[0] > 100:
            raise Slow
        _, position, speed, current = unpack(data)
        if not (-v_max <= speed <= v_max and -i_max <= current <= i_max and p_lo <= position <= p_hi):
            raise Slow
        return make(data[0], position, speed, current, model)

    return decode


def _fd_decoder(model: HollowModel) -> Callable[[bytes], FdReply]:
    from servobus.protocols.hollow.commands import ControlMode

    unpack = packers(model).fd_reply.unpack
    modes = {int(m): m for m in ControlMode}
    p_lo, p_hi = fd_position_limits_deg()
    t_lo, t_hi = FD_TEMPERATURE_LIMITS
    v_lo, v_hi = fd_velocity_limits_rpm(model)
    make = maker(
        FdReply,
        (
            "position_deg",
            "velocity_rpm",
            "current_raw",
            "mode",
            "running",
            "reserved",
            "temperature_c",
            "slave_id",
            "model",
        ),
    )

    def decode(data: bytes) -> FdReply:
        if len(data) != FD_PAYLOAD_SIZE or data[15] > 100 or data[12] > 1:
            raise Slow
        position, velocity, current, mode, _, reserved, temperature, _ = unpack(data)
        member = modes.get(int(mode))
        if member is None or not (
            p_lo <= position <= p_hi and v_lo <= velocity <= v_hi and t_lo <= temperature <= t_hi
        ):
            raise Slow
        return make(  # type: ignore[no-any-return]
            position,
            velocity,
            int(current),
            member,
            data[12] == 1,
            int(reserved),
            int(temperature),
            data[15],
            model,
        )

    return decode


def _frame_kind(cls: type[OnLinks]) -> str:
    """What frame ``cls`` is, for a refusal: its kind tells the user which link it needs."""
    if not issubclass(cls, HollowCommand):
        return "a serial frame"
    if cls.EXTENDED_ID:
        return "an extended-id frame"
    return "a CAN FD frame" if cls.FD else "a classic-CAN frame"


class HollowCodec(CodecBase):
    """One hollow motor on one link. Build it with :func:`bind` (or ``FAMILY.bind``)."""

    family = "hollow"
    RESTART = RESTART  # what proves a restart (servobus.bus.restarts)
    # Classic CAN has the special Stop frame; an FD motor (and the converter) is stopped by a control
    # frame with Run Cmd off. The hollow motors have no brake command and no separate power-off.
    SAFE_COMMANDS = {  # noqa: RUF012 - a class table, not per instance
        "stop": lambda codec: Stop() if codec.link == "can" else FdCommand(run=False, model=codec.model),
        "shutdown": lambda codec: Stop() if codec.link == "can" else FdCommand(run=False, model=codec.model),
    }
    model: HollowModel

    __slots__ = (
        "_fast_classic",
        "_fast_ext",
        "_fast_fd",
        "_key",
        "host_id",
    )

    def __init__(self, motor_id: int, revision: Any, model: HollowModel, link: str, host_id: int) -> None:
        self.motor_id = check_motor_id(motor_id)
        self.host_id = check_host_id(host_id)
        self.revision = revision
        self.model = model
        self.link = link
        self._key = frame_key(host_id, motor_id)
        self.reply_ids: frozenset[int] = frozenset()
        self.shared_ids = frozenset({host_id})
        self.request_ids = frozenset({motor_id, motor_id | EXTENDED})
        self.framing: TransparentFraming | ModbusFraming | None = None
        if link == "rs485":
            if host_id > 0xFF:
                raise ValueError(f"host_id=0x{host_id:X}: the converter's frames carry a one-byte id")
            self.request_ids = frozenset({motor_id})
            self.framing = TransparentFraming()
        elif link == "modbus":
            check_modbus_slave_id(motor_id)
            self.request_ids = self.reply_ids = frozenset({motor_id})
            self.shared_ids = frozenset({MODBUS_BROADCAST})
            self.framing = ModbusFraming()
        self._fast_classic = _classic_decoder(model, extended=False)
        self._fast_ext = _classic_decoder(model, extended=True)
        self._fast_fd = _fd_decoder(model)

    def __repr__(self) -> str:
        return f"<hollow motor {self.motor_id} {self.link}, host id {self.host_id}>"

    def wire(self, command: Command) -> Command:
        """The message that goes out for ``command`` on this link: the command itself, or on
        ``modbus`` an FdCommand as the 0x10 write of its bytes (:class:`ModbusWrite`).

        Raises:
            ValueError: not a hollow command, a class whose ``LINKS`` do not include this link, another
                slave, or another motor model.
        """
        if not isinstance(command, OnLinks):
            raise ValueError(f"{command!r} is not a hollow command")
        cls = type(command)
        if self.link not in cls.LINKS:
            carried = (
                f"carried on link {', '.join(map(repr, cls.LINKS))}" if cls.LINKS else "sent outside a link"
            )
            raise ValueError(f"{cls.__name__} is {_frame_kind(cls)} {carried}, not on link={self.link!r}")
        if self.link == "modbus" and isinstance(command, FdCommand):
            command = ModbusWrite(slave_id=self.motor_id, command=command)
        slave = getattr(command, "slave_id", self.motor_id)
        if slave != self.motor_id:
            raise ValueError(f"{command!r} addresses slave {slave}, not {self.motor_id}")
        carried_command = getattr(command, "command", command)
        model = getattr(carried_command, "model", None)
        if model is not None and model is not self.model and model != self.model:
            raise ValueError(f"the command's model {model.name} is not this motor's {self.model.name}")
        return command

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor.

        On ``modbus`` an FdCommand (or a ModbusWrite) becomes the 0x10 write of its 16 bytes, and a
        ModbusRead the 0x03 read of the motor's reply registers.

        Raises:
            ValueError: not a hollow command, or a frame kind this link does not carry.
        """
        message = self.wire(command)
        if self.link == "modbus":  # the serial Frame: slave id, then function .. up to the CRC
            wire = message.encode()
            return Frame(arbitration_id=self.motor_id, data=wire[1:-2], is_serial=True, is_rx=False)
        assert isinstance(message, HollowCommand)
        if self.link == "rs485":
            return Frame(arbitration_id=self.motor_id, data=message.encode(), is_serial=True, is_rx=False)
        fd = message.FD
        return Frame(
            arbitration_id=self.motor_id,
            data=message.encode(),
            is_extended_id=message.EXTENDED_ID,
            is_fd=fd,
            bitrate_switch=fd and self.link == "canfd",
            is_rx=False,
        )

    def reply_key(self, command: Command) -> Hashable | None:
        """(host id, motor id) on CAN and in transparent mode, where every request is answered once;
        (slave, function) on Modbus, where a write is acknowledged and a read answered.

        Raises:
            ValueError: as :meth:`encode`.
        """
        message = self.wire(command)
        if type(message).NO_REPLY is not None:
            return None
        if self.link == "modbus":
            return frame_key(self.motor_id, int(message.FUNCTION))  # type: ignore[attr-defined]
        return self._key

    def timeout_s(self, command: Command) -> float:
        """How long to wait for the reply to ``command``: longer for a command declared ``SLOW``."""
        return DEFAULT_TIMEOUT_S[self.link] * (SLOW_FACTOR if type(command).SLOW else 1.0)

    def retry_safe(self, command: Command) -> bool:
        """True for a command declared ``READ`` (the Modbus read): every other hollow request is a
        set-point or a mode change."""
        return type(command).READ

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """REPLY for a received reply naming this motor (by payload on CAN, by address on Modbus)."""
        if not frame.is_rx or frame.is_extended_id or frame.is_serial != (self.framing is not None):
            return KIND_NOT_OURS, None
        data = frame.data
        if self.link == "modbus":
            if frame.arbitration_id == self.motor_id and data:
                return KIND_REPLY, frame_key(self.motor_id, data[0] & 0x7F)
            return KIND_NOT_OURS, None
        if frame.arbitration_id != self.host_id:
            return KIND_NOT_OURS, None
        if frame.is_fd or frame.is_serial:
            if len(data) == FD_PAYLOAD_SIZE and data[15] == self.motor_id:
                return KIND_REPLY, self._key
        elif len(data) in _CLASSIC_SIZES and data[0] == self.motor_id:
            return KIND_REPLY, self._key
        return KIND_NOT_OURS, None

    def request_key(self, frame: Frame) -> Hashable | None:
        """The key of the reply to ``frame`` if it is another host's request to this motor (on its
        motor id, received; the motor answers on its host id whoever asked). None on the serial
        links (one master per line)."""
        if self.framing is not None or not frame.is_rx or frame.arbitration_id != self.motor_id:
            return None
        return self._key

    def decode(self, frame: Frame) -> Reply:
        """The typed reply in ``frame``.

        Raises:
            ProtocolError: bytes that do not decode, or a frame that is not this motor's reply.
        """
        data = frame.data
        if self.link == "modbus":
            if frame.arbitration_id != self.motor_id:
                raise ProtocolError(f"{frame!r} is not from slave {self.motor_id}", raw=data)
            return decode_modbus_reply(ModbusFraming().encode(frame), model=self.model)
        if frame.arbitration_id != self.host_id:
            raise ProtocolError(
                f"{frame!r} is not on the host id {self.host_id}", raw=data, motor_id=self.motor_id
            )
        fd = frame.is_fd or frame.is_serial
        fast = self._fast_fd if fd else self._fast_ext if len(data) == 8 else self._fast_classic
        try:
            return fast(data)
        except Slow:
            pass
        return decode_reply(
            frame.arbitration_id, data, is_extended_id=frame.is_extended_id, is_fd=fd, model=self.model
        )


class TransparentFraming:
    """The converter's transparent mode: ``ID | 16 bytes | CRC-32`` <-> Frame(ID byte, 16 bytes)."""

    name = "hollow-transparent"

    def encode(self, frame: Frame) -> bytes:
        """The 21 bytes on the wire.

        Raises:
            ValueError: an ID above 255 or a body that is not 16 bytes.
        """
        return encode_transparent(frame.arbitration_id, frame.data)

    def deframer(self) -> _SerialFrames:
        """A de-framer of received bytes into Frames (CRC checked, noise counted)."""
        return _SerialFrames(HollowTransparentDeframer(), trailer=4)


class ModbusFraming:
    """Modbus RTU: ``slave | function ... | CRC-16`` <-> Frame(slave, function and the rest)."""

    name = "hollow-modbus-rtu"

    def encode(self, frame: Frame) -> bytes:
        """The frame on the wire: address, body, CRC-16/MODBUS low byte first."""
        head = bytes([frame.arbitration_id]) + frame.data
        return head + crc16_modbus(head).to_bytes(2, "little")

    def deframer(self) -> _SerialFrames:
        """A de-framer of received replies into Frames (CRC checked, noise counted)."""
        return _SerialFrames(ModbusRtuDeframer("replies"), trailer=2)


class _SerialFrames:
    """A byte de-framer whose whole frames become serial Frames: address byte, body, no check."""

    __slots__ = ("_inner", "_trailer")

    def __init__(self, inner: Any, *, trailer: int) -> None:
        self._inner = inner
        self._trailer = trailer

    def _frames(self, raws: list[bytes]) -> list[Frame]:
        end = -self._trailer
        return [Frame(arbitration_id=raw[0], data=raw[1:end], is_serial=True) for raw in raws]

    def feed(self, data: bytes) -> list[Frame]:
        return self._frames(self._inner.feed(data))

    def idle(self) -> list[Frame]:
        return self._frames(self._inner.idle())

    @property
    def discarded_bytes(self) -> int:
        """Bytes dropped as noise (the serial transport's ``stats()`` reads it)."""
        return int(self._inner.discarded_bytes)

    @property
    def crc_errors(self) -> int:
        """Frames that failed their check (the serial transport's ``stats()`` reads it)."""
        return int(self._inner.crc_errors)


def bind(
    motor_id: int,
    *,
    revision: Any = None,
    model: HollowModel | None = None,
    link: str = "can",
    host_id: int = DEFAULT_HOST_ID,
) -> HollowCodec:
    """The codec of hollow motor ``motor_id``.

    Args:
        motor_id: 0..100 (the console's CAN id).
        revision: the one revision, HO_SERIES (default).
        model: the motor model's scales (default: the default model).
        link: ``"can"``, ``"canfd"`` or ``"rs485"`` (the converter's transparent mode).
        host_id: the id the motors reply on (console item h, default 100).

    Raises:
        ValueError: an id out of range, an unknown revision or link, or a model that is not a HollowModel.
    """
    rev = find_revision("hollow", REVISIONS, revision) if revision is not None else REVISIONS[0]
    if link not in LINKS:
        raise ValueError(f"hollow has no link {link!r} (links: {', '.join(LINKS)})")
    model = DEFAULT_MODEL if model is None else model
    if not isinstance(model, HollowModel):
        raise ValueError(f"model={model!r} is not a HollowModel")
    if motor_id not in _MOTOR_IDS or isinstance(motor_id, bool):
        raise ValueError(f"motor_id={motor_id!r} is outside [0, 100]")
    return HollowCodec(motor_id, rev, model, link, host_id)


def broadcast(command: Command, motors: Sequence[HollowCodec]) -> Broadcast:
    """Hollow motors have no broadcast frame (§3: each request addresses one motor id).

    Raises:
        ValueError: always.
    """
    raise ValueError("hollow motors have no broadcast frame: send to each motor")

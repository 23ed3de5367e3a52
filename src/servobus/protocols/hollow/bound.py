"""One hollow motor's codec on Frames (protocols/_bound.py's contract): ``FAMILY.bind(3, link="canfd")``.

Links:

* ``"can"``: classic CAN. Set-points and special commands on the motor id (11-bit), the mode switch
  and PI frames on the same number as a 29-bit id; the reply (6 bytes in normal mode, 8 in extended)
  comes on the host id with the motor id in D0.
* ``"canfd"``: the 16-byte CAN FD control frame on the motor id (and the PI frames, 29-bit); the
  reply comes on the host id with the Slave ID in D15.
* ``"rs485"``: the RS-485 -> CANFD converter in transparent mode (§9.4). It carries the CAN FD frame
  as it is, so a Frame here is the FD frame (``arbitration_id`` = the ID byte, ``data`` = the 16 bytes)
  and the framing adds the CRC-32.

Every request is answered once (§3, "one request, one reply"), and all motors reply on the one host
id, so a reply's key is (host id, motor id from the payload). The host id is every hollow motor's
shared identifier: a motor whose own id equals it is refused on a bus with others.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import Any

from servobus.codec import HollowTransparentDeframer
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols._bound import EXTENDED, Broadcast, FrameKind, frame_key
from servobus.protocols._fast import Slow, maker
from servobus.protocols._message import Command, Reply
from servobus.protocols.hollow.codec import decode_reply
from servobus.protocols.hollow.commands import CanModeSwitch, HollowCommand
from servobus.protocols.hollow.commands_fd import (
    FD_PAYLOAD_SIZE,
    fd_position_limits_deg,
    fd_velocity_limits_rpm,
)
from servobus.protocols.hollow.ids import DEFAULT_HOST_ID, check_host_id, check_motor_id
from servobus.protocols.hollow.model import DEFAULT_MODEL, HollowModel, packers
from servobus.protocols.hollow.replies import ExtendedReply, FdReply, NormalReply
from servobus.protocols.hollow.rs485 import encode_transparent

__all__ = ["LINKS", "HollowCodec", "TransparentFraming", "bind", "broadcast"]

LINKS = ("can", "canfd", "rs485")

#: §3: the motor answers within 500 µs; the converter adds a serial round trip at 1 Mbaud.
DEFAULT_TIMEOUT_S = {"can": 0.01, "canfd": 0.01, "rs485": 0.02}
_MOTOR_IDS = range(0, 101)
_TEMPERATURE = (-128, 127)


def _classic_decoder(model: HollowModel, extended: bool) -> Callable[[bytes], Any]:
    """Normal (6 B) or extended (8 B) reply through the model's packer, unvalidated; Slow when in doubt."""
    packer = packers(model).extended_reply if extended else packers(model).normal_reply
    unpack = packer.unpack
    size = 8 if extended else 6
    cls = ExtendedReply if extended else NormalReply
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
        if member is None or not (p_lo <= position <= p_hi and v_lo <= velocity <= v_hi):
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


class HollowCodec:
    """One hollow motor on one link. Build it with :func:`bind` (or ``FAMILY.bind``)."""

    family = "hollow"

    __slots__ = (
        "_fast_classic",
        "_fast_ext",
        "_fast_fd",
        "_fd",
        "_key",
        "framing",
        "host_id",
        "link",
        "model",
        "motor_id",
        "reply_ids",
        "request_ids",
        "revision",
        "shared_ids",
    )

    def __init__(self, motor_id: int, revision: Any, model: HollowModel, link: str, host_id: int) -> None:
        self.motor_id = check_motor_id(motor_id)
        self.host_id = check_host_id(host_id)
        self.revision = revision
        self.model = model
        self.link = link
        self._fd = link != "can"
        self._key = frame_key(host_id, motor_id)
        self.request_ids = frozenset({motor_id, motor_id | EXTENDED})
        self.reply_ids: frozenset[int] = frozenset()
        self.shared_ids = frozenset({host_id})
        self.framing: TransparentFraming | None = TransparentFraming() if link == "rs485" else None
        self._fast_classic = _classic_decoder(model, extended=False)
        self._fast_ext = _classic_decoder(model, extended=True)
        self._fast_fd = _fd_decoder(model)

    def __repr__(self) -> str:
        return f"<hollow motor {self.motor_id} {self.link}, host id {self.host_id}>"

    @property
    def streams(self) -> frozenset[int]:
        """Always empty: hollow motors only answer."""
        return frozenset()

    def _check(self, command: Command) -> HollowCommand:
        if not isinstance(command, HollowCommand):
            raise ValueError(f"{command!r} is not a hollow command")
        if self._fd:
            if not command.FD and not command.EXTENDED_ID:
                raise ValueError(
                    f"{type(command).__name__} is a classic-CAN frame; a {self.link} motor takes FD"
                )
            if isinstance(command, CanModeSwitch):
                raise ValueError("a CAN FD motor has no normal/extended mode to switch (§5)")
            if self.link == "rs485" and not command.FD:
                raise ValueError(
                    f"the converter carries 16-byte FD frames only, not {type(command).__name__}"
                )
        elif command.FD:
            raise ValueError(f"{type(command).__name__} is a CAN FD frame; link='can' is classic CAN")
        model = getattr(command, "model", None)
        if model is not None and model is not self.model and model != self.model:
            raise ValueError(f"the command's model {model.name} is not this motor's {self.model.name}")
        return command

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor.

        Raises:
            ValueError: not a hollow command, or a frame kind this link does not carry.
        """
        message = self._check(command)
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
        """(host id, motor id): every request is answered once.

        Raises:
            ValueError: as :meth:`encode`.
        """
        self._check(command)
        return self._key

    def timeout_s(self, command: Command) -> float:
        """How long to wait for the reply to ``command``."""
        return DEFAULT_TIMEOUT_S[self.link]

    def retry_safe(self, command: Command) -> bool:
        """False: every hollow request is a set-point or a mode change; none is a pure read."""
        return False

    def note_sent(self, command: Command) -> None:
        """Nothing a hollow command changes alters how its frames are classified."""

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """REPLY for a received frame on the host id whose payload names this motor, else NOT_OURS."""
        if frame.arbitration_id != self.host_id or not frame.is_rx or frame.is_extended_id:
            return FrameKind.NOT_OURS, None
        data = frame.data
        if frame.is_fd:
            if len(data) == FD_PAYLOAD_SIZE and data[15] == self.motor_id:
                return FrameKind.REPLY, self._key
        elif len(data) in (6, 8) and data[0] == self.motor_id:
            return FrameKind.REPLY, self._key
        return FrameKind.NOT_OURS, None

    def decode(self, frame: Frame) -> Reply:
        """The typed reply in ``frame``.

        Raises:
            ProtocolError: bytes that do not decode, or a frame that is not this motor's reply.
        """
        data = frame.data
        if frame.arbitration_id != self.host_id:
            raise ProtocolError(
                f"{frame!r} is not on the host id {self.host_id}", raw=data, motor_id=self.motor_id
            )
        fast = self._fast_fd if frame.is_fd else self._fast_ext if len(data) == 8 else self._fast_classic
        try:
            return fast(data)
        except Slow:
            pass
        return decode_reply(
            frame.arbitration_id,
            data,
            is_extended_id=frame.is_extended_id,
            is_fd=frame.is_fd,
            model=self.model,
        )

    def decode_many(self, frames: Sequence[Frame]) -> list[Reply]:
        """:meth:`decode` of each frame."""
        return [self.decode(f) for f in frames]


class TransparentFraming:
    """The converter's transparent mode: ``ID | 16 bytes | CRC-32`` <-> FD Frame(ID byte, 16 bytes)."""

    name = "hollow-transparent"

    def encode(self, frame: Frame) -> bytes:
        """The 21 bytes on the wire.

        Raises:
            ValueError: an ID above 255 or data not 16 bytes.
        """
        return encode_transparent(frame.arbitration_id, frame.data)

    def deframer(self) -> _TransparentFrameDeframer:
        """A de-framer of received bytes into FD Frames (CRC checked, noise counted)."""
        return _TransparentFrameDeframer()


class _TransparentFrameDeframer:
    __slots__ = ("_inner",)

    def __init__(self) -> None:
        self._inner = HollowTransparentDeframer()

    def feed(self, data: bytes) -> list[Frame]:
        return [Frame(arbitration_id=raw[0], data=raw[1:17], is_fd=True) for raw in self._inner.feed(data)]

    def idle(self) -> list[Frame]:
        return [Frame(arbitration_id=raw[0], data=raw[1:17], is_fd=True) for raw in self._inner.idle()]


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
    from servobus.protocols.hollow import FAMILY

    rev = FAMILY.revision(revision) if revision is not None else FAMILY.default_revision
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

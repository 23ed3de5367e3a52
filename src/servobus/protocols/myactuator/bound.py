"""One MyActuator motor's codec on Frames (protocols/_bound.py's contract): ``FAMILY.bind(3)``.

Links: ``"can"`` (0x140/0x240 + ID, motion mode on 0x400/0x500 + ID, 0x79 on 0x300) and ``"rs485"`` (the
0x3E frame; a serial Frame's ``arbitration_id`` is the ID byte and ``data`` the 8 DATA bytes). RS485 motion
frames (FE EE) are refused on the rs485 link: their size and CRC are not known well enough to cut them
out of a byte stream (myactuator-v4.md §6), so no transport could receive their replies.

Classification tracks two things the motor's configuration changes, told through ``note_sent``:

* 0xB6 streams: a frame with a streamed command's DATA[0] is STREAM, even while a request for that
  command waits (the motor answers no request while it streams, §4.36 and spec ambiguity 18; the Bus
  may take the first stream frame after its request left as the fresh answer).
* 0x20 index 3 (error reporting): a 0x9A frame is REPORT (sent every 100 ms while an error lasts),
  never taken as a reply by classification alone.

And one thing the motor tells of itself: a 0xF1 frame (``CommunicationTimeoutTripped``, REPORT) says its
0xB3 protection tripped, and the first command after that is echoed, not executed. From an 0xF1 until
the motor's next reply-shaped frame the codec is ``echoing``, and ``may_echo`` is True for every command
(a stop's real reply is its own bytes too); for control commands it always is (``NEVER_ECHOED``).
"""

from __future__ import annotations

from array import array
from collections.abc import Callable, Hashable, Sequence
from typing import Any

from servobus.errors import ProtocolError
from servobus.frame import Frame, classic_request
from servobus.protocols._bound import (
    KIND_NOT_OURS,
    KIND_REPLY,
    KIND_REPORT,
    KIND_STREAM,
    Broadcast,
    CodecBase,
    FrameKind,
    check_bus,
    echo_key,
    frame_key,
    motor_ids_of,
)
from servobus.protocols._family import find_revision
from servobus.protocols._fast import Slow, maker
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import commands as cmd
from servobus.protocols.myactuator import replies as rep
from servobus.protocols.myactuator._fast import (
    compile_fixed,
    compile_fixed_encoder,
    motion_command_encoder,
    motion_reply_decoder,
)
from servobus.protocols.myactuator._layout import PAYLOAD_SIZE, Fixed, MyActuatorMessage
from servobus.protocols.myactuator.codec import (
    COMMANDS,
    NO_REPLY,
    REPLIES,
    check_available,
    decode_reply,
    decode_standard_reply,
)
from servobus.protocols.myactuator.enums import FunctionIndex
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_CODE,
    ID_SETTING_ID,
    RS485_BROADCAST_ID,
    check_motor_id,
    motion_reply_id,
    motion_request_id,
    reply_id,
    request_id,
)
from servobus.protocols.myactuator.motion import (
    MOTION_SCALES,
    MotionCommand,
    MotionReply,
    MotionScales,
    reply_packer,
)
from servobus.protocols.myactuator.restart import RESTART
from servobus.protocols.myactuator.revision import Revision
from servobus.protocols.myactuator.rs485 import RS485_FRAME_SIZE, encode_rs485, rs485_deframer
from servobus.protocols.myactuator.rs485_motion import Rs485MotionCommand

__all__ = ["LINKS", "MyActuatorCodec", "Rs485Framing", "bind", "broadcast"]

LINKS = ("can", "rs485")
#: the revisions, the default first (the Family\'s)
REVISIONS = (Revision.V4_4, Revision.V4_3)

#: Reply timeouts. A motor answers within a millisecond on CAN; the default leaves room for a loaded
#: bus. Writes to ROM/flash and the brake take longer (tens of ms on the bench, not stated in the manual).
DEFAULT_TIMEOUT_S = {"can": 0.02, "rs485": 0.05}
SLOW_TIMEOUT_S = 0.5
# Each command class declares READ, SLOW, ECHO and NOTED once (protocols/_message.py); the bound codec
# reads them per class, and caches the answer (the hot path asks per request).
_IS_SLOW: dict[type, bool] = {}
_IS_READ: dict[type, bool] = {}
_IS_NOTED: dict[type, bool] = {}
_ERROR_REPORT_CODE = cmd.ReadStatus1.CODE
_EVENT_CODES = frozenset(event.CODE for event in rep.EVENTS)
#: Echo replies that carry the value their request wrote (§0, declared ``ECHO``): keyed with it
#: (``echo_key``). Not the fixed all-zero echoes (nothing to tell apart), 0xB3 (the manuals print an
#: all-zero reply to it, §9 item 8) nor 0x79 (its reply comes on a shared identifier).
_VALUE_ECHO_CODES = frozenset(c.CODE for c in COMMANDS if c.ECHO)
_SPECIAL_CODES = _VALUE_ECHO_CODES | _EVENT_CODES


def _fast_table(revision: Revision) -> dict[int, Callable[[bytes], Any]]:
    """DATA[0] -> fast decoder, for the codes with one layout in ``revision`` that compiles."""
    table: dict[int, Callable[[bytes], Any]] = {}
    for code, layouts in REPLIES.items():
        candidates = [layout for layout in layouts if revision in layout.revisions]
        if len(candidates) != 1 or not issubclass(candidates[0].message, Fixed):
            continue
        if getattr(candidates[0].decode, "__func__", None) is not getattr(
            candidates[0].message.decode, "__func__", 0
        ):
            continue  # echoes decode through their command class
        fast = compile_fixed(candidates[0].message)
        if fast is not None:
            table[code] = fast
    return table


_FAST: dict[Revision, dict[int, Callable[[bytes], Any]]] = {r: _fast_table(r) for r in Revision}


def _class_plan(cls: type, revision: Revision) -> tuple[bool, Callable[[Any], bytes] | None]:
    """(available in ``revision`` whatever its values, fast encoder or None) for a command class."""
    per_instance = cls.unavailable_reason is not MyActuatorMessage.unavailable_reason  # type: ignore[attr-defined]
    # Motion commands are checked per instance: their scales must be the motor's.
    always = (
        not per_instance and revision in getattr(cls, "REVISIONS", ()) and not issubclass(cls, MotionCommand)
    )
    # 0x79 goes to 0x300 (RS485: 0xCD), not to the motor's request identifier.
    to_motor = issubclass(cls, Fixed) and not issubclass(cls, cmd.SetCanId | cmd.ReadCanId)
    fast = compile_fixed_encoder(cls) if to_motor else None
    return always, fast


_PLANS: dict[Revision, dict[type, tuple[bool, Callable[[Any], bytes] | None]]] = {}  # by revision, then class


class MyActuatorCodec(CodecBase):
    """One MyActuator motor on one link. Build it with :func:`bind` (or ``FAMILY.bind``)."""

    family = "myactuator"
    RESTART = RESTART  # what proves a restart (servobus.bus.restarts)
    SAFE_COMMANDS = {  # noqa: RUF012 - a class table, not per instance
        "stop": lambda codec: cmd.MotorStop(),
        "shutdown": lambda codec: cmd.MotorShutdown(),
        "brake": lambda codec: cmd.BrakeLock(),
    }
    revision: Revision
    model: MotionScales

    __slots__ = (
        "_fast",
        "_has_id_setting",
        "_motion_encode",
        "_motion_fast",
        "_motion_key",
        "_motion_reply_id",
        "_motion_request_id",
        "_plans",
        "_reply_base",
        "_reply_id",
        "_reports",
        "_request_id",
        "_rs485",
        "_streams",
        "echoing",
    )

    def __init__(self, motor_id: int, revision: Revision, scales: MotionScales, link: str) -> None:
        self.motor_id = check_motor_id(motor_id)
        self.revision = revision
        self.model = scales
        self.link = link
        self._rs485 = link == "rs485"
        self._has_id_setting = revision in cmd.SetCanId.REVISIONS
        self._streams: frozenset[int] = frozenset()
        self._reports = False
        self.echoing = False
        self._fast = _FAST[revision]
        self._plans = _PLANS.setdefault(revision, {})
        self._motion_fast = motion_reply_decoder(scales, motor_id)
        self._motion_encode = motion_command_encoder(scales)
        if self._rs485:
            self._reply_id = self._request_id = motor_id
            self._motion_reply_id = self._motion_request_id = -1
            self.request_ids = self.reply_ids = frozenset({motor_id})
            self.shared_ids = frozenset({RS485_BROADCAST_ID})
            self.framing: Rs485Framing | None = Rs485Framing()
        else:
            self._reply_id = reply_id(motor_id)
            self._request_id = request_id(motor_id)
            self._motion_reply_id = motion_reply_id(motor_id)
            self._motion_request_id = motion_request_id(motor_id)
            self.request_ids = frozenset({request_id(motor_id), motion_request_id(motor_id)})
            self.reply_ids = frozenset({self._reply_id, self._motion_reply_id})
            self.shared_ids = frozenset({BROADCAST_ID, ID_SETTING_ID})
            self.framing = None
        self._reply_base = frame_key(self._reply_id, 0)
        self._motion_key = frame_key(self._motion_reply_id) if not self._rs485 else None

    @property
    def streams(self) -> frozenset[int]:
        """The command bytes the motor streams (0xB6), as far as this codec was told."""
        return self._streams

    # ---- sending ----

    def _plan(self, command: Command) -> tuple[bool, Callable[[Any], bytes] | None]:
        plan = self._plans.get(type(command))  # (by class alone: an Enum key hashes in Python)
        if plan is None:
            if not isinstance(command, MyActuatorMessage) or not isinstance(command, Command):
                raise ValueError(f"{command!r} is not a MyActuator command")
            if isinstance(command, Rs485MotionCommand):
                raise ValueError("the RS485 motion frame (FE EE) goes on no bound link (myactuator-v4.md §6)")
            plan = self._plans[type(command)] = _class_plan(type(command), self.revision)
        return plan

    def _check(self, command: Command) -> MyActuatorMessage:
        always, _ = self._plan(command)
        if always:
            return command  # type: ignore[return-value]
        if isinstance(command, MotionCommand):
            if self._rs485:
                raise ValueError("motion mode on RS485 (FE EE frames) is not supported on the rs485 link")
            if command.scales is not self.model and command.scales != self.model:
                raise ValueError(
                    f"the command's motion scales {command.scales} are not this motor's {self.model}"
                )
        else:
            check_available(command, self.revision)  # type: ignore[arg-type]
        return command  # type: ignore[return-value]

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor.

        Raises:
            ValueError: not a MyActuator command, a command this revision or link does not have, or
                motion scales other than the motor's.
        """
        if type(command) is MotionCommand and command.scales is self.model and not self._rs485:
            # 8 bytes the encoder made, on the motor's own identifier: nothing for Frame() to check
            return classic_request(self._motion_request_id, self._motion_encode(command))
        always, fast = self._plan(command)
        if always and fast is not None and not self._rs485:
            return classic_request(self._request_id, fast(command))
        message = self._check(command)
        if self._rs485:
            if isinstance(message, cmd.ActiveReply):
                raise ValueError("0xB6 active reply is CAN only: RS485 does not support it (§4.36)")
            is_id = isinstance(message, cmd.SetCanId | cmd.ReadCanId)
            address = RS485_BROADCAST_ID if is_id else self.motor_id
            return Frame(arbitration_id=address, data=message.encode(), is_serial=True, is_rx=False)
        if isinstance(message, MotionCommand):
            # 8 bytes the encoder made, on the motor's own identifier: nothing for Frame() to check
            return classic_request(self._motion_request_id, self._motion_encode(message))
        elif isinstance(message, cmd.SetCanId | cmd.ReadCanId):
            ident = ID_SETTING_ID
        else:
            ident = request_id(self.motor_id)
        return Frame(arbitration_id=ident, data=message.encode(), is_rx=False)

    def reply_key(self, command: Command) -> Hashable | None:
        """The key of the reply to ``command``, or None for 0x76, 0xB4 and 0xB6 (no reply), and for
        every command but a read of a streamed one while the motor streams (it answers none then,
        §4.36 and spec ambiguity 18: the command is executed, its reply never comes).

        Raises:
            ValueError: as :meth:`encode`.
        """
        message = self._check(command)
        if isinstance(message, MotionCommand):
            return None if self._streams else self._motion_key
        code = message.code
        assert code is not None
        if code in NO_REPLY or (self._streams and code not in self._streams):
            return None
        if code == ID_SETTING_CODE:
            return frame_key(RS485_BROADCAST_ID if self._rs485 else ID_SETTING_ID, ID_SETTING_CODE)
        if code in _VALUE_ECHO_CODES:
            return echo_key(self._reply_base | code, message.encode())
        return self._reply_base | code

    def timeout_s(self, command: Command) -> float:
        """How long to wait for the reply to ``command``."""
        slow = _IS_SLOW.get(type(command))
        if slow is None:
            slow = _IS_SLOW[type(command)] = command.SLOW
        return SLOW_TIMEOUT_S if slow else DEFAULT_TIMEOUT_S[self.link]

    def retry_safe(self, command: Command) -> bool:
        """True for reads: resending them changes nothing on the motor."""
        read = _IS_READ.get(type(command))
        if read is None:
            read = _IS_READ[type(command)] = command.READ
        return read

    def note_sent(self, command: Command) -> None:
        """Track what ``command`` changes in how the motor talks (0xB6 streams, 0x9A reports, reset)."""
        noted = _IS_NOTED.get(type(command))
        if noted is None:
            noted = _IS_NOTED[type(command)] = command.NOTED
        if not noted:
            return
        if isinstance(command, cmd.ActiveReply):
            code = int(command.command)
            self._streams = self._streams | {code} if command.enabled else self._streams - {code}
        elif isinstance(command, cmd.FunctionControl) and command.index is FunctionIndex.ERROR_REPORTING:
            self._reports = command.value == 1
        elif isinstance(command, cmd.SystemReset):
            self._streams = frozenset()  # streams are RAM settings: a restart ends them

    # ---- receiving ----

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """What ``frame`` is to this motor, from its identifier and DATA[0].

        ``(REPLY, None)`` is a frame on this motor's reply identifier that can answer nothing (empty).
        """
        if not frame.is_rx or frame.is_extended_id or frame.is_fd or frame.is_serial is not self._rs485:
            return KIND_NOT_OURS, None
        ident = frame.arbitration_id
        data = frame.data
        if ident == self._reply_id:
            if not data:
                return KIND_REPLY, None
            code = data[0]
            if code in self._streams:
                return KIND_STREAM, self._reply_base | code
            if code == _ERROR_REPORT_CODE and self._reports:
                return KIND_REPORT, self._reply_base | code
            if code in _SPECIAL_CODES:  # (one look-up on the hot path for both kinds)
                if code in _EVENT_CODES:
                    self.echoing = True  # the next command is echoed, not executed
                    return KIND_REPORT, self._reply_base | code
                self.echoing = False
                return KIND_REPLY, echo_key(self._reply_base | code, data)
            if self.echoing:
                self.echoing = False  # the motor answers again: past the echo
            return KIND_REPLY, self._reply_base | code
        if ident == self._motion_reply_id:
            self.echoing = False
            return KIND_REPLY, self._motion_key
        # 0x79 replies come on an identifier every motor shares, so one 0x79 exchange at a time per
        # bus; and only a revision that has 0x79 claims them.
        shared = RS485_BROADCAST_ID if self._rs485 else ID_SETTING_ID
        if ident == shared and data and data[0] == ID_SETTING_CODE and self._has_id_setting:
            return KIND_REPLY, frame_key(shared, ID_SETTING_CODE)
        return KIND_NOT_OURS, None

    def request_key(self, frame: Frame) -> Hashable | None:
        """The key of the reply to ``frame`` if it is another host's request to this motor (on
        0x140+ID or 0x400+ID, received: not our own frame looped back), as :meth:`reply_key` would
        give for the command it carries; None on RS485 (request and reply share the address)."""
        if self._rs485 or not frame.is_rx or frame.is_extended_id or frame.is_fd or frame.is_serial:
            return None
        ident = frame.arbitration_id
        if ident == self._motion_request_id:
            return None if self._streams else self._motion_key
        data = frame.data
        if ident != self._request_id or not data:
            return None
        code = data[0]
        if code in NO_REPLY or (self._streams and code not in self._streams):
            return None
        if code in _VALUE_ECHO_CODES:
            return echo_key(self._reply_base | code, data)
        return self._reply_base | code

    def decode(self, frame: Frame) -> Reply:
        """The typed reply in ``frame`` (a frame :meth:`classify` did not call NOT_OURS).

        Raises:
            ProtocolError: the bytes do not decode for this motor's revision, or the frame is not one of
                this motor's (the error names the motor).
        """
        data = frame.data
        ident = frame.arbitration_id
        if ident == self._reply_id and data:
            fast = self._fast.get(data[0])
            if fast is not None:
                try:
                    return fast(data)  # type: ignore[no-any-return]
                except Slow:
                    pass
            if not self._rs485:
                return decode_reply(ident, data, revision=self.revision, motion_scales=self.model)
            try:
                return decode_standard_reply(data, self.revision)
            except ProtocolError as exc:
                raise exc.with_context(motor_id=self.motor_id) from None
        if ident == self._motion_reply_id:
            try:
                return self._motion_fast(data)  # type: ignore[no-any-return]
            except Slow:
                return decode_reply(ident, data, revision=self.revision, motion_scales=self.model)
        if self._rs485 and ident == RS485_BROADCAST_ID and data[:1] == bytes([ID_SETTING_CODE]):
            return decode_standard_reply(data, self.revision)
        if not self._rs485 and ident == ID_SETTING_ID:
            return decode_reply(ident, data, revision=self.revision)
        raise ProtocolError(f"{frame!r} is not a frame of this motor", raw=data, motor_id=self.motor_id)

    def decode_many(self, frames: Sequence[Frame]) -> list[Reply]:
        """:meth:`decode` of each frame; motion replies go through the C core in one call."""
        if frames and all(f.arbitration_id == self._motion_reply_id for f in frames):
            return _decode_motion_batch(self, frames)
        return [self.decode(f) for f in frames]


def _decode_motion_batch(codec: MyActuatorCodec, frames: Sequence[Frame]) -> list[Reply]:
    """Motion replies in one C-core call; any frame that is not a plain 8-byte reply of this motor
    sends the whole batch through :meth:`MyActuatorCodec.decode`, frame by frame."""
    motor_id = codec.motor_id
    datas = [f.data for f in frames]
    joined = b"".join(datas)
    n = len(datas)
    if len(joined) != PAYLOAD_SIZE * n or any(d[0] != motor_id for d in datas):
        return [codec.decode(f) for f in frames]
    packer = reply_packer(codec.model)
    values = array("d", bytes(8 * 4 * n))
    packer.unpack_into(joined, values)
    _, ps, vs, ts = packer.scales
    p_hi, v_hi, t_hi, scales, make = ps.hi, vs.hi, ts.hi, codec.model, _MAKE_MOTION
    # Codes decode into [lo, hi + 1 ulp]: only the top needs the clamp MotionReply.decode applies.
    it = iter(values)
    return [
        make(motor_id, p if p <= p_hi else p_hi, v if v <= v_hi else v_hi, t if t <= t_hi else t_hi, scales)
        for _, p, v, t in zip(it, it, it, it, strict=True)
    ]


_MAKE_MOTION = maker(MotionReply, ("motor_id", "position_rad", "velocity_rad_s", "torque_nm", "scales"))


class Rs485Framing:
    """The 0x3E frame: ``3E ID 08 DATA[8] CRC16`` <-> serial Frame(ID byte, 8 DATA bytes)."""

    name = "myactuator-rs485"
    frame_size = RS485_FRAME_SIZE

    def encode(self, frame: Frame) -> bytes:
        """The 13 bytes on the wire.

        Raises:
            ValueError: an ID byte that is neither 1..32 nor 0xCD, or DATA not 8 bytes.
        """
        return encode_rs485(frame.arbitration_id, frame.data)

    def deframer(self) -> _Rs485FrameDeframer:
        """A de-framer of received bytes into Frames (CRC checked, noise counted)."""
        return _Rs485FrameDeframer()


class _Rs485FrameDeframer:
    __slots__ = ("_inner",)

    def __init__(self) -> None:
        self._inner = rs485_deframer()

    def feed(self, data: bytes) -> list[Frame]:
        return [
            Frame(arbitration_id=raw[1], data=raw[3:-2], is_serial=True) for raw in self._inner.feed(data)
        ]

    def idle(self) -> list[Frame]:
        return [Frame(arbitration_id=raw[1], data=raw[3:-2], is_serial=True) for raw in self._inner.idle()]

    @property
    def discarded_bytes(self) -> int:
        """Bytes dropped as noise (the serial transport's ``stats()`` reads it)."""
        return self._inner.discarded_bytes

    @property
    def crc_errors(self) -> int:
        """Frames that failed their check (the serial transport's ``stats()`` reads it)."""
        return self._inner.crc_errors


def bind(
    motor_id: int,
    *,
    revision: Revision | str | None = None,
    model: MotionScales | None = None,
    link: str = "can",
) -> MyActuatorCodec:
    """The codec of MyActuator motor ``motor_id``.

    Args:
        motor_id: 1..32.
        revision: V4_4 (default) or V4_3, as a Revision or its name.
        model: the motor's motion-mode ranges (default: the revision's; V4.4's torque range is
            model-specific, see ``MotionScales.for_revision``).
        link: ``"can"`` or ``"rs485"``.

    Raises:
        ValueError: an id outside 1..32, an unknown revision or link.
    """
    rev: Revision = (
        find_revision("myactuator", REVISIONS, revision) if revision is not None else Revision.V4_4
    )
    if link not in LINKS:
        raise ValueError(f"myactuator has no link {link!r} (links: {', '.join(LINKS)})")
    scales = MOTION_SCALES[rev] if model is None else model
    if not isinstance(scales, MotionScales):
        raise ValueError(f"model={model!r} is not a MotionScales")
    return MyActuatorCodec(motor_id, rev, scales, link)


def broadcast(command: Command, motors: Sequence[MyActuatorCodec]) -> Broadcast:
    """One frame to every motor: 0x280 on CAN, ID byte 0xCD on RS485; each motor replies as to its own.

    Args:
        command: a standard command (not motion mode, not 0x79, which always goes to every motor).
        motors: the bound codecs of the motors whose replies to gather (all on one link).

    Raises:
        ValueError: a motion or 0x79 command, a command one motor's revision lacks, mixed links.
    """
    if not motors:
        raise ValueError("broadcast needs at least one motor")
    motor_ids_of(motors)
    check_bus(motors)
    links = {m.link for m in motors}
    if len(links) != 1 or not all(isinstance(m, MyActuatorCodec) for m in motors):
        raise ValueError("a broadcast goes to MyActuator motors on one link")
    if isinstance(command, MotionCommand | cmd.SetCanId | cmd.ReadCanId) or not isinstance(
        command, MyActuatorMessage
    ):
        raise ValueError(f"{type(command).__name__} has no broadcast form")
    if isinstance(command, cmd.FunctionControl) and command.index is FunctionIndex.SET_CAN_ID:
        raise ValueError("0x20 index 5 sets the CAN id: broadcast, every motor would take the same id")
    keys = {m.motor_id: m.reply_key(command) for m in motors}
    frame = motors[0].encode(command)
    rs485 = links == {"rs485"}
    if rs485 and isinstance(command, cmd.ActiveReply):
        raise ValueError("0xB6 active reply is CAN only")
    ident = RS485_BROADCAST_ID if rs485 else BROADCAST_ID
    replies = {m: k for m, k in keys.items() if k is not None}
    return Broadcast(Frame(arbitration_id=ident, data=frame.data, is_serial=rs485, is_rx=False), replies)

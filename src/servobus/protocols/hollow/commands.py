"""Classic-CAN requests of the hollow series (hollow.md §4-§6): special commands, setpoints, the
extended-id mode switch and the PI multiplier frames; and the enums requests and replies share.

Frames are told apart by identifier kind and content, not by a DATA[0] command byte:

* standard id, 8 bytes, ``FF x7 + F9..FE``: a special command (§4.1);
* standard id, 8 bytes, anything else: a setpoint, absolute in normal mode (§4.2) and an increment in
  extended mode (§5.2) - the bytes are the same, the motor's CAN mode decides;
* extended id, D0 = 0x00 and D1 = 0x01..0x04: a PI multiplier frame (§6);
* extended id, otherwise: the normal/extended mode switch (§5.1).

Each class says which identifier kind and frame type it travels in (``EXTENDED_ID``, ``FD``), so a
transport can build the frame (:func:`servobus.protocols.hollow.codec.request_frame`); the links of
the bound codec that carry it (``LINKS``); its reply type (the argument of its base); and, in
:meth:`HollowCommand.claims`, which bytes of its frame kind are it. The codec's decoders and the
bound codec's checks are derived from these classes, so a new request is one class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Self

from servobus.core import FieldScale
from servobus.errors import ProtocolError
from servobus.protocols._layout import EnumField, Float32BEField, Layout
from servobus.protocols._message import Command, R
from servobus.protocols.bits import BitField, BitLayout, Code, Const
from servobus.protocols.hollow._checks import require_size, to_enum
from servobus.protocols.hollow._packed import OnLinks, Packed, check_model
from servobus.protocols.hollow.enums import CanMode, ControlMode, PiGain
from servobus.protocols.hollow.model import DEFAULT_MODEL, HollowModel
from servobus.protocols.hollow.replies import (
    ClassicReply,
    ExtendedReply,
    FdReply,
    NormalReply,
    classic_fields,
)

__all__ = [
    "SETPOINT_GAIN_MAX",
    "SPECIAL_CODES",
    "SPECIAL_PREFIX",
    "CanMode",
    "CanModeSwitch",
    "ControlMode",
    "HollowCommand",
    "IncrementalSetpoint",
    "PiGain",
    "PiMultiplier",
    "SelectMode",
    "SetZero",
    "Setpoint",
    "SpecialCommand",
    "Start",
    "Stop",
    "check_model",
    "claimant",
    "decode_extended_request",
    "decode_setpoint_frame",
    "decode_special",
    "is_special_command",
    "request_classes",
]

# §4.1: D0..D6 = 0xFF, D7 = the command code (A1, A2).
SPECIAL_PREFIX = b"\xff" * 7
SPECIAL_CODES = range(0xF9, 0xFF)
# §4.2 / §4.3: KP and KD are raw 12-bit codes.
SETPOINT_GAIN_MAX = 0xFFF

_SETPOINT_SIZE = 8
_MODE_SWITCH_SIZE = 8
_MODE_SWITCH_BIT = 0x02
_PI_SIZES = range(6, 9)  # A17: DLC 6 or 8; we send 8
_PI_PADDING = b"\x00\x00"

_REQUESTS: list[type[HollowCommand[Any]]] = []


def is_special_command(data: bytes) -> bool:
    """True for the special-command pattern ``FF FF FF FF FF FF FF F9..FE`` (§4.1, A35)."""
    return len(data) == _SETPOINT_SIZE and data[:7] == SPECIAL_PREFIX and data[7] in SPECIAL_CODES


class HollowCommand(OnLinks, Command[R]):
    """A host -> motor CAN or CAN FD request of the hollow family, with the frame kind it travels in.

    ``EXTENDED_ID`` (29-bit identifier) and ``FD`` (CAN FD frame) give the frame; ``LINKS`` the
    bound codec's links that carry it; :meth:`claims` which payloads of that frame kind are this
    request, so :func:`claimant` finds the class of a received frame from the classes alone.

    The RS-485 converter's frames (:mod:`~servobus.protocols.hollow.rs485`,
    :mod:`~servobus.protocols.hollow.converter`) are serial frames, not CAN requests, so they derive
    from :class:`~servobus.protocols.Command` directly.
    """

    __slots__ = ()
    EXTENDED_ID: ClassVar[bool] = False  # 29-bit identifier (mode switch, PI frames)
    FD: ClassVar[bool] = False  # CAN FD frame (16-byte control frames)
    LINKS: ClassVar[tuple[str, ...]] = ("can",)
    # Claims what no other class of its frame kind claims, so its decoder says what is wrong with
    # bytes that are no request (the setpoints, the mode switch); asked after the others.
    FALLBACK: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "__dataclass_fields__" in cls.__dict__:  # the finished (slotted) dataclass, once
            specific = sum(1 for other in _REQUESTS if not other.FALLBACK)
            _REQUESTS.insert(len(_REQUESTS) if cls.FALLBACK else specific, cls)

    @classmethod
    def claims(cls, data: bytes, can_mode: CanMode) -> bool:
        """Whether ``data``, in a frame of this class's kind to a motor in ``can_mode``, is this request."""
        return True

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode the payload (``model``: the scales, for the classes whose bytes depend on them)."""
        raise NotImplementedError(cls.__name__)


def request_classes() -> tuple[type[HollowCommand[Any]], ...]:
    """Every concrete request class, in the order :func:`claimant` asks them: in definition order, the
    fallbacks last (the codec's dispatch is derived from them)."""
    return tuple(_REQUESTS)


def claimant(data: bytes, *, extended_id: bool, fd: bool, can_mode: CanMode) -> type[HollowCommand[Any]]:
    """The request class of a received payload: the first of its frame kind that claims it, a
    ``FALLBACK`` class only if no other does.

    An extended identifier is enough for the extended-id frames, which may come classic or FD (A17).

    Raises:
        ProtocolError: no class of that frame kind claims the bytes.
    """
    for cls in _REQUESTS:
        if extended_id == cls.EXTENDED_ID and (extended_id or fd == cls.FD) and cls.claims(data, can_mode):
            return cls
    raise ProtocolError("no hollow request has this frame kind and content", raw=data)


# ---- special commands (§4.1) ----


class SpecialCommand(BitLayout, HollowCommand[ClassicReply]):
    """An 8-byte ``FF x7 + code`` command, the same in normal and extended mode (§4.1, §5.2),
    declared as a bit layout: the prefix and the code are constants (:class:`Const`), which are the
    command's identity (:meth:`claims`)."""

    __slots__ = ()
    SIZE: ClassVar[int] = _SETPOINT_SIZE
    SPECIAL_CODE: ClassVar[int]
    SPECIAL_COUNT: ClassVar[int] = 1  # how many codes from SPECIAL_CODE on are this command

    @property
    def special_code(self) -> int:
        """D7 of the frame."""
        return self.encode()[7]

    @classmethod
    def claims(cls, data: bytes, can_mode: CanMode) -> bool:
        return is_special_command(data) and cls._is_code(data[7]) and cls.matches(data)

    @classmethod
    def _is_code(cls, code: int) -> bool:
        """Whether D7 ``code`` is one of this command's (SelectMode's constants are the prefix only)."""
        return 0 <= code - cls.SPECIAL_CODE < cls.SPECIAL_COUNT

    @classmethod
    def from_code(cls, code: int) -> Self:
        """The command whose D7 is ``code`` (one of its codes)."""
        return cls.decode(SPECIAL_PREFIX + bytes([code]))

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode ``data`` as this special command.

        Raises:
            ProtocolError: not the special pattern, or another special command.
        """
        require_size(data, _SETPOINT_SIZE, what="special command")
        if not is_special_command(data):
            raise ProtocolError("not a special command (FF x7 + F9..FE)", raw=data)
        if not (cls._is_code(data[7]) and cls.matches(data)):
            raise ProtocolError(
                f"special command 0x{data[7]:02X} is not {cls.__name__}", raw=data, command=data[7]
            )
        return super().decode(data)


def _special(code: int) -> tuple[Const, Const]:
    """The FIELDS of the special command ``code``: FF x7, then the code (§4.1)."""
    return (Const((0, 56), int.from_bytes(SPECIAL_PREFIX, "big")), Const((56, 8), code))


@dataclass(frozen=True, slots=True, kw_only=True)
class Start(SpecialCommand):
    """FC: run in the selected mode with the last received setpoint (send a setpoint first).

    In extended position mode the motor locks at its present position (§5.2).
    """

    SPECIAL_CODE: ClassVar[int] = 0xFC
    FIELDS = _special(SPECIAL_CODE)


@dataclass(frozen=True, slots=True, kw_only=True)
class Stop(SpecialCommand):
    """FD: no output power, the motor is free (§4.1; bytes reconstructed, A2)."""

    SPECIAL_CODE: ClassVar[int] = 0xFD
    FIELDS = _special(SPECIAL_CODE)


@dataclass(frozen=True, slots=True, kw_only=True)
class SetZero(SpecialCommand):
    """FE: the present position becomes the mechanical zero, multi-turn count cleared.

    Only while the motor is not enabled (send :class:`Stop` first); not persisted (§4.1, A33).
    """

    SPECIAL_CODE: ClassVar[int] = 0xFE
    FIELDS = _special(SPECIAL_CODE)


@dataclass(frozen=True, slots=True, kw_only=True)
class SelectMode(SpecialCommand):
    """F9/FA/FB: switch the control mode until power-off (§4.1; D7 = 0xF9 + mode, A3).

    Attributes:
        mode: the control mode to switch to.
    """

    SPECIAL_CODE: ClassVar[int] = 0xF9  # + mode
    SPECIAL_COUNT: ClassVar[int] = len(ControlMode)
    # (D7 is the mode plus 0xF9: a scale whose code 0 is the value -0xF9)
    FIELDS = (
        _special(0)[0],
        BitField(
            "mode",
            ((56, 8),),
            FieldScale(name="mode", lo=0, hi=len(ControlMode) - 1, origin=-SPECIAL_CODE),
            ControlMode,
        ),
    )
    mode: ControlMode


def decode_special(data: bytes) -> SpecialCommand:
    """Decode an ``FF x7 + F9..FE`` frame (§4.1).

    Raises:
        ProtocolError: ``data`` is not 8 bytes of the special pattern.
    """
    require_size(data, _SETPOINT_SIZE, what="special command")
    if not is_special_command(data):
        raise ProtocolError("not a special command (FF x7 + F9..FE)", raw=data)
    cls = claimant(data, extended_id=False, fd=False, can_mode=CanMode.NORMAL)
    assert issubclass(cls, SpecialCommand)  # the special pattern is claimed by a special command
    return cls.decode(data)


# ---- setpoints (§4.2-§4.4, §5.2) ----


def _setpoint_fields(position: str) -> tuple[Any, ...]:
    # §4.2, big-endian bits: P (position or step) 16, V 12, KP 12, KD 12, T 12 (HOLLOW_SETPOINT's order).
    p, v, t = classic_fields(position, ((0, 16), (16, 12), (52, 12)))
    return (p, v, Code("kp", (28, 12), 0, SETPOINT_GAIN_MAX), Code("kd", (40, 12), 0, SETPOINT_GAIN_MAX), t)


#: what kp = 0 leaves unused in a setpoint (Command.inactive)
_POSITION = frozenset({"position_deg", "step_deg"})


class _SetpointFrame(Packed, HollowCommand[ClassicReply]):
    """The 8-byte setpoint bytes (§4.2): the motor's CAN mode tells which class they are (§5.2)."""

    __slots__ = ()
    PACKER: ClassVar[str] = "setpoint"
    SIZE: ClassVar[int] = _SETPOINT_SIZE
    CAN_MODE: ClassVar[CanMode]
    FALLBACK: ClassVar[bool] = True

    @classmethod
    def claims(cls, data: bytes, can_mode: CanMode) -> bool:
        return can_mode is cls.CAN_MODE and not is_special_command(data)

    def inactive(self) -> frozenset[str]:
        """With kp = 0 the position (or step) is not acted on: velocity and torque set-points."""
        return _POSITION if getattr(self, "kp", 1) == 0 else frozenset()

    @classmethod
    def refuse(cls, data: bytes) -> None:
        if is_special_command(data):
            # §4.1 / A35: the special pattern is checked first, so it is never a setpoint.
            raise ProtocolError(f"{cls.WHAT}: the frame is a special command", raw=data, command=data[7])


@dataclass(frozen=True, slots=True, kw_only=True)
class Setpoint(_SetpointFrame):
    """The normal-mode setpoint frame: absolute position plus limits and gains (§4.2-§4.4).

    What the motor does with each field depends on its control mode (§4.4): in position mode P is
    the target, V the maximum speed, T the maximum current, KP/KD the PD gains; in speed mode V is
    the target and T the current limit; in torque mode T is the target current.

    Encoding quantises to the 16/12-bit codes (round half away from zero, the C core's rule) and
    clamps +full scale onto the last code (§4.3). The position code 0xFFFF is lowered to 0xFFFE
    when the frame would otherwise read as a special command (§4.1, A35).

    Attributes:
        position_deg: target position from the mechanical zero, within ±360·Pmax.
        speed_rad_s: speed (target or limit), within ±ω_fs of the model.
        kp: position-loop gain code 0..4095 (0x800 is "50 %").
        kd: position-loop damping code 0..4095.
        current_a: current (target or limit), within ±I_fs of the model; torque = Kt·I.
        model: the scaling of the motor (:data:`~servobus.protocols.hollow.model.DEFAULT_MODEL`).
    """

    WHAT: ClassVar[str] = "setpoint"
    CAN_MODE: ClassVar[CanMode] = CanMode.NORMAL
    FIELDS = _setpoint_fields("position_deg")
    position_deg: float
    speed_rad_s: float
    kp: int
    kd: int
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)


@dataclass(frozen=True, slots=True, kw_only=True)
class IncrementalSetpoint(_SetpointFrame):
    """The extended-mode setpoint: the same bytes as :class:`Setpoint`, but P is a step (§5.2).

    Each frame moves the target by ``step_deg`` once (A11); a step of 0 moves nothing and polls.

    Attributes:
        step_deg: position increment, within ±360·Pmax.
        speed_rad_s, kp, kd, current_a, model: as in :class:`Setpoint`.
    """

    POSITION = "relative"  # (host-side limits: servobus.limits)

    WHAT: ClassVar[str] = "incremental setpoint"
    CAN_MODE: ClassVar[CanMode] = CanMode.EXTENDED
    FIELDS = _setpoint_fields("step_deg")
    step_deg: float
    speed_rad_s: float
    kp: int
    kd: int
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)


# ---- extended-id frames (§5.1, §6) ----


def _is_pi_frame(data: bytes) -> bool:
    # §5.1 [I]: both frames are extended with D0 = 0; a PI frame names its gain in D1 = 1..4.
    return len(data) >= 2 and data[0] == 0x00 and data[1] in PiGain._value2member_map_


@dataclass(frozen=True, slots=True, kw_only=True)
class CanModeSwitch(HollowCommand[ClassicReply]):
    """Select normal (absolute) or extended (incremental) CAN mode: extended id, DLC 8 (§5.1).

    D0 bit 1 is the mode (1 = normal, 0 = extended, A4); every other bit and byte is zero.
    Extended mode lasts until power-off. The reply's length confirms the mode (6 or 8 bytes).

    Attributes:
        mode: the CAN mode to select.
    """

    EXTENDED_ID: ClassVar[bool] = True
    FALLBACK: ClassVar[bool] = True
    mode: CanMode

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", to_enum("mode", self.mode, CanMode))

    def encode(self) -> bytes:
        return bytes([_MODE_SWITCH_BIT if self.mode is CanMode.NORMAL else 0x00]) + bytes(7)

    @classmethod
    def claims(cls, data: bytes, can_mode: CanMode) -> bool:
        return not _is_pi_frame(data)

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode the 8-byte mode switch.

        Raises:
            ProtocolError: wrong length, a PI multiplier frame, or a reserved bit/byte set (the
                manual requires D0's other bits to be zero and leaves D1..D7 unused, sent as 0).
        """
        require_size(data, _MODE_SWITCH_SIZE, what="CAN mode switch")
        if _is_pi_frame(data):
            raise ProtocolError("CAN mode switch: the frame is a PI multiplier frame", raw=data)
        if data[0] & ~_MODE_SWITCH_BIT or any(data[1:]):
            raise ProtocolError("CAN mode switch: reserved bits are not zero", raw=data, command=data[0])
        return cls(mode=CanMode.NORMAL if data[0] & _MODE_SWITCH_BIT else CanMode.EXTENDED)


@dataclass(frozen=True, slots=True, kw_only=True)
class PiMultiplier(Layout, HollowCommand[NormalReply | ExtendedReply | FdReply]):
    """Scale one speed- or current-loop PI gain at runtime: extended id (§6).

    ``D0 = 0x00, D1 = gain, D2..D5 = float32 big-endian``, padded with two zero bytes to DLC 8 (A17).
    The actual gain is the preset gain times ``multiplier``; not persisted. A classic motor answers
    with the reply of its CAN mode, a CAN FD motor with its FD reply.

    Attributes:
        gain: which gain to scale.
        multiplier: the factor, a finite float32 >= 0 (1.0 leaves the gain unchanged). A negative
            factor would invert a control loop, so it is refused [I].
    """

    EXTENDED_ID: ClassVar[bool] = True
    LINKS: ClassVar[tuple[str, ...]] = ("can", "canfd")
    CODE: ClassVar[int | None] = 0x00
    FIELDS = ((1, EnumField("gain", 1, PiGain)), (2, Float32BEField("multiplier", lo=0.0)))
    gain: PiGain
    multiplier: float

    @classmethod
    def claims(cls, data: bytes, can_mode: CanMode) -> bool:
        return _is_pi_frame(data)

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode a PI multiplier frame of 6 to 8 bytes (D6/D7, when present, are not defined: ignored).

        Raises:
            ProtocolError: wrong length, D0 not 0, unknown gain, or a multiplier that is NaN,
                infinite or negative.
        """
        if len(data) not in _PI_SIZES:
            raise ProtocolError(f"PI multiplier: expected 6 to 8 data bytes, got {len(data)}", raw=data)
        return super(PiMultiplier, cls).decode(bytes(data[:6]) + _PI_PADDING)


def decode_extended_request(data: bytes) -> HollowCommand[Any]:
    """Decode an extended-id request: a PI multiplier frame or the CAN mode switch (§5.1 rule).

    Raises:
        ProtocolError: neither layout fits.
    """
    return claimant(data, extended_id=True, fd=False, can_mode=CanMode.NORMAL).decode(data)


def decode_setpoint_frame(data: bytes, *, model: HollowModel, can_mode: CanMode) -> HollowCommand[Any]:
    """Decode a standard-id 8-byte frame: special command first, else a setpoint of ``can_mode``.

    Raises:
        ProtocolError: wrong length.
    """
    return claimant(data, extended_id=False, fd=False, can_mode=can_mode).decode(data, model=model)

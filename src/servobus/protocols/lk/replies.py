"""LK replies about the motor's state: echoes, status 1/2/3, brake. One class per reply layout.

Encoder, zero, angle and acceleration replies are in :mod:`~servobus.protocols.lk.replies_position`,
parameter replies in :mod:`~servobus.protocols.lk.params_v236` / ``params_v235``. Where
several command bytes share a layout (echoes; the status-2 shape of 0x9C and 0xA0..0xA8; 0x9A and
0x9B; 0x19 and 0x91; 0x33 and 0x34) one class serves them and carries the byte as ``command``.
Where a layout differs between revisions (0x9A/0x9B, 0x9D, 0x94) the V2.35 class has the ``V235``
suffix. Values whose scale depends on the motor type or encoder width carry ``motor_type`` /
``encoder_bits`` as fields, so every reply encodes by itself (the simulator encodes replies).

Ranges are the wire types' ranges, narrowed where a manual states the range of the reported value:
encoder counts must fit the declared encoder width (so a wrong ``encoder_bits`` shows up as a
ProtocolError), and DATA[2..3] of the status-2 shape has the ranges of :func:`torque_range`: iq ±2048
in V2.35. V2.36 states no range for a reported iq, so there it may go beyond the nominal ±2048 up to
the int16 limits. Power (the 0xA0 reply on every motor type, MS's status 2) is the raw int16 on both
revisions (spec A24): the manuals give it three different ranges, and motors report beyond them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    IqSlot,
    LkReply,
    build,
    check_command,
    check_encoder_count,
    enum_byte,
    expect,
    payload,
)
from servobus.protocols.lk.model import (
    DEFAULT_MODEL,
    LkModel,
    MotorType,
    Revision,
    check_encoder_bits,
    check_member,
    encoder_counts_per_turn,
)
from servobus.protocols.lk.states import BrakeState, ErrorState, ErrorStateV235, MotorState

__all__ = [
    "ECHO_CODES",
    "OPEN_LOOP_REPLY",
    "STATUS2_CODES",
    "BrakeReply",
    "EchoReply",
    "Status1Reply",
    "Status1ReplyV235",
    "Status2Reply",
    "Status3Reply",
    "Status3ReplyV235",
    "status2_slot",
    "torque_range",
]

ECHO_CODES = frozenset({0x80, 0x81, 0x88, 0x95})
STATUS1_CODES = frozenset({0x9A, 0x9B})
STATUS2_CODES = frozenset({0x9C, 0xA0, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 0xA6, 0xA7, 0xA8})
OPEN_LOOP_CODE = 0xA0

TEMPERATURE = IntField("temperature_c", size=1, signed=True)  # int8, 1 °C/LSB (spec §2, A25)
VOLTAGE = ScaledField("voltage_v", size=2, signed=True, counts_per_unit=100)  # V2.36 int16 0.01 V
VOLTAGE_V235 = ScaledField("voltage_v", size=2, signed=False, counts_per_unit=10)  # V2.35 uint16 0.1 V
BUS_CURRENT = ScaledField("current_a", size=2, signed=True, counts_per_unit=100)  # V2.36 int16 0.01 A
REPLY_SPEED = ScaledField("speed_dps", size=2, signed=True, counts_per_unit=1)  # int16 1 dps/LSB
# Spec §8.2: iq in A (MF, MG), MS output power (unitless), MH raw (scale not stated).
REPLY_IQ = IqSlot(
    "current_a",
    {MotorType.MS: "power_counts", MotorType.MH: "iq_counts"},
    max_counts=0x7FFF,
    min_counts=-0x8000,
)
# Spec §4.9, A20, A24: the 0xA0 reply's DATA[2..3] is the output power, unitless, on every motor
# type ([003]'s table labels the bytes "Torque current", its text says "Motor Power"; [001]: MS only,
# power): the raw int16, never amperes.
OPEN_LOOP_REPLY = IqSlot(
    "current_a",
    dict.fromkeys(MotorType, "power_counts"),
    max_counts=0x7FFF,
    min_counts=-0x8000,
    in_amps=False,
)
# Spec §4.4 [001]: phase currents MG 66/4096, MF 33/4096 A/LSB (= the iq scales); MS "no effect",
# MH not stated: raw.
PHASE = IqSlot(
    "currents_a",
    {MotorType.MS: "currents_counts", MotorType.MH: "currents_counts"},
    max_counts=0x7FFF,
    min_counts=-0x8000,
)
PHASE_V235 = ScaledField("currents_a", size=2, signed=True, counts_per_unit=64)  # [003]: 1/64 A/LSB


def status2_slot(command: int) -> IqSlot:
    """What the status-2 shape's DATA[2..3] is in the reply to ``command``: 0xA0's power
    (:data:`OPEN_LOOP_REPLY`, raw counts on every motor type), else :data:`REPLY_IQ` (spec §8.2)."""
    return OPEN_LOOP_REPLY if command == OPEN_LOOP_CODE else REPLY_IQ


def torque_range(revision: Revision, motor_type: MotorType, command: int) -> tuple[int, int] | None:
    """The count range a status-2 reply's DATA[2..3] is checked against, or None for the int16 range.

    * Power, unitless (the 0xA0 reply on every motor type, spec §4.9/A20; MS's status 2): None. The
      manuals give it three ranges ([001] 0x9C reply -1000..1000, 0xA0 request -850..850, [003] 0xA0
      reply -850..850) and no unit; spec A24 keeps the raw int16. Motors do report beyond them
      (issue 24: V2.35 ``A0 EC C2 FB 29 FE 34 3A``, power -1086).
    * V2.35, iq: -2048..2048 ([003] §4.14 0x9C and §5 0xA1..0xA8 replies: "Range:-2048~2048").
    * V2.36, iq (MF/MH/MG): not stated (only the resolution), so the int16 range.
    """
    if command == OPEN_LOOP_CODE or motor_type is MotorType.MS:
        return None
    if revision is Revision.V2_35:
        return (-2048, 2048)
    return None


def _check_torque_range(data: bytes, model: LkModel, what: str) -> None:
    limits = torque_range(model.revision, model.motor_type, data[0])
    counts = _i16(data, 2)
    if limits is not None and not limits[0] <= counts <= limits[1]:
        values = status2_slot(data[0]).from_counts(model.motor_type, counts)
        named = [(k, v) for k, v in values.items() if v is not None]
        name, value = named[0] if named else ("iq_counts", counts)
        raise ProtocolError(
            f"{what}: {name}={value!r} ({counts} counts) is outside [{limits[0]}, {limits[1]}] counts "
            f"({model.revision.name}, {model.motor_type.name})",
            raw=data,
            command=data[0],
        )


def _u16(data: bytes, offset: int) -> int:
    return int.from_bytes(data[offset : offset + 2], "little")


def _i16(data: bytes, offset: int) -> int:
    return int.from_bytes(data[offset : offset + 2], "little", signed=True)


def _check_command(value: int, codes: frozenset[int]) -> None:
    check_command(value, codes)


@dataclass(frozen=True, slots=True, kw_only=True)
class EchoReply(LkReply):
    """Reply to 0x80, 0x81, 0x88, 0x95: the request's bytes echoed (spec §1.1 rule 3).

    Attributes:
        command: 0x80 (off), 0x81 (stop), 0x88 (run) or 0x95 (zero in RAM).
    """

    command: int

    def __post_init__(self) -> None:
        _check_command(self.command, ECHO_CODES)

    def encode(self) -> bytes:
        return payload(self.command)

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        return build(cls, data, command=expect(data, ECHO_CODES, cls.__name__))


@dataclass(frozen=True, slots=True, kw_only=True)
class Status1Reply(LkReply):
    """0x9A/0x9B reply, V2.36 layout ``<BbhhBB`` (spec §4.1, §4.2).

    Attributes:
        command: 0x9A (read) or 0x9B (clear errors).
        temperature_c: motor temperature, 1 °C/LSB.
        voltage_v: bus voltage, 0.01 V/LSB.
        current_a: bus current, 0.01 A/LSB.
        motor_state: ON or OFF.
        error_state: error flags (unknown bits are kept; all eight are defined in V2.36).
    """

    REVISIONS = V2_36_ONLY
    FAULTS: ClassVar[str | None] = "error_state"
    command: int
    temperature_c: int
    voltage_v: float
    current_a: float
    motor_state: MotorState
    error_state: ErrorState

    def __post_init__(self) -> None:
        _check_command(self.command, STATUS1_CODES)
        TEMPERATURE.check(self.temperature_c)
        VOLTAGE.check(self.voltage_v)
        BUS_CURRENT.check(self.current_a)
        check_member("motor_state", self.motor_state, MotorState)
        check_member("error_state", self.error_state, ErrorState)

    def encode(self) -> bytes:
        return payload(
            self.command,
            (1, TEMPERATURE.encode(self.temperature_c)),
            (2, VOLTAGE.encode(self.voltage_v)),
            (4, BUS_CURRENT.encode(self.current_a)),
            (6, bytes([self.motor_state, self.error_state])),
        )

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        command = expect(data, STATUS1_CODES, cls.__name__)
        return build(
            cls,
            data,
            command=command,
            temperature_c=TEMPERATURE.decode(data, 1),
            voltage_v=VOLTAGE.decode(data, 2),
            current_a=BUS_CURRENT.decode(data, 4),
            motor_state=enum_byte(MotorState, data, 6, what=cls.__name__),
            error_state=ErrorState(data[7]),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Status1ReplyV235(LkReply):
    """0x9A/0x9B reply, V2.35 layout ``<BbxHxxB`` (spec §4.1, §4.2, D3).

    [003] prints DATA[0] = 0x9A in its 0x9B reply table (A4): a drive that copies the table answers
    0x9B with 0x9A; :func:`servobus.protocols.lk.ids.request_keys` therefore expects either byte.

    Attributes:
        command: 0x9A or 0x9B.
        temperature_c: motor temperature, 1 °C/LSB.
        voltage_v: bus voltage, 0.1 V/LSB (uint16).
        error_state: LOW_VOLTAGE (bit 0), OVER_TEMPERATURE (bit 3); other ("invalid") bits kept.
    """

    REVISIONS = V2_35_ONLY
    FAULTS: ClassVar[str | None] = "error_state"
    command: int
    temperature_c: int
    voltage_v: float
    error_state: ErrorStateV235

    def __post_init__(self) -> None:
        _check_command(self.command, STATUS1_CODES)
        TEMPERATURE.check(self.temperature_c)
        VOLTAGE_V235.check(self.voltage_v)
        check_member("error_state", self.error_state, ErrorStateV235)

    def encode(self) -> bytes:
        return payload(
            self.command,
            (1, TEMPERATURE.encode(self.temperature_c)),
            (3, VOLTAGE_V235.encode(self.voltage_v)),
            (7, bytes([self.error_state])),
        )

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        command = expect(data, STATUS1_CODES, cls.__name__)
        return build(
            cls,
            data,
            command=command,
            temperature_c=TEMPERATURE.decode(data, 1),
            voltage_v=VOLTAGE_V235.decode(data, 3),
            error_state=ErrorStateV235(data[7]),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Status2Reply(LkReply):
    """The status-2 shape ``<BbhhH``: reply to 0x9C and to every control command 0xA0..0xA8 (spec §8.1).

    Also the reply of each motor to the 0x280 multi-motor frame (command 0xA1, on 0x140+ID).
    DATA[2..3] depends on the motor type (spec §8.2): exactly one of ``current_a`` (MF, MG),
    ``power_counts`` (MS) or ``iq_counts`` (MH) is set. In the 0xA0 (open loop) reply it is the
    output power on every motor type (spec §4.9, A20): ``power_counts`` is set, whatever the type.

    Attributes:
        command: 0x9C or 0xA0..0xA8.
        motor_type: what DATA[2..3] means.
        encoder_bits: width the encoder count must fit.
        temperature_c: motor temperature, 1 °C/LSB.
        speed_dps: motor speed, 1 dps/LSB.
        encoder_counts: encoder position (uint16), 0..2**encoder_bits - 1 (18-bit: 0..65535).
        current_a: MF/MG torque current iq in A (MF 33/4096, MG 66/4096 A/LSB).
        power_counts: output power as the raw int16, unitless (MS; every motor in the 0xA0 reply).
            The manuals' ranges (-1000..1000, -850..850) are not enforced (spec A24).
        iq_counts: MH iq as raw counts (scale not stated, A23).
    """

    command: int
    motor_type: MotorType
    encoder_bits: int
    temperature_c: int
    speed_dps: float
    encoder_counts: int
    current_a: float | None = None
    power_counts: int | None = None
    iq_counts: int | None = None

    def __post_init__(self) -> None:
        _check_command(self.command, STATUS2_CODES)
        check_member("motor_type", self.motor_type, MotorType)
        check_encoder_bits(self.encoder_bits)
        TEMPERATURE.check(self.temperature_c)
        REPLY_SPEED.check(self.speed_dps)
        check_encoder_count("encoder_counts", self.encoder_counts, self.encoder_bits)
        self._iq_counts()

    def _iq_counts(self) -> int:
        values = {"current_a": self.current_a, "power_counts": self.power_counts, "iq_counts": self.iq_counts}
        if self.command != OPEN_LOOP_CODE:
            return REPLY_IQ.to_counts(self.motor_type, values)
        try:
            return OPEN_LOOP_REPLY.to_counts(self.motor_type, values)
        except ValueError as exc:
            raise ValueError(f"0xA0 reply (DATA[2..3] is power, spec §4.9): {exc}") from None

    @property
    def encoder_deg(self) -> float:
        """The encoder position as an angle of the motor shaft in degrees (0..360)."""
        return self.encoder_counts * 360.0 / encoder_counts_per_turn(self.encoder_bits)

    def encode(self) -> bytes:
        return payload(
            self.command,
            (1, TEMPERATURE.encode(self.temperature_c)),
            (2, self._iq_counts().to_bytes(2, "little", signed=True)),
            (4, REPLY_SPEED.encode(self.speed_dps)),
            (6, self.encoder_counts.to_bytes(2, "little")),
        )

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        command = expect(data, STATUS2_CODES, cls.__name__)
        _check_torque_range(data, model, cls.__name__)
        return build(
            cls,
            data,
            command=command,
            motor_type=model.motor_type,
            encoder_bits=model.encoder_bits,
            temperature_c=TEMPERATURE.decode(data, 1),
            speed_dps=REPLY_SPEED.decode(data, 4),
            encoder_counts=_u16(data, 6),
            **status2_slot(command).from_counts(model.motor_type, _i16(data, 2)),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Status3Reply(LkReply):
    """0x9D reply, V2.36 layout ``<Bbhhh``: temperature and phase currents A, B, C (spec §4.4).

    Attributes:
        motor_type: MF/MG give ``currents_a``; MS ("no effect") and MH (scale unknown) give
            ``currents_counts``.
        temperature_c: motor temperature, 1 °C/LSB.
        currents_a: (iA, iB, iC) in A (MG 66/4096, MF 33/4096 A/LSB).
        currents_counts: (iA, iB, iC) as raw int16 counts.
    """

    CODE: ClassVar[int] = 0x9D
    REVISIONS = V2_36_ONLY
    motor_type: MotorType
    temperature_c: int
    currents_a: tuple[float, float, float] | None = None
    currents_counts: tuple[int, int, int] | None = None

    def __post_init__(self) -> None:
        check_member("motor_type", self.motor_type, MotorType)
        TEMPERATURE.check(self.temperature_c)
        self._counts()

    def _counts(self) -> list[int]:
        for name in ("currents_a", "currents_counts"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, tuple) or len(value) != 3):
                raise ValueError(f"{name}={value!r} is not a tuple of 3 values (iA, iB, iC)")
        amps = self.currents_a or (None, None, None)
        raw = self.currents_counts or (None, None, None)
        counts = []
        for phase, (current, count) in zip("ABC", zip(amps, raw, strict=True), strict=True):
            try:
                counts.append(
                    PHASE.to_counts(self.motor_type, {"currents_a": current, "currents_counts": count})
                )
            except ValueError as exc:
                raise ValueError(f"phase {phase}: {exc}") from None
        return counts

    def encode(self) -> bytes:
        currents = b"".join(c.to_bytes(2, "little", signed=True) for c in self._counts())
        return payload(self.CODE, (1, TEMPERATURE.encode(self.temperature_c)), (2, currents))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        phases = [PHASE.from_counts(model.motor_type, _i16(data, i)) for i in (2, 4, 6)]
        fields = {name: tuple(p[name] for p in phases) for name in ("currents_a", "currents_counts")}
        values = {name: None if None in value else value for name, value in fields.items()}
        return build(
            cls, data, motor_type=model.motor_type, temperature_c=TEMPERATURE.decode(data, 1), **values
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Status3ReplyV235(LkReply):
    """0x9D reply, V2.35 layout ``<Bxhhh``: DATA[1] NULL, phase currents at 1/64 A/LSB (spec §4.4, D5).

    Attributes:
        currents_a: (iA, iB, iC) in A.
    """

    CODE: ClassVar[int] = 0x9D
    REVISIONS = V2_35_ONLY
    currents_a: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not isinstance(self.currents_a, tuple) or len(self.currents_a) != 3:
            raise ValueError(f"currents_a={self.currents_a!r} is not a tuple of 3 values (iA, iB, iC)")
        for phase, current in zip("ABC", self.currents_a, strict=True):
            try:
                PHASE_V235.check(current)
            except ValueError as exc:
                raise ValueError(f"phase {phase}: {exc}") from None

    def encode(self) -> bytes:
        return payload(self.CODE, (2, b"".join(PHASE_V235.encode(c) for c in self.currents_a)))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        a, b, c = (PHASE_V235.decode(data, i) for i in (2, 4, 6))
        return build(cls, data, currents_a=(a, b, c))


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeReply(LkReply):
    """0x8C reply, V2.36 only: the brake state (spec §4.8).

    Attributes:
        state: ENGAGED (de-energised, holding) or RELEASED (energised).
    """

    CODE: ClassVar[int] = 0x8C
    REVISIONS = V2_36_ONLY
    state: BrakeState

    def __post_init__(self) -> None:
        check_member("state", self.state, BrakeState)

    def encode(self) -> bytes:
        return payload(self.CODE, (1, bytes([self.state])))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        return build(cls, data, state=enum_byte(BrakeState, data, 1, what=cls.__name__))

"""LK replies about the motor's state: echoes, status 1/2/3, brake. One class per reply layout.

Encoder, zero, angle and acceleration replies are in :mod:`~servobus.protocols.lk.replies_position`,
parameter replies in :mod:`~servobus.protocols.lk.params_v236` / ``params_v235``. Where
several command bytes share a layout (echoes; the status-2 shape of 0x9C and 0xA0..0xA8; 0x9A and
0x9B; 0x19 and 0x91; 0x33 and 0x34) one class serves them and carries the byte as ``command``; the
bytes it accepts are those of the commands that declare it as their reply (:meth:`LkReply.answers`).
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
from types import MappingProxyType
from typing import ClassVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    CommandField,
    EncoderCountField,
    FlagByteField,
    IqField,
    IqSlot,
    LkReply,
    MemberField,
    TupleField,
)
from servobus.protocols.lk.model import LkModel, MotorType, Revision, encoder_counts_per_turn
from servobus.protocols.lk.states import BrakeState, ErrorState, ErrorStateV235, MotorState

__all__ = [
    "OPEN_LOOP_REPLY",
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
    note="0xA0 reply (DATA[2..3] is power, spec §4.9)",
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
_PHASES = ("A", "B", "C")


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


@dataclass(frozen=True, slots=True, kw_only=True)
class EchoReply(LkReply):
    """Reply to 0x80, 0x81, 0x88, 0x95: the request's bytes echoed (spec §1.1 rule 3).

    Attributes:
        command: 0x80 (off), 0x81 (stop), 0x88 (run) or 0x95 (zero in RAM).
    """

    MODEL_FIELDS = ((0, CommandField()),)
    command: int


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
    FIELDS = (
        (1, TEMPERATURE),
        (2, VOLTAGE),
        (4, BUS_CURRENT),
        (6, MemberField("motor_state", MotorState)),
        (7, FlagByteField("error_state", ErrorState)),
    )
    MODEL_FIELDS = ((0, CommandField()),)
    command: int
    temperature_c: int
    voltage_v: float
    current_a: float
    motor_state: MotorState
    error_state: ErrorState


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
    FIELDS = ((1, TEMPERATURE), (3, VOLTAGE_V235), (7, FlagByteField("error_state", ErrorStateV235)))
    MODEL_FIELDS = ((0, CommandField()),)
    command: int
    temperature_c: int
    voltage_v: float
    error_state: ErrorStateV235


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

    MODEL = ("motor_type", "encoder_bits")
    FIELDS = ((1, TEMPERATURE), (4, REPLY_SPEED))
    MODEL_FIELDS = (
        (0, CommandField()),
        (2, IqField(REPLY_IQ, by_command=MappingProxyType({OPEN_LOOP_CODE: OPEN_LOOP_REPLY}))),
        (6, EncoderCountField("encoder_counts")),
    )
    command: int
    motor_type: MotorType
    encoder_bits: int
    temperature_c: int
    speed_dps: float
    encoder_counts: int
    current_a: float | None = None
    power_counts: int | None = None
    iq_counts: int | None = None

    @property
    def encoder_deg(self) -> float:
        """The encoder position as an angle of the motor shaft in degrees (0..360)."""
        return self.encoder_counts * 360.0 / encoder_counts_per_turn(self.encoder_bits)

    @classmethod
    def check_bytes(cls, data: bytes, model: LkModel) -> None:
        """DATA[2..3] within the range the revision's manual states for it (:func:`torque_range`)."""
        limits = torque_range(model.revision, model.motor_type, data[0])
        counts = int.from_bytes(data[2:4], "little", signed=True)
        if limits is not None and not limits[0] <= counts <= limits[1]:
            values = status2_slot(data[0]).from_counts(model.motor_type, counts)
            named = [(k, v) for k, v in values.items() if v is not None]
            name, value = named[0] if named else ("iq_counts", counts)
            raise ProtocolError(
                f"{cls.__name__}: {name}={value!r} ({counts} counts) is outside [{limits[0]}, {limits[1]}]"
                f" counts ({model.revision.name}, {model.motor_type.name})",
                raw=data,
                command=data[0],
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
    MODEL = ("motor_type",)
    FIELDS = ((1, TEMPERATURE),)
    MODEL_FIELDS = ((2, IqField(PHASE, "phase", _PHASES)),)
    motor_type: MotorType
    temperature_c: int
    currents_a: tuple[float, float, float] | None = None
    currents_counts: tuple[int, int, int] | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Status3ReplyV235(LkReply):
    """0x9D reply, V2.35 layout ``<Bxhhh``: DATA[1] NULL, phase currents at 1/64 A/LSB (spec §4.4, D5).

    Attributes:
        currents_a: (iA, iB, iC) in A.
    """

    CODE: ClassVar[int] = 0x9D
    REVISIONS = V2_35_ONLY
    FIELDS = ((2, TupleField(PHASE_V235, "phase", _PHASES)),)
    currents_a: tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeReply(LkReply):
    """0x8C reply, V2.36 only: the brake state (spec §4.8).

    Attributes:
        state: ENGAGED (de-energised, holding) or RELEASED (energised).
    """

    CODE: ClassVar[int] = 0x8C
    REVISIONS = V2_36_ONLY
    FIELDS = ((1, MemberField("state", BrakeState)),)
    state: BrakeState

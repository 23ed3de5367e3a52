"""Per-motor-model scaling of the hollow series, and the C-core packers built from it (once per model).

The manual fixes the bit layouts but not all the scales: the classic-CAN speed and current full scales
"differ between motor types" and are never listed (hollow.md §4.3, A8), Pmax is a console parameter
(§2.4 item e), and the CAN FD velocity is an electrical frequency whose conversion to shaft speed needs
the pole-pair count (§7.4). :class:`HollowModel` holds those numbers; every command and reply whose
bytes depend on them carries one, so ``.encode()`` is self-contained.

The :class:`~servobus.core.Packer` objects for a model are built on first use and cached
(:func:`packers`): a control loop never rebuilds a scale table per frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from servobus.core import (
    HOLLOW_EXT_REPLY,
    HOLLOW_FD_COMMAND,
    HOLLOW_FD_REPLY,
    HOLLOW_SETPOINT,
    MIT_REPLY,
    FieldScale,
    Packer,
)

__all__ = [
    "COUNTS_PER_TURN",
    "DEFAULT_MODEL",
    "FD_VELOCITY_COUNTS_PER_HZ",
    "MODELS",
    "MODEL_3507",
    "HollowModel",
    "Packers",
    "packers",
]

# hollow.md §5.3 and §7.2: 20-bit single turn, in the extended-mode reply and in CAN FD.
COUNTS_PER_TURN = 1 << 20
# hollow.md §7.4: f_elec [Hz] = Velocity / 8388608 * 1000, so one hertz is 8388.608 counts.
FD_VELOCITY_COUNTS_PER_HZ = (1 << 23) / 1000


@dataclass(frozen=True, slots=True, kw_only=True)
class HollowModel:
    """The scaling parameters of one hollow-series motor model.

    Attributes:
        name: a label for listings and reprs.
        pmax_turns: Pmax, the position full scale of classic CAN in turns (console item *e*). The
            manual says it "should be set to 1.0 for all hollow series motors"; any Pmax > 0 is
            supported (hollow.md A30).
        speed_full_scale_rad_s: ω_fs, the classic-CAN speed code 0xFFF/0x000 is ±ω_fs (§4.3). Not
            listed in the manual; 200 rad/s is what its worked examples imply (A8).
        current_full_scale_a: I_fs, the classic-CAN current ("torque") code's ±full scale (§4.3).
            Not listed in the manual; 4 A is what its worked examples imply (A8).
        pole_pairs: pole pairs of the motor, converting the CAN FD electrical frequency to shaft
            speed (§7.4: "14 … for the 3507 motor; change it for other motors").

    Raises:
        ValueError: a parameter is not finite and positive (pole_pairs: not a positive integer).
    """

    name: str = "default"
    pmax_turns: float = 1.0
    speed_full_scale_rad_s: float = 200.0
    current_full_scale_a: float = 4.0
    pole_pairs: int = 14

    def __post_init__(self) -> None:
        for attr in ("pmax_turns", "speed_full_scale_rad_s", "current_full_scale_a"):
            value = getattr(self, attr)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{attr}={value!r} is not a finite number")
            if value <= 0:
                raise ValueError(f"{attr}={value!r} is outside (0, inf)")
        if isinstance(self.pole_pairs, bool) or not isinstance(self.pole_pairs, int):
            raise ValueError(f"pole_pairs={self.pole_pairs!r} is not an integer")
        if self.pole_pairs < 1:
            raise ValueError(f"pole_pairs={self.pole_pairs!r} is outside [1, inf)")

    @property
    def position_full_scale_deg(self) -> float:
        """±Pmax turns in degrees: the classic-CAN position range (normal and incremental)."""
        return 360.0 * self.pmax_turns

    @property
    def fd_velocity_counts_per_rpm(self) -> float:
        """CAN FD velocity counts per shaft rpm: rpm = f_elec · 60 / pole_pairs (§7.4)."""
        return FD_VELOCITY_COUNTS_PER_HZ * self.pole_pairs / 60.0


# The defaults reproduce the manual's worked examples exactly (hollow.md §4.6, [H1], [H2]).
DEFAULT_MODEL = HollowModel()

# A data point from third-party host scripts for a "3507" motor of what looks like the same vendor
# (hollow.md §4.3 [C]): 58.639 rad/s and 4 A; 14 pole pairs is the manual's own 3507 figure (§7.4).
# The HO4307/HO5515/HO2212/HO6213 rows of the manual's PWM table (§10) are PWM limits in motor Hz,
# not CAN full scales (A8), so they are deliberately not presets.
MODEL_3507 = HollowModel(name="3507", speed_full_scale_rad_s=58.639, current_full_scale_a=4.0, pole_pairs=14)

MODELS: dict[str, HollowModel] = {DEFAULT_MODEL.name: DEFAULT_MODEL, MODEL_3507.name: MODEL_3507}


@dataclass(frozen=True, slots=True)
class Packers:
    """The five C-core packers of one model (layouts from ``servobus.core.packing``)."""

    setpoint: Packer  # HOLLOW_SETPOINT: p, v, kp, kd, t (§4.2); never emits a special command
    normal_reply: Packer  # MIT_REPLY: motor_id, p, v, t (§4.5, 6 bytes)
    extended_reply: Packer  # HOLLOW_EXT_REPLY: motor_id, x (int32 counts), v, t (§5.3, 8 bytes)
    fd_command: Packer  # HOLLOW_FD_COMMAND: pos, vel, cur, mode, run, kp, kd, zero (§7.2)
    fd_reply: Packer  # HOLLOW_FD_REPLY: pos, vel, cur, mode, run, reserved, temp, slave (§7.3)


def _fd_position() -> FieldScale:
    return FieldScale.twos_complement("position_deg", 40, codes=COUNTS_PER_TURN, span=360.0)


def _fd_velocity(model: HollowModel) -> FieldScale:
    return FieldScale.twos_complement("velocity_rpm", 32, codes=model.fd_velocity_counts_per_rpm, span=1.0)


@lru_cache(maxsize=64)
def packers(model: HollowModel) -> Packers:
    """The packers for ``model``, built on the first call and cached (models are hashable).

    Args:
        model: the motor model whose scales the packers apply.

    Returns:
        The model's :class:`Packers`.
    """
    position = FieldScale.offset_binary("position_deg", model.position_full_scale_deg, 16)
    speed = FieldScale.offset_binary("speed_rad_s", model.speed_full_scale_rad_s, 12)
    current = FieldScale.offset_binary("current_a", model.current_full_scale_a, 12)
    motor_id = FieldScale.integer("motor_id", 0, 255)
    return Packers(
        setpoint=Packer(
            HOLLOW_SETPOINT,
            [position, speed, FieldScale.integer("kp", 0, 4095), FieldScale.integer("kd", 0, 4095), current],
        ),
        normal_reply=Packer(MIT_REPLY, [motor_id, position, speed, current]),
        extended_reply=Packer(
            HOLLOW_EXT_REPLY,
            [
                motor_id,
                FieldScale.twos_complement("position_deg", 32, codes=COUNTS_PER_TURN, span=360.0),
                speed,
                current,
            ],
        ),
        fd_command=Packer(
            HOLLOW_FD_COMMAND,
            [
                _fd_position(),
                _fd_velocity(model),
                FieldScale.twos_complement("current_raw", 16),
                FieldScale.integer("mode", 0, 2),
                FieldScale.integer("run", 0, 1),
                FieldScale.integer("kp", 0, 255),
                FieldScale.integer("kd", 0, 255),
                FieldScale.integer("zero", 0, 1),
            ],
        ),
        fd_reply=Packer(
            HOLLOW_FD_REPLY,
            [
                _fd_position(),
                _fd_velocity(model),
                FieldScale.twos_complement("current_raw", 16),
                FieldScale.integer("mode", 0, 255),
                FieldScale.integer("run", 0, 255),
                FieldScale.integer("reserved", 0, 255),
                FieldScale.integer("temperature_c", -128, 127),
                FieldScale.integer("slave_id", 0, 255),
            ],
        ),
    )

"""What ``servobus demo`` drives a family's simulated motors with: its simulator part, and the
operation of its ``cli`` part that moves a motor to an angle: ``move`` (with the demo's own speed
limit, :data:`MAX_SPEED_DPS`), else ``mit`` (the target position, velocity 0, the gains
:data:`MIT_KP` and :data:`MIT_KD`); a family with neither is refused in one line (exit 2)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import click

from servobus.bus import Motor
from servobus.cli._connect import sim_part
from servobus.cli.plugin import sharing_rounds
from servobus.protocols import Command, get_family
from servobus.sim.family import SimFamily, SimOptions

if TYPE_CHECKING:
    from servobus.cli.plugin import CliFamily, Op

__all__ = ["MAX_SPEED_DPS", "MIT_KD", "MIT_KP", "Parts", "parts"]

#: the speed limit of the demo's moves (its choice: a move's own default is the family's)
MAX_SPEED_DPS = 500.0
#: the gains of the demo's ``mit`` set-points, for a family without ``move`` (N·m/rad, N·m·s/rad)
MIT_KP = 20.0
MIT_KD = 1.0


@dataclass(frozen=True, slots=True)
class Parts:
    """What the demo asks of the family: its simulator, and the operation that moves a motor to an
    angle (``uses``: its ``move``, else its ``mit``) with the values it takes for an angle."""

    family: str
    sim: SimFamily
    op: Op
    values: Callable[[float], dict[str, Any]]
    uses: str = "move"

    def start(self, motor: Motor, angle_deg: float) -> Sequence[Command]:
        """What starts an absolute move to ``angle_deg`` (hollow: its mode, the set-point, Start)."""
        return self.op.first(motor.codec, self.values(angle_deg))

    def setpoint(self, motor: Motor, angle_deg: float) -> Command:
        """The absolute position set-point to ``angle_deg``, as the operation resends it each tick
        (its first command: LK's move also rereads the angle, which the demo does not)."""
        values = self.values(angle_deg)
        again = self.op.repeat(motor.codec, values) if self.op.repeat is not None else None
        return again[0] if again else self.op.first(motor.codec, values)[-1]

    def ids(self, count: int) -> list[int]:
        """The ids of ``count`` motors on one simulated bus: the family's first ids from 1 that can
        share a bus (:func:`~servobus.protocols.check_bus`): 1..count, unless some ids' frames
        collide (Damiao: motor 1's feedback id is motor 17's command id, so 1-16, then 33..).

        Raises:
            click.BadParameter: the family has fewer such ids (exit 2).
        """
        family = get_family(self.family)
        codecs = [family.bind(i) for i in family.motor_ids if i >= 1]
        chosen = sharing_rounds(codecs)[0][:count] if codecs else []
        if len(chosen) < count:
            raise click.BadParameter(
                f"{count} {self.family} motors on one bus: at most {len(chosen)} can share one; "
                "give more --buses",
                param_hint="--motors",
            )
        return [c.motor_id for c in chosen]

    @property
    def how(self) -> str:
        """The values the operation takes besides the angle, in a few words (for the demo's lines)."""
        if self.uses == "mit":
            return f"kp {MIT_KP:g}, kd {MIT_KD:g}, velocity 0"
        return f"at most {MAX_SPEED_DPS:g} dps"


def _move_values(angle_deg: float) -> dict[str, Any]:
    """``move``'s values: the demo's own speed limit (:data:`MAX_SPEED_DPS`), absolute."""
    return {"angle_deg": angle_deg, "max_speed_dps": MAX_SPEED_DPS, "relative": False, "max_current_a": None}


def _move_without_limit(angle_deg: float) -> dict[str, Any]:
    """``move``'s values for a move that takes no speed limit (``Op.speed_limit``): none given."""
    return {**_move_values(angle_deg), "max_speed_dps": None}


def _mit_values(angle_deg: float) -> dict[str, Any]:
    """``mit``'s values, the fallback without a move: the position, no velocity or torque
    feed-forward, the demo's gains (:data:`MIT_KP`, :data:`MIT_KD`)."""
    return {
        "position_rad": math.radians(angle_deg),
        "velocity_rad_s": 0.0,
        "kp": MIT_KP,
        "kd": MIT_KD,
        "torque_ff_nm": 0.0,
    }


#: what the demo moves motors with, in order of preference, and the values each takes for an angle
_DRIVES: tuple[tuple[str, Callable[[float], dict[str, Any]]], ...] = (
    ("move", _move_values),
    ("mit", _mit_values),
)


def parts(family: str) -> Parts:
    """The family's simulator and what moves its motors (``move``, else ``mit``), or a one-line
    refusal (exit 2) saying which it lacks."""
    try:
        sim = sim_part(family)
        sim.check(SimOptions())
    except ValueError as exc:
        raise click.BadParameter(str(exc).removeprefix("--sim: "), param_hint="--family") from None
    try:
        cli: CliFamily = get_family(family).part("cli")
    except LookupError as exc:
        raise click.BadParameter(
            f"{exc}: the demo moves motors with its move, or mit", param_hint="--family"
        ) from None
    for name, values in _DRIVES:
        op = cli.op(name)
        if op is not None:
            if name == "move" and not op.speed_limit:
                values = _move_without_limit
            return Parts(family, sim, op, values, name)
    # (the move's reason last: the demo's first choice, what the user most likely looks for)
    no_mit = cli.why_not.get("mit", "the family's cli part has none")
    no_move = cli.why_not.get("move", "")
    raise click.BadParameter(
        f"the demo moves motors with move, else mit (no mit: {no_mit}); "
        f"{family} motors have no move" + (f": {no_move}" if no_move else ""),
        param_hint="--family",
    )

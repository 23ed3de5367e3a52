"""The DM-J family's part of the command line (``FAMILY.part("cli")``): everything it sends is a MIT
set-point after an :class:`Enable`, a special command, or the refresh. The contract is
:mod:`servobus.protocols.cli`'s.

``mit`` sends the user's set-point as it is; ``move`` a MIT position set-point with the gains
:data:`MOVE_KP`/:data:`MOVE_KD` (the MIT law has no speed limit: a ``max_speed_dps`` given, the
user's or the demo's, is not sent; the gains set the pace); ``speed`` a velocity set-point (kp = 0, kd
:data:`SPEED_KD`). ``status``, ``monitor`` and ``scan`` read with :class:`RefreshState` (derived
from the declarations: it is ``READ``); ``stop`` and ``off`` are the bound codec's safe command,
:class:`Disable`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from servobus.authoring import BoundCodec, CliFamily, Command, Make, Op, Values, once
from servobus_dm.codec import MOTOR_IDS
from servobus_dm.messages import ClearError, Disable, Enable, MitControl, SaveZero

__all__ = ["CLI", "MOVE_KD", "MOVE_KP", "SPEED_KD"]

#: ``move``'s stiffness (N·m/rad) and damping (N·m·s/rad): a firm, well-damped joint on every model.
MOVE_KP = 20.0
MOVE_KD = 1.0
#: ``speed``'s damping: the torque per rad/s of speed error.
SPEED_KD = 1.0


def _mit(codec: BoundCodec, v: Values) -> Command:
    return MitControl(
        position_rad=v["position_rad"],
        velocity_rad_s=v["velocity_rad_s"],
        kp=v["kp"],
        kd=v["kd"],
        torque_nm=v["torque_ff_nm"],
        model=codec.model,
    )


def _move(codec: BoundCodec, v: Values) -> Command:
    if v["relative"]:
        raise ValueError("dm motors: a MIT set-point is absolute; give the angle (drop --relative)")
    return MitControl(position_rad=math.radians(v["angle_deg"]), kp=MOVE_KP, kd=MOVE_KD, model=codec.model)


def _speed(codec: BoundCodec, v: Values) -> Command:
    return MitControl(
        position_rad=0.0, velocity_rad_s=math.radians(v["speed_dps"]), kd=SPEED_KD, model=codec.model
    )


def _enabled(make: Make) -> Op:
    """Enable, then the set-point; the set-point again at the command's rate."""

    def first(codec: BoundCodec, v: Values) -> Sequence[Command]:
        point = make(codec, v)
        codec.encode(point)  # out of the model's range: refused before the motor is enabled
        return (Enable(), point)

    return Op(first=first, repeat=lambda codec, v: (make(codec, v),))


CLI = CliFamily(
    scan_ids=MOTOR_IDS,  # 1..15: their feedback ids (0x11..0x1F) are no motor's command id
    ops={
        "mit": _enabled(_mit),
        "move": _enabled(_move),
        "speed": _enabled(_speed),
        "zero": Op(
            first=lambda codec, v: (Disable(), SaveZero()),
            rom=True,  # a flash write: asked first
            note="the zero is kept in flash; the motor was disabled for it",
        ),
        "clear-errors": once(lambda codec, v: ClearError(), note="the motor is disabled: enable it to drive"),
    },
    why_not={
        "torque": "DM-J motors take a torque in N·m, not a current: servobus mit --kp 0 --kd 0 "
        "--torque-ff-nm T",
        "brake": "DM-J motors have no brake",
        "set-id": "the DM-J id is set with the vendor's tool",
        "reset": "the DM-J MIT protocol has no reset: servobus clear-errors",
    },
)

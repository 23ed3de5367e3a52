"""The toy family's part of the command line (``FAMILY.part("cli")``): what ``servobus speed``,
``reset`` and ``config`` send. The contract is :mod:`servobus.protocols.cli`'s.

``status``, ``monitor`` and ``scan`` need nothing here: their reads are derived from the commands'
declarations (:class:`~servobus_toy.messages.ReadState` is ``READ``, takes no argument and its reply
carries ``position_deg``, ``speed_dps`` and the fault flags); ``stop`` and ``off`` are the bound codec's
safe commands.
"""

from __future__ import annotations

from servobus.protocols.cli import CliFamily, build, once, setpoint, setting_of
from servobus_toy.messages import Restart, SetSpeed, WriteSpeedLimit

__all__ = ["CLI"]

CLI = CliFamily(
    ops={
        "speed": setpoint(build(SetSpeed, speed_dps="speed_dps")),
        "reset": once(build(Restart), note="the motor restarts: no reply comes"),
    },
    why_not={
        "move": "the toy protocol has no position set-point; servobus speed, then stop",
        "torque": "the toy protocol has no current set-point",
        "mit": "the toy protocol has no impedance mode",
        "brake": "toy motors have no brake",
        "zero": "the toy protocol cannot set the zero",
        "set-id": "the toy id is set by hand, on the drive",
        "clear-errors": "a restart clears the latched faults: servobus reset",
    },
    settings=(
        setting_of(
            "speed_limit_dps",
            "the highest speed any set-point runs at, 0..1000 dps (flash)",
            write=WriteSpeedLimit,
            rom=True,
        ),
    ),
)

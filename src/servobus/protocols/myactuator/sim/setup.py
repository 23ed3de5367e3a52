"""The MyActuator simulator part (``FAMILY.part("sim")``): motors on CAN, or on the RS485 line."""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from servobus.protocols.myactuator.revision import Revision
from servobus.protocols.myactuator.sim.device import DEFAULT_TURNAROUND_S, MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.sim.family import Setup, SimFamily, SimOptions

__all__ = ["SIM", "MyActuatorSim"]

#: The RS485 rate when none is given: the manuals name no default (myactuator-v4.md §1.2).
DEFAULT_BAUD = 1_000_000


class MyActuatorSim(SimFamily):
    """V4.3/V4.4 motors on classic CAN, or each behind its RS485 ``3E`` framing at ``--baud``."""

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not a MyActuator Revision")
        motors = [MyActuatorMotor(i, revision=revision) for i in ids]
        if options.rs485:
            return Setup(serial_devices=[MyActuatorRs485Motor(m) for m in motors], baud=self.baud(options))
        return Setup(can_devices=motors)


SIM = MyActuatorSim(
    family="myactuator",
    media=("can", "rs485"),
    options=("baud",),
    turnaround_s=DEFAULT_TURNAROUND_S,
    default_baud=DEFAULT_BAUD,
)

"""The simulated lk devices: the family's protocol spoken from the device side (sans-IO, see servobus.sim)."""

from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.lk.sim.setup import SIM

__all__ = ["SIM", "LkMotor"]

"""The simulated lk devices: the family's protocol spoken from the device side (sans-IO, see servobus.sim)."""

from servobus.protocols.lk.sim.device import LkMotor

__all__ = ["LkMotor"]

"""The simulated hollow devices: the family's protocol from the device side (sans-IO)."""

from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import HollowMotor

__all__ = ["ConverterMode", "HollowConverter", "HollowMotor"]

"""The simulated hollow devices: the family's protocol from the device side (sans-IO)."""

from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.hollow.sim.setup import SIM

__all__ = ["SIM", "ConverterMode", "HollowConverter", "HollowMotor"]

"""The simulated myactuator devices: the family's protocol from the device side (sans-IO)."""

from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor
from servobus.protocols.myactuator.sim.setup import SIM

__all__ = ["SIM", "MyActuatorMotor", "MyActuatorRs485Motor"]

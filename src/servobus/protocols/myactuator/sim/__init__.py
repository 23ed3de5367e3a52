"""The simulated myactuator devices: the family's protocol from the device side (sans-IO)."""

from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.rs485 import MyActuatorRs485Motor

__all__ = ["MyActuatorMotor", "MyActuatorRs485Motor"]

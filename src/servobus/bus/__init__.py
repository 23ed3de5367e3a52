"""The Bus: one physical bus, its motors, and every request's life on it (:class:`Bus`).

``from servobus.bus import Bus, Motor, MotorStatus, FrameLink`` (``servobus.Bus`` is the same).

One control tick, ``await bus.cycle([(motor, command), ...])``, walked from the Bus to the link and
back (TICK_WALK_PLACEHOLDER)
"""

from servobus.bus.core import Bus
from servobus.bus.motor import Motor, MotorFrames, command_classes
from servobus.bus.watchdog import MotorStatus
from servobus.transports.contract import FrameLink

__all__ = ["Bus", "FrameLink", "Motor", "MotorFrames", "MotorStatus", "command_classes"]

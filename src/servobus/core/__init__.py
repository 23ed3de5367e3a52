"""servobus.core: the Python face of the C core (servobus._core).

* CRCs: :func:`crc16_modbus`, :func:`crc32_ieee`.
* Float <-> code scaling and frame bit layouts: :class:`FieldScale`, :class:`Packer`, the layouts.
* Stream de-framers: :class:`MyActuatorRs485Deframer`, :class:`HollowTransparentDeframer`,
  :class:`ModbusRtuDeframer`; SLCAN (LAWICEL) lines into Frames: :class:`SlcanDeframer`.

Sans-IO: nothing here awaits, sleeps or reads a clock. Only servobus.core._lib imports the
compiled module, and nothing above this package sees cdata.

The one exception, imported by name and not re-exported here: :mod:`servobus.core.timer`, the
pacer's CLOCK_MONOTONIC timerfd (system calls to arm and clear it; it never waits: the event loop
does, in servobus.ticks).
"""

from servobus.core.crc import crc16_modbus, crc32_ieee
from servobus.core.deframe import (
    Deframer,
    HollowTransparentDeframer,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
)
from servobus.core.packing import (
    HOLLOW_EXT_REPLY,
    HOLLOW_FD_COMMAND,
    HOLLOW_FD_REPLY,
    HOLLOW_SETPOINT,
    LAYOUTS,
    MIT_COMMAND,
    MIT_REPLY,
    FieldScale,
    Layout,
    Packer,
)
from servobus.core.slcan import SlcanDeframer

__all__ = [
    "HOLLOW_EXT_REPLY",
    "HOLLOW_FD_COMMAND",
    "HOLLOW_FD_REPLY",
    "HOLLOW_SETPOINT",
    "LAYOUTS",
    "MIT_COMMAND",
    "MIT_REPLY",
    "Deframer",
    "FieldScale",
    "HollowTransparentDeframer",
    "Layout",
    "ModbusRtuDeframer",
    "MyActuatorRs485Deframer",
    "Packer",
    "SlcanDeframer",
    "crc16_modbus",
    "crc32_ieee",
]

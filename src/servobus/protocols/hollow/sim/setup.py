"""The hollow simulator part (``FAMILY.part("sim")``): motors on CAN or CAN FD, or behind the
RS-485 -> CAN FD converter (transparent, or Modbus RTU with ``--modbus``)."""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from servobus.protocols import SerialLine
from servobus.protocols.hollow.bound import ModbusFraming, TransparentFraming
from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import DEFAULT_TURNAROUND_S, HollowMotor
from servobus.sim.family import Setup, SimFamily, SimOptions

__all__ = ["SIM", "HollowSim"]


class HollowSim(SimFamily):
    """Hollow motors: classic CAN, CAN FD (``fd``), or CAN FD behind the converter (``rs485``)."""

    def check(self, options: SimOptions) -> None:
        if options.fd and options.rs485:
            raise ValueError("--fd: behind --rs485 the hollow converter always talks CAN FD; drop --fd")
        if options.modbus and not options.rs485:
            raise ValueError("--modbus: the hollow converter's RS485 mode; it needs --rs485")
        super().check(options)

    def motor_ids(self, options: SimOptions) -> range:
        ids = super().motor_ids(options)
        # hollow.md §9.5: Modbus address 0 is the broadcast, never answered
        return range(max(ids.start, 1), ids.stop) if options.modbus else ids

    def motor_ids_note(self, options: SimOptions) -> str:
        return " with --modbus (Modbus address 0 is the broadcast)" if options.modbus else ""

    def serial_line(self, options: SimOptions) -> SerialLine:
        wanted = (ModbusFraming if options.modbus else TransparentFraming).name
        return next(line for line in self.protocol().serial if line.name == wanted)

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        if not options.rs485:
            return Setup(can_devices=[HollowMotor(i, fd_enabled=options.fd) for i in ids])
        mode = ConverterMode.MODBUS if options.modbus else ConverterMode.TRANSPARENT
        converter = HollowConverter([HollowMotor(i, fd_enabled=True) for i in ids], mode=mode)
        return Setup(serial_devices=[converter], baud=converter.baud)


SIM = HollowSim(
    family="hollow",
    media=("can", "canfd", "rs485"),
    options=("modbus",),
    turnaround_s=DEFAULT_TURNAROUND_S,
    refusals={"baud": "the hollow converter fixes its own rate (1000000 transparent, 19200 with --modbus)"},
)

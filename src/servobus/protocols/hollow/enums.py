"""The enums the hollow requests and replies share (hollow.md §0, §5.1, §6)."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["CanMode", "ControlMode", "PiGain"]


class ControlMode(IntEnum):
    """The control mode (hollow.md §0): CAN FD Mode Sel / Mode byte, and F9 + value in classic CAN."""

    TORQUE = 0  # "Moment": current loop, F9
    VELOCITY = 1  # speed-torque, FA
    POSITION = 2  # position-velocity-torque triple closed loop, FB


class CanMode(IntEnum):
    """Classic-CAN addressing mode; the value is D0 bit 1 of the mode-switch frame (§5.1, A4)."""

    EXTENDED = 0  # incremental position, 8-byte replies
    NORMAL = 1  # absolute position, 6-byte replies; the power-on default (§3)


class PiGain(IntEnum):
    """D1 of the motor's PI multiplier frame (§6). The converter numbers them one higher (A18)."""

    SPEED_KP = 0x01
    SPEED_KI = 0x02
    CURRENT_KP = 0x03
    CURRENT_KI = 0x04

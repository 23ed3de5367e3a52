"""``python -m servobus``: a self-check of the installed C core against the manuals' examples.

It stands where the demo on simulated motors will go once the simulator and the Bus land; until
then it proves the install works: every check below uses bytes printed in the vendor manuals.
Exit status 0 when every check passes, 1 otherwise.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from servobus import __version__
from servobus.core import (
    HOLLOW_SETPOINT,
    MIT_COMMAND,
    FieldScale,
    HollowTransparentDeframer,
    MyActuatorRs485Deframer,
    Packer,
    crc16_modbus,
    crc32_ieee,
)


def _mit_example() -> bytes:
    scales = [
        FieldScale.linear("position_rad", -12.5, 12.5, 16),
        FieldScale.linear("velocity_rad_s", -45.0, 45.0, 12),
        FieldScale.linear("kp", 0.0, 500.0, 12),
        FieldScale.linear("kd", 0.0, 5.0, 12),
        FieldScale.linear("torque_ff_nm", -24.0, 24.0, 12),
    ]
    return Packer(MIT_COMMAND, scales).pack([10.0, 2094 * 90 / 4095 - 45, 10.0, 1.0, 10.0])


def _hollow_example() -> bytes:
    scales = [
        FieldScale.offset_binary("position_deg", 360.0, 16),
        FieldScale.offset_binary("speed_rad_s", 200.0, 12),
        FieldScale.integer("kp", 0, 4095),
        FieldScale.integer("kd", 0, 4095),
        FieldScale.offset_binary("current_a", 4.0, 12),
    ]
    return Packer(HOLLOW_SETPOINT, scales).pack([180.0, 100.0, 0x100, 0x020, 2.0])


def _deframe_rs485() -> bytes:
    frame = bytes.fromhex("3E 01 08 9C 00 00 00 00 00 00 00 F2 30")
    deframer = MyActuatorRs485Deframer()
    frames = [f for b in b"\x00noise" + frame for f in deframer.feed(bytes([b]))]
    return b"".join(frames)


def _deframe_transparent() -> bytes:
    frame = bytes.fromhex("01" + "00" * 16 + "FE 3A 49 4E")
    return b"".join(HollowTransparentDeframer().feed(b"\xaa\xbb" + frame))


CHECKS: list[tuple[str, Callable[[], bytes], str]] = [
    (
        "CRC-16/MODBUS, MyActuator 0x9C read",
        lambda: crc16_modbus(bytes.fromhex("3E01089C00000000000000")).to_bytes(2, "little"),
        "F2 30",
    ),
    (
        "CRC-32, hollow transparent poll",
        lambda: crc32_ieee(bytes([1]) + bytes(16)).to_bytes(4, "little"),
        "FE 3A 49 4E",
    ),
    ("MIT pack, MyActuator motion example", _mit_example, "E6 66 82 E0 52 33 3B 55"),
    ("hollow setpoint, 180 deg / 100 rad/s / 2 A", _hollow_example, "C0 00 C0 01 00 02 0C 00"),
    ("RS485 de-framer, byte by byte after noise", _deframe_rs485, "3E 01 08 9C 00 00 00 00 00 00 00 F2 30"),
    ("transparent de-framer, CRC sync", _deframe_transparent, "01" + " 00" * 16 + " FE 3A 49 4E"),
]


def main() -> int:
    print(f"servobus {__version__}: self-check of the C core against the manuals' examples")
    failed = 0
    for name, check, expected in CHECKS:
        got = check()
        ok = got == bytes.fromhex(expected)
        failed += not ok
        print(f"  {'ok  ' if ok else 'FAIL'} {name}: {got.hex(' ').upper()}")
        if not ok:
            print(f"       expected {expected}")
    print("all checks passed" if not failed else f"{failed} check(s) failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Frames of every family, both directions, with what the family's own decoders make of them.

The oracle is the family's ``decode_request``/``decode_reply`` (never the code under test), so tests of
``servobus.tools.logs``, ``servobus decode`` and the log round trips compare byte-exactly against them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from servobus.frame import Frame
from servobus.protocols import Message, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma


@dataclass(frozen=True)
class Sample:
    family: str
    revision: str | None
    frame: Frame
    direction: str
    motor_id: int | None
    expected: Message


def _request(family: str, motor_id: int, command: Any, revision: str | None = None, **bind: Any) -> Sample:
    codec = get_family(family).bind(motor_id, **({"revision": revision} if revision else {}), **bind)
    frame = codec.encode(command)
    fam = get_family(family)
    options: dict[str, Any] = {"revision": codec.revision}
    if family == "hollow":
        options.update(is_extended_id=frame.is_extended_id, is_fd=frame.is_fd)
    expected = fam.decode_request(frame.arbitration_id, frame.data, **options)
    return Sample(family, revision, frame, "request", motor_id, expected)


def _reply(
    family: str, ident: int, data: bytes, motor_id: int | None, revision: str | None = None, fd: bool = False
) -> Sample:
    fam = get_family(family)
    options: dict[str, Any] = {"revision": fam.revision(revision) if revision else fam.default_revision}
    if family == "hollow":
        options["is_fd"] = fd
    expected = fam.decode_reply(ident, data, **options)
    frame = Frame(arbitration_id=ident, data=data, is_fd=fd, bitrate_switch=fd)
    return Sample(family, revision, frame, "reply", motor_id, expected)


SAMPLES: list[Sample] = [
    # MyActuator V4.4: standard requests and replies, an echo, error flags, a broadcast, motion mode.
    _request("myactuator", 1, ma.ReadStatus2()),
    _reply("myactuator", 0x241, bytes.fromhex("9C326400F4012D00"), 1),
    _request("myactuator", 2, ma.SpeedControl(speed_dps=123.45)),
    _reply("myactuator", 0x242, bytes.fromhex("A21EF6FF38FF10FF"), 2),
    _request("myactuator", 3, ma.AbsolutePositionControl(angle_deg=-90.5, max_speed_dps=500)),
    _reply("myactuator", 0x243, bytes.fromhex("9A2D2C0102020600"), 3),
    _reply("myactuator", 0x243, bytes.fromhex("8100000000000000"), 3),
    _reply("myactuator", 0x244, bytes.fromhex("9D28E803E8FC0000"), 4),
    _reply("myactuator", 0x244, bytes.fromhex("3001000000004842"), 4),
    _request(
        "myactuator",
        4,
        ma.MotionCommand(position_rad=1.5, velocity_rad_s=-2.0, kp=50, kd=1, torque_ff_nm=0.5),
    ),
    _reply(
        "myactuator",
        0x504,
        ma.MotionReply(motor_id=4, position_rad=1.0, velocity_rad_s=3.0, torque_nm=-2.5).encode(),
        4,
    ),
    # LK V2.36: replies on 0x180 + ID.
    _request("lk", 1, lk.ReadStatus2()),
    _reply("lk", 0x181, bytes.fromhex("9C1E64003200A01F"), 1),
    _request("lk", 2, lk.MotorOff()),
    _reply("lk", 0x182, bytes.fromhex("8000000000000000"), 2),
    # hollow: classic set-point and 6-byte reply, CAN FD command and reply (replies on host id 100).
    _request("hollow", 3, ho.Setpoint(position_deg=90, speed_rad_s=5, kp=100, kd=10, current_a=1)),
    _reply(
        "hollow", 100, ho.NormalReply(motor_id=3, position_deg=45, speed_rad_s=-2, current_a=0.5).encode(), 3
    ),
    _request("hollow", 5, ho.FdCommand(position_deg=720, velocity_rpm=30, run=True), link="canfd"),
    _reply(
        "hollow",
        100,
        ho.FdReply(slave_id=5, position_deg=-30, velocity_rpm=12, temperature_c=40).encode(),
        5,
        fd=True,
    ),
]

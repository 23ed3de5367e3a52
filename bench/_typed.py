"""Typed codec benchmark (part of bench_codec.py): the bound codecs against hand-written struct code.

What is measured, per frame, each through ``Family.bind()``, the path the Bus uses:

* **decode** of the control-loop replies: MyActuator R2 status (0x9C/0xA1..0xA9), 0x9A status 1, motion
  reply (0x500+ID); LK status 2 (0x9C/0xA1..0xA8); hollow normal and extended MIT replies and the CAN FD
  reply. ``typed_decode_us`` is the slowest of them.
* **encode** of the control-loop commands (a prebuilt, validated command to its Frame): MyActuator
  torque, speed, absolute position and motion commands; LK torque and speed. ``typed_encode_us`` is the
  slowest. Building the command itself (its range checks) is reported apart, as ``*_construct_us``.
* **batch decode**: ``decode_many`` of 32 motion replies (one C-core call), µs per frame.
* **the struct baseline**: the R2 status reply decoded by hand-written code, ``struct.unpack`` plus the
  scaling, into a hand-written frozen slotted dataclass with the same five fields (the same kind of
  object the bound codec returns). ``typed_vs_struct`` = our R2 decode time / the baseline's. A second
  baseline into a plain mutable slotted class (the cheapest object Python builds) is reported too, as
  ``typed_vs_struct_plain``, for the reader who wants the floor.

Method: ``timeit`` loops calibrated to ~0.2 s (quick: ~0.02 s), 7 repeats (quick: 3), median, in the
same process right after one another, so the ratios compare like with like on a noisy shared machine.
"""

from __future__ import annotations

import statistics
import struct
import timeit
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from servobus import Frame
from servobus.protocols import get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma

TARGET_US = 2.0
BATCH_TARGET_US = 0.5
RATIO_TARGET = 2.0


def _per_call_us(fn: Callable[[], Any], target_s: float, repeats: int, per: int = 1) -> float:
    timer = timeit.Timer(fn)
    n = 16
    while (took := timer.timeit(n)) < target_s / 8:  # calibration (and warm-up): ~1/8 of a repeat
        n *= 4
    n = max(1, int(n * target_s / took))
    times = timer.repeat(repeat=repeats, number=n)
    return statistics.median(times) / n / per * 1e6


@dataclass(frozen=True, slots=True)
class _HandStatus:
    command: int
    temperature_c: int
    current_a: float
    speed_dps: float
    angle_deg: float


class _PlainStatus:
    __slots__ = ("angle_deg", "command", "current_a", "speed_dps", "temperature_c")

    def __init__(
        self, command: int, temperature_c: int, current_a: float, speed_dps: float, angle_deg: float
    ):
        self.command = command
        self.temperature_c = temperature_c
        self.current_a = current_a
        self.speed_dps = speed_dps
        self.angle_deg = angle_deg


_R2 = struct.Struct("<Bbhhh")


def _hand_decode(frame: Frame) -> _HandStatus:
    c, t, i, s, a = _R2.unpack(frame.data)
    return _HandStatus(c, t, i / 100, float(s), float(a))


def _plain_decode(frame: Frame) -> _PlainStatus:
    c, t, i, s, a = _R2.unpack(frame.data)
    return _PlainStatus(c, t, i / 100, float(s), float(a))


def run(quick: bool, log: Callable[[str], None]) -> dict[str, Any]:
    """Measure; return the figures for results.json's ``codec`` key (``typed_*``)."""
    target_s, repeats = (0.02, 3) if quick else (0.2, 7)
    mab = get_family("myactuator").bind(1)
    lkb = get_family("lk").bind(1)
    hob = get_family("hollow").bind(1)
    hofd = get_family("hollow").bind(1, link="canfd")
    r2 = Frame(arbitration_id=0x241, data=bytes.fromhex("A1 32 64 00 F4 01 2D 00"))
    motion = ma.MotionReply(motor_id=1, position_rad=1.0, velocity_rad_s=2.0, torque_nm=3.0)
    motion_frame = Frame(arbitration_id=0x501, data=motion.encode())
    decodes: dict[str, tuple[Any, Frame]] = {
        "myactuator_status2": (mab, r2),
        "myactuator_status1": (
            mab,
            Frame(arbitration_id=0x241, data=bytes.fromhex("9A 32 00 01 E5 01 04 00")),
        ),
        "myactuator_motion": (mab, motion_frame),
        "lk_status2": (lkb, Frame(arbitration_id=0x181, data=bytes.fromhex("A1 32 64 00 F4 01 2D 00"))),
        "hollow_normal": (
            hob,
            Frame(
                arbitration_id=100,
                data=ho.NormalReply(motor_id=1, position_deg=10.0, speed_rad_s=1.0, current_a=0.5).encode(),
            ),
        ),
        "hollow_extended": (
            hob,
            Frame(
                arbitration_id=100,
                data=ho.ExtendedReply(motor_id=1, position_deg=10.0, speed_rad_s=1.0, current_a=0.5).encode(),
            ),
        ),
        "hollow_fd": (
            hofd,
            Frame(arbitration_id=100, data=ho.FdReply(slave_id=1, position_deg=3.0).encode(), is_fd=True),
        ),
    }
    encodes: dict[str, tuple[Any, Callable[[], Any]]] = {
        "myactuator_torque": (mab, lambda: ma.TorqueControl(current_a=1.5)),
        "myactuator_speed": (mab, lambda: ma.SpeedControl(speed_dps=100.0)),
        "myactuator_position": (mab, lambda: ma.AbsolutePositionControl(angle_deg=90.0, max_speed_dps=360.0)),
        "myactuator_motion": (
            mab,
            lambda: ma.MotionCommand(position_rad=1.0, velocity_rad_s=0.5, kp=20.0, kd=1.0, torque_ff_nm=0.5),
        ),
        "lk_torque": (lkb, lambda: lk.TorqueControl(motor_type=lk.MotorType.MG, current_a=1.5)),
        "lk_speed": (
            lkb,
            lambda: lk.SpeedControl(motor_type=lk.MotorType.MG, speed_dps=100.0, current_limit_a=5.0),
        ),
    }
    out: dict[str, Any] = {}
    decode_us: dict[str, float] = {}
    for name, (codec, frame) in decodes.items():
        decode_us[name] = _per_call_us(lambda c=codec, f=frame: c.decode(f), target_s, repeats)
        log(f"  typed decode {name:<20} {decode_us[name]:6.2f} µs")
    encode_us: dict[str, float] = {}
    construct_us: dict[str, float] = {}
    for name, (codec, build) in encodes.items():
        command = build()
        encode_us[name] = _per_call_us(lambda c=codec, m=command: c.encode(m), target_s, repeats)
        construct_us[name] = _per_call_us(build, target_s, repeats)
        built = construct_us[name]
        log(f"  typed encode {name:<20} {encode_us[name]:6.2f} µs (building the command: {built:.2f} µs)")
    batch = [motion_frame] * 32
    batch_us = _per_call_us(lambda: mab.decode_many(batch), target_s, repeats, per=32)
    log(f"  batch decode motion x32         {batch_us:6.2f} µs/frame")
    ours = _per_call_us(lambda: mab.decode(r2), target_s, repeats)
    hand = _per_call_us(lambda: _hand_decode(r2), target_s, repeats)
    plain = _per_call_us(lambda: _plain_decode(r2), target_s, repeats)
    log(f"  R2 status: bound {ours:.2f} µs, struct + frozen dataclass {hand:.2f} µs, plain {plain:.2f} µs")
    out["typed_decode_us"] = round(max(decode_us.values()), 3)
    out["typed_decode_slowest"] = max(decode_us, key=decode_us.__getitem__)
    out["typed_encode_us"] = round(max(encode_us.values()), 3)
    out["typed_encode_slowest"] = max(encode_us, key=encode_us.__getitem__)
    out["batch_decode_us"] = round(batch_us, 3)
    out["typed_vs_struct"] = round(ours / hand, 2)
    out["typed_vs_struct_plain"] = round(ours / plain, 2)
    if not quick:
        import _profile

        def hot_path() -> None:
            for _ in range(50_000):
                mab.decode(r2)
            command = ma.MotionCommand(
                position_rad=1.0, velocity_rad_s=0.5, kp=20.0, kd=1.0, torque_ff_nm=0.5
            )
            for _ in range(50_000):
                mab.encode(command)

        out["typed_profile"] = _profile.cprofile(hot_path, top=10)
    out["typed_detail"] = {
        "decode_us": {k: round(v, 3) for k, v in decode_us.items()},
        "encode_us": {k: round(v, 3) for k, v in encode_us.items()},
        "construct_us": {k: round(v, 3) for k, v in construct_us.items()},
        "status2_us": {
            "bound": round(ours, 3),
            "struct_frozen": round(hand, 3),
            "struct_plain": round(plain, 3),
        },
        "targets": {
            "typed_decode_us": TARGET_US,
            "typed_encode_us": TARGET_US,
            "batch_decode_us": BATCH_TARGET_US,
            "typed_vs_struct": RATIO_TARGET,
        },
    }
    return out


def misses(figures: dict[str, Any]) -> list[str]:
    """The typed targets a run missed, as sentences."""
    out = []
    for key, limit in figures["typed_detail"]["targets"].items():
        if figures[key] > limit:
            out.append(f"{key} = {figures[key]} (target <= {limit})")
    return out


def markdown(figures: dict[str, Any]) -> list[str]:
    """Lines for the codec section of RESULTS.md."""
    detail = figures["typed_detail"]
    lines = [
        "",
        "### Typed codec through `Family.bind()` (per frame, median)",
        "",
        "| frame | decode µs |",
        "|---|---|",
        *(f"| {k} | {v:.2f} |" for k, v in detail["decode_us"].items()),
        "",
        "| command | encode µs | building the command µs |",
        "|---|---|---|",
        *(f"| {k} | {v:.2f} | {detail['construct_us'][k]:.2f} |" for k, v in detail["encode_us"].items()),
        "",
        f"- `typed_decode_us` (slowest hot reply, {figures['typed_decode_slowest']}): "
        f"**{figures['typed_decode_us']:.2f} µs** (target ≤ {TARGET_US})",
        f"- `typed_encode_us` (slowest hot command, {figures['typed_encode_slowest']}): "
        f"**{figures['typed_encode_us']:.2f} µs** (target ≤ {TARGET_US})",
        f"- `batch_decode_us` (32 motion replies, one C call): **{figures['batch_decode_us']:.2f} µs/frame** "
        f"(target ≤ {BATCH_TARGET_US})",
        f"- `typed_vs_struct` (R2 status: bound decode / struct into a frozen slotted dataclass): "
        f"**{figures['typed_vs_struct']:.2f}** (target ≤ {RATIO_TARGET}); against struct into a plain "
        f"mutable slotted class: {figures['typed_vs_struct_plain']:.2f}",
    ]
    if figures.get("typed_profile"):
        import _profile

        lines += [
            "",
            "#### Where the time goes: 50,000 R2 status decodes and 50,000 motion-command encodes through "
            "`Family.bind()` (cProfile)",
            "",
            *_profile.markdown(figures["typed_profile"], 10),
        ]
    return lines

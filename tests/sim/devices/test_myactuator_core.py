"""The MyActuator C path (csrc/sim_myactuator.c) against the Python model, the reference.

Two motors are built the same way: one Python-only, one attached to a C twin (an ``sb_simmotor``)
and driven as the engine drives it: frames and deadlines go to ``lib.sb_ma_receive`` /
``lib.sb_ma_poll`` first, and to the model's ``receive`` / ``poll`` when C says SB_HOT_COLD, with
``core_push()`` after every call into the model. Seeded traces of every hot command (both revisions,
random values up to the fields' limits, garbage too) interleaved with cold commands, injected errors,
reboots, 0xB3 trips and streams must give the same reply bytes at the same times, the same deadlines,
the same counters, the same model state and the same plant state, bit for bit (floats compared with
``==`` and by their bit patterns: no tolerance).
"""

from __future__ import annotations

import math
import random
import struct
import timeit
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator import ErrorFlags, Revision
from servobus.protocols.myactuator.codec import request_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.coreplant import CorePlant
from servobus.sim.device import Emission
from servobus.sim.plant import Plant

Sent = tuple[float, int, bytes]  # ready time, identifier, data

CAP = 16


class Twin:
    """A model attached to a C twin, driven the way the engine drives it (no network)."""

    def __init__(self, device: MyActuatorMotor) -> None:
        self.device = device
        self.motor = ffi.new("sb_simmotor *")
        device.core_attach(self.motor, None)
        self.frame_in = ffi.new("sb_simframe *")
        self.out = ffi.new("sb_simframe[]", CAP)
        self.n_out = ffi.new("int *")
        self.hot = self.cold = 0
        self.hot_codes: set[int] = set()  # DATA[0] of the frames C acted on (0x400: motion mode)

    def _c_frames(self) -> list[Sent]:
        out = self.out
        return [(out[i].t, out[i].id, bytes(out[i].data[0 : out[i].len])) for i in range(self.n_out[0])]

    def python(self, call: Callable[[], Any]) -> Any:
        result = call()
        self.device.core_push()
        return result

    def receive(self, frame: Frame, now_s: float) -> list[Sent]:
        f = self.frame_in
        f.id = frame.arbitration_id
        f.flags = (lib.SB_FRAME_EXT if frame.is_extended_id else 0) | (lib.SB_FRAME_FD if frame.is_fd else 0)
        f.len = len(frame.data)
        f.data[0 : len(frame.data)] = frame.data
        accepted = self.motor.counters[lib.SB_MA_CTR_ACCEPTED]
        status = lib.sb_ma_receive(self.motor, f, now_s, self.out, CAP, self.n_out)
        if status == lib.SB_HOT_DONE:
            self.hot += 1
            if self.motor.counters[lib.SB_MA_CTR_ACCEPTED] != accepted:
                self.hot_codes.add(0x400 if frame.arbitration_id & 0x400 else frame.data[0])
            return self._c_frames()
        assert status == lib.SB_HOT_COLD, status
        assert self.n_out[0] == 0
        self.cold += 1
        emissions = self.python(lambda: self.device.receive(frame, now_s))
        return [(e.ready_s, e.frame.arbitration_id, e.frame.data) for e in emissions]

    def next_deadline_s(self) -> float | None:
        c = lib.sb_ma_next_deadline(self.motor)
        py = self.device.next_deadline_s()
        found = c if py is None else min(c, py)
        return None if found == math.inf else found

    def poll(self, now_s: float) -> list[Sent]:
        """Everything due by now_s: C's streams, else (COLD) the model's poll."""
        sent: list[Sent] = []
        for _ in range(10):
            if lib.sb_ma_next_deadline(self.motor) <= now_s:
                status = lib.sb_ma_poll(self.motor, now_s, self.out, CAP, self.n_out)
                if status == lib.SB_HOT_DONE:
                    sent += self._c_frames()
                    continue
                assert status == lib.SB_HOT_COLD, status
            py = self.device.next_deadline_s()
            if py is None or py > now_s:
                return sent
            emissions = self.python(lambda: self.device.poll(now_s))
            sent += [(e.ready_s, e.frame.arbitration_id, e.frame.data) for e in emissions]
        raise AssertionError("the twin's deadlines do not move")


def _sent(emissions: list[Emission]) -> list[Sent]:
    return [(e.ready_s, e.frame.arbitration_id, e.frame.data) for e in emissions]


def _python_poll(device: MyActuatorMotor, now_s: float) -> list[Sent]:
    sent: list[Sent] = []
    while (deadline := device.next_deadline_s()) is not None and deadline <= now_s:
        sent += _sent(device.poll(now_s))
    return sent


# ---- comparing the two ----


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _plant_state(plant: Plant | CorePlant) -> tuple[Any, ...]:
    python = plant.to_python() if isinstance(plant, CorePlant) else plant
    return (
        python.control,
        *(
            _bits(v)
            for v in (
                python.now_s,
                python.position_deg,
                python.speed_dps,
                python.current_a,
                python.temperature_c,
                python.acceleration_dps2,
            )
        ),
        python._anchor,
        python._steps,
        python._resting,
        tuple(_bits(getattr(python._committed, n)) for n in ("position_deg", "speed_dps", "current_a")),
    )


def _model_state(device: MyActuatorMotor) -> tuple[Any, ...]:
    return (
        device.control,
        device.run_mode,
        device.brake_released,
        device.feedforward_pct,
        device.comm_tripped,
        device.protection_deadline_s(),
        {k: (s.interval_s, s.origin_s, s.count) for k, s in device.streams.items()},
        list(device.streams),
        device.motor_id,
        device.errors.flags,
    )


def _same(py: MyActuatorMotor, twin: Twin, where: str) -> None:
    c = twin.device
    assert dict(c.counters) == dict(py.counters), where
    assert _model_state(c) == _model_state(py), where
    assert _plant_state(c.plant) == _plant_state(py.plant), where


# ---- the traces ----

_STREAMABLE = [int(s) for s in ma.StreamableCommand]
_HOT_CODES = (0xA1, 0xA2, 0xA4, 0xA6, 0xA8, 0xA9, 0x72, 0x73, 0x9A, 0x9C, 0x9D, 0x92, 0x60, 0x61, 0x62)


def _hot_data(rng: random.Random) -> bytes:
    """A hot command's 8 bytes with random values, limits included (and a few that do not decode)."""
    code = rng.choice(_HOT_CODES)
    data = bytearray(8)
    data[0] = code
    extreme = rng.random() < 0.15

    def i32() -> bytes:
        if extreme:
            return rng.choice((-(1 << 31), (1 << 31) - 1, 0)).to_bytes(4, "little", signed=True)
        return rng.randint(-200_000, 200_000).to_bytes(4, "little", signed=True)

    if code == 0xA1:
        value = rng.choice((-32768, 32767)) if extreme else rng.randint(-3000, 3000)
        data[4:6] = value.to_bytes(2, "little", signed=True)
    elif code == 0xA2:
        data[1] = rng.choice((0, 0, rng.randint(1, 255)))
        speed = rng.randint(-(1 << 31), (1 << 31) - 1) if extreme else rng.randint(-150_000, 150_000)
        data[4:8] = speed.to_bytes(4, "little", signed=True)
    elif code in (0xA4, 0xA8, 0xA9, 0x72, 0x73):
        data[1] = rng.randint(0, 255)
        data[2:4] = rng.choice((0, rng.randint(1, 2000), 65535)).to_bytes(2, "little")
        data[4:8] = i32()
    elif code == 0xA6:
        data[1] = rng.choice((0, 1, 1, 0, 2))
        data[2:4] = rng.choice((0, rng.randint(1, 2000))).to_bytes(2, "little")
        data[4:6] = rng.choice((0, 36000, 36001, rng.randint(0, 36000))).to_bytes(2, "little")
    if rng.random() < 0.1:  # a NULL byte that is not: decoders ignore it
        data[rng.randint(1, 7)] |= rng.randint(0, 255)
    return bytes(data)


def _stream_data(rng: random.Random) -> bytes:
    enabled = rng.random() < 0.6
    interval = rng.choice((0, 1, 2, 3, 5)) if enabled else rng.choice((0, 3))
    return bytes([0xB6, rng.choice(_STREAMABLE), int(enabled), interval, 0, 0, 0, 0])


def _cold_command(rng: random.Random, revision: Revision) -> Any:
    choices: list[Any] = [
        ma.ReadPid(index=ma.PidIndex.SPEED_KP),
        ma.WritePidRam(index=ma.PidIndex.CURRENT_KI, value=rng.uniform(0, 2)),
        ma.WriteAcceleration(
            index=rng.choice(list(ma.AccelIndex)), acceleration_dps_s=rng.choice((None, 100, 5000, 60000))
        ),
        ma.WriteCurrentPositionAsZero(),
        ma.WriteEncoderZero(offset_counts=rng.randint(-5000, 5000)),
        ma.BrakeRelease(),
        ma.BrakeLock(),
        ma.MotorShutdown(),
        ma.MotorStop(),
        ma.SetCommTimeout(timeout_ms=rng.choice((None, 15, 40, 120))),
        ma.ReadRunMode(),
        ma.ReadRunTime(),
        ma.ReadSingleTurnAngle(),
        ma.FunctionControl.can_id_filter(rng.random() < 0.3),
        ma.FunctionControl.save_multi_turn(rng.random() < 0.5),
        ma.FunctionControl.error_reporting(rng.random() < 0.5),
        ma.SystemReset(),
    ]
    return rng.choice(choices)


def _frame(rng: random.Random, device: MyActuatorMotor) -> Frame:
    motor_id, revision = device.motor_id, device.revision
    roll = rng.random()
    if roll < 0.55:
        can_id = 0x280 if rng.random() < 0.15 else 0x140 + motor_id
        return Frame(arbitration_id=can_id, data=_hot_data(rng))
    if roll < 0.68:
        return Frame(arbitration_id=0x400 + motor_id, data=bytes(rng.randint(0, 255) for _ in range(8)))
    if roll < 0.74:
        return Frame(arbitration_id=0x140 + motor_id, data=_stream_data(rng))
    if roll < 0.78:  # other identifiers and kinds, short frames
        kind = rng.randint(0, 4)
        if kind == 0:
            return Frame(arbitration_id=0x140 + motor_id, data=b"\x9c\x00", is_extended_id=True)
        if kind == 1:
            return Frame(arbitration_id=0x140 + motor_id, data=bytes(8), is_fd=True)
        if kind == 2:
            return Frame(arbitration_id=0x140 + motor_id, data=b"\x9c\x00\x00")
        if kind == 3:
            return Frame(arbitration_id=0x300, data=bytes([0x79, 0, 1, 0, 0, 0, 0, 0]))
        return Frame(arbitration_id=0x140 + (motor_id % 32) + 1, data=bytes([0x9C, 0, 0, 0, 0, 0, 0, 0]))
    command = _cold_command(rng, revision)
    broadcast = rng.random() < 0.1
    return request_frame(command, motor_id, revision=revision, broadcast=broadcast)


def _event(rng: random.Random, device: MyActuatorMotor, faults: bool) -> tuple[str, Any]:
    roll = rng.random()
    if roll < 0.955 or not faults:
        return "frame", _frame(rng, device)
    if roll < 0.962:
        flags = (ErrorFlags.STALL, ErrorFlags.LOW_VOLTAGE, ErrorFlags.OVER_SPEED, ErrorFlags.OVER_VOLTAGE)
        return "inject_error", rng.choice(flags)
    if roll < 0.98:
        return (
            "clear_error",
            ErrorFlags.STALL | ErrorFlags.LOW_VOLTAGE | ErrorFlags.OVER_SPEED | ErrorFlags.OVER_VOLTAGE,
        )
    if roll < 0.988:
        return "reboot", None
    return "unresponsive", rng.random() < 0.3


def _build(seed: int, revision: Revision) -> MyActuatorMotor:
    rng = random.Random(seed)
    return MyActuatorMotor(
        rng.randint(1, 32),
        revision=revision,
        has_brake=rng.random() < 0.7,
        turnaround_s=rng.choice((200e-6, 0.0, 1e-3)),
    )


def run_trace(seed: int, revision: Revision, steps: int, *, faults: bool = True) -> Twin:
    """Drive both motors through one seeded trace, comparing everything after every step."""
    py, c = _build(seed, revision), _build(seed, revision)
    twin = Twin(c)
    rng = random.Random(seed * 7919 + 1)
    t = 0.0
    for step in range(steps):
        t += rng.choice((1e-4, 5e-4, 1e-3, 1e-3, 2e-3, 7e-3, 0.02, 0.05))
        # the deadlines due before the event, as the network runs them
        while True:
            deadline = py.next_deadline_s()
            assert deadline == twin.next_deadline_s(), f"seed {seed} step {step}: deadlines"
            if deadline is None or deadline > t:
                break
            assert _python_poll(py, deadline) == twin.poll(deadline), f"seed {seed} step {step}: poll"
            _same(py, twin, f"seed {seed} step {step} poll at {deadline}")
        kind, arg = _event(rng, py, faults)
        where = f"seed {seed} step {step} {kind} {arg!r} at {t}"
        if kind == "frame":
            assert _sent(py.receive(arg, t)) == twin.receive(arg, t), where
        elif kind == "unresponsive":
            py.unresponsive = arg
            c.unresponsive = arg
        else:
            method: Callable[..., None] = getattr(py, kind)
            twin_method: Callable[..., None] = getattr(c, kind)
            if arg is None:
                method(t)
                twin.python(lambda m=twin_method, at=t: m(at))
            else:
                method(arg, t)
                twin.python(lambda m=twin_method, a=arg, at=t: m(a, at))
        _same(py, twin, where)
    return twin


@pytest.mark.parametrize("revision", [Revision.V4_3, Revision.V4_4], ids=lambda r: r.name)
@pytest.mark.parametrize("seed", range(12))
def test_c_path_matches_the_model_on_a_seeded_trace(seed: int, revision: Revision) -> None:
    """Faults on: errors injected and cleared, reboots, an unresponsive motor, 0xB3 trips."""
    twin = run_trace(seed, revision, 600)
    assert twin.hot > 30 and twin.cold > 30  # both paths taken, and the hand-overs between them


@pytest.mark.parametrize("revision", [Revision.V4_3, Revision.V4_4], ids=lambda r: r.name)
@pytest.mark.parametrize("seed", range(100, 104))
def test_c_path_handles_every_hot_command_on_a_clean_trace(seed: int, revision: Revision) -> None:
    twin = run_trace(seed, revision, 1500, faults=False)
    hot = {0xA1, 0xA2, 0xA4, 0xA6, 0xA8, 0xA9, 0x9A, 0x9C, 0x9D, 0x92, 0x60, 0x61, 0x62, 0xB6, 0x400}
    if revision is Revision.V4_4:
        hot |= {0x72, 0x73}
    assert twin.hot_codes == hot
    assert twin.hot > twin.cold


def test_c_path_counts_and_streams_like_the_model_through_a_long_quiet_stream() -> None:
    """Streams at 10 ms for 5 s, polled late sometimes (skipped slots), while set-points go silent."""
    py, c = MyActuatorMotor(3), MyActuatorMotor(3)
    twin = Twin(c)
    for data, at in (
        (bytes([0xB6, 0x9C, 1, 1, 0, 0, 0, 0]), 0.001),
        (bytes([0xB6, 0x92, 1, 3, 0, 0, 0, 0]), 0.002),
    ):
        frame = Frame(arbitration_id=0x143, data=data)
        assert _sent(py.receive(frame, at)) == twin.receive(frame, at) == []
    t = 0.002
    rng = random.Random(3)
    for _ in range(500):
        t += 0.01
        late = t + rng.choice((0.0, 0.0, 0.025))
        assert _python_poll(py, late) == twin.poll(late)
        frame = request_frame(ma.SpeedControl(speed_dps=rng.uniform(-500, 500)), 3)
        assert _sent(py.receive(frame, late)) == twin.receive(frame, late) == []
        t = late
    _same(py, twin, "end")
    assert c.counters["stream_frames"] > 500 and c.counters["stream_skipped"] > 0
    assert c.counters["silenced_by_active_reply"] == 500 and twin.cold == 0


def test_detach_gives_back_a_python_model_that_goes_on_the_same() -> None:
    py, c = MyActuatorMotor(5), MyActuatorMotor(5)
    twin = Twin(c)
    frame = request_frame(ma.AbsolutePositionControl(angle_deg=90.0, max_speed_dps=300.0), 5)
    assert _sent(py.receive(frame, 0.01)) == twin.receive(frame, 0.01)
    c.core_detach()
    assert isinstance(c.plant, Plant) and c._core is None
    status = request_frame(ma.ReadStatus2(), 5)
    assert _sent(py.receive(status, 0.5)) == _sent(c.receive(status, 0.5))
    _same_plain = (dict(py.counters), _model_state(py), _plant_state(py.plant))
    assert _same_plain == (dict(c.counters), _model_state(c), _plant_state(c.plant))


def test_a_subclass_that_overrides_the_model_keeps_the_python_path() -> None:
    class Tagged(MyActuatorMotor):
        def receive(self, frame: Frame, now_s: float) -> Any:
            return super().receive(frame, now_s)

    twin = Twin(Tagged(1))
    assert twin.motor.hot == 0
    assert len(twin.receive(request_frame(ma.ReadStatus2(), 1), 0.1)) == 1 and twin.cold == 1


def test_a_class_patched_to_watch_the_model_keeps_the_python_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """As tests/cli/test_control.py watches every frame a motor receives: C must not answer past it."""
    seen: list[Frame] = []

    def receive(self: Any, frame: Frame, now_s: float, _original: Any = MyActuatorMotor.receive) -> Any:
        seen.append(frame)
        return _original(self, frame, now_s)

    monkeypatch.setattr(MyActuatorMotor, "receive", receive)
    twin = Twin(MyActuatorMotor(1))
    status = request_frame(ma.ReadStatus2(), 1)
    assert len(twin.receive(status, 0.1)) == 1 and seen == [status] and twin.cold == 1
    monkeypatch.undo()
    twin.device.core_push()
    assert len(twin.receive(status, 0.2)) == 1 and seen == [status] and twin.hot == 1


def test_unresponsive_set_from_outside_stops_the_c_path_at_once() -> None:
    twin = Twin(MyActuatorMotor(2))
    status = request_frame(ma.ReadStatus2(), 2)
    assert len(twin.receive(status, 0.1)) == 1 and twin.hot == 1
    twin.device.unresponsive = True
    assert twin.receive(status, 0.2) == [] and twin.cold == 1
    assert twin.device.counters["unanswered"] == 1


def test_c_entry_points_refuse_bad_arguments() -> None:
    motor = ffi.new("sb_simmotor *")
    frame = ffi.new("sb_simframe *")
    out = ffi.new("sb_simframe[]", 4)
    n = ffi.new("int *")
    # not a myactuator twin, NULLs, a bad length, a negative capacity
    assert lib.sb_ma_receive(motor, frame, 0.0, out, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_poll(motor, 0.0, out, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_next_deadline(motor) == math.inf
    assert lib.sb_ma_next_deadline(ffi.NULL) == math.inf
    twin = Twin(MyActuatorMotor(1))
    m = twin.motor
    assert lib.sb_ma_receive(ffi.NULL, frame, 0.0, out, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_receive(m, ffi.NULL, 0.0, out, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_receive(m, frame, 0.0, ffi.NULL, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_receive(m, frame, 0.0, out, -1, n) == lib.SB_E_ARG
    assert lib.sb_ma_receive(m, frame, math.nan, out, 4, n) == lib.SB_E_ARG
    assert lib.sb_ma_poll(m, 0.0, out, 4, ffi.NULL) == lib.SB_E_ARG
    frame.len = 65
    assert lib.sb_ma_receive(m, frame, 0.0, out, 4, n) == lib.SB_E_ARG
    # a reply with nowhere to go is refused before anything changes
    frame.id, frame.len = 0x141, 8
    frame.data[0:8] = bytes([0x9C, 0, 0, 0, 0, 0, 0, 0])
    assert lib.sb_ma_receive(m, frame, 0.1, out, 0, n) == lib.SB_E_ARG
    assert twin.device.counters["received"] == 0
    # a state written from outside that the arithmetic cannot take: cold, never undefined behaviour
    state = ffi.cast("sb_ma_state *", m.state)
    state.counts_per_turn = 0
    assert lib.sb_ma_receive(m, frame, 0.1, out, 4, n) == lib.SB_HOT_COLD
    state.counts_per_turn, state.n_streams = 16384, 99
    assert lib.sb_ma_receive(m, frame, 0.1, out, 4, n) == lib.SB_HOT_COLD
    assert lib.sb_ma_next_deadline(m) == math.inf
    state.n_streams, m.plant.max_step_s = 0, 0.0
    assert lib.sb_ma_receive(m, frame, 0.1, out, 4, n) == lib.SB_HOT_COLD
    assert lib.sb_ma_poll(m, 0.1, out, 4, n) == lib.SB_HOT_COLD


def test_fuzz_random_frames_into_the_c_path_match_the_model() -> None:
    """Random identifiers near the motor's, random lengths and bytes (the fuzz target's frames)."""
    rng = random.Random(27)
    py, c = MyActuatorMotor(7, revision=Revision.V4_3), MyActuatorMotor(7, revision=Revision.V4_3)
    twin = Twin(c)
    t = 0.0
    for step in range(3000):
        t += 0.0007
        can_id = rng.choice((0x147, 0x147, 0x280, 0x300, 0x407, 0x146, 0x247))
        data = bytes([rng.choice((*_HOT_CODES, 0xB6, 0x00, 0xFF))]) + bytes(
            rng.randint(0, 255) for _ in range(rng.choice((7, 7, 7, 0, 3)))
        )
        frame = Frame(arbitration_id=can_id, data=data)
        assert _python_poll(py, t) == twin.poll(t), step
        assert _sent(py.receive(frame, t)) == twin.receive(frame, t), (step, frame)
    _same(py, twin, "fuzz")


_FUZZ_IDS = (0x141, 0x141, 0x141, 0x280, 0x300, 0x401, 0x401, 0x142, 0x241, 0x501)
_FUZZ_CODES = (*_HOT_CODES, 0xB6, 0xB6, 0x80, 0x77, 0xB3)


def _fuzz_frames(data: bytes) -> list[tuple[float, Frame]]:
    """Frames from fuzz bytes: per frame an identifier, a kind, a length, a time step and the bytes."""
    frames: list[tuple[float, Frame]] = []
    t, at = 0.0, 0
    while at + 4 <= len(data):
        pick, kind, size, step = data[at : at + 4]
        at += 4
        length = (8, 8, 8, 8, 0, 3, 7, 12)[size % 8] if kind % 8 != 7 else 64
        body = bytearray(data[at : at + length].ljust(length, b"\0"))
        at += length
        if body and kind & 0x10:
            body[0] = _FUZZ_CODES[body[0] % len(_FUZZ_CODES)]  # mostly commands the C path knows
        t += (step % 64) * 5e-4
        fd = length > 8 or kind % 8 == 6
        ext = kind % 8 == 5
        frames.append((t, Frame(arbitration_id=_FUZZ_IDS[pick % len(_FUZZ_IDS)], data=bytes(body), is_fd=fd,
                                is_extended_id=ext)))  # fmt: skip
    return frames


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.binary(max_size=400), st.sampled_from([Revision.V4_3, Revision.V4_4]))
def test_fuzz_frames_into_the_c_path(data: bytes, revision: Revision) -> None:
    """The fuzz target of the C device path: any frames, the C path and the model agree (and under
    .ci/sanitize's ASan + UBSan, C reads and writes nothing it should not)."""
    py, c = MyActuatorMotor(1, revision=revision), MyActuatorMotor(1, revision=revision)
    twin = Twin(c)
    for t, frame in _fuzz_frames(data):
        assert _python_poll(py, t) == twin.poll(t)
        assert _sent(py.receive(frame, t)) == twin.receive(frame, t), frame
    _same(py, twin, "fuzz")


# ---- cost (reported by the test, not asserted beyond a sanity bound) ----


def _cost_ns(call: Callable[[], object], number: int) -> float:
    return min(timeit.repeat(call, number=number, repeat=5)) / number * 1e9


def test_cost_of_a_set_point_and_a_status_read(capsys: pytest.CaptureFixture[str]) -> None:
    twin = Twin(MyActuatorMotor(1))
    m, f, out, n = twin.motor, twin.frame_in, twin.out, twin.n_out
    receive = lib.sb_ma_receive
    f.id, f.len = 0x141, 8
    speed = request_frame(ma.SpeedControl(speed_dps=100.0), 1).data
    status = request_frame(ma.ReadStatus2(), 1).data
    clock = [0.0]

    def c_call(data: bytes) -> Callable[[], object]:
        f.data[0:8] = data

        def call() -> object:
            clock[0] += 1e-3
            return receive(m, f, clock[0], out, CAP, n)

        return call

    c_speed = _cost_ns(c_call(speed), 20000)
    c_status = _cost_ns(c_call(status), 20000)
    py = MyActuatorMotor(1)
    py_clock = [0.0]

    def py_call(data: bytes) -> Callable[[], object]:
        frame = Frame(arbitration_id=0x141, data=data)

        def call() -> object:
            py_clock[0] += 1e-3
            return py.receive(frame, py_clock[0])

        return call

    py_speed = _cost_ns(py_call(speed), 2000)
    py_status = _cost_ns(py_call(status), 2000)
    with capsys.disabled():
        print(
            f"\nsb_ma_receive: 0xA2 {c_speed:.0f} ns, 0x9C {c_status:.0f} ns (cffi call included); "
            f"Python model: 0xA2 {py_speed / 1000:.1f} µs, 0x9C {py_status / 1000:.1f} µs"
        )
    assert c_speed < py_speed and c_status < py_status


# ---- through the engine: 32 C motors on CoreCanNetwork against 32 Python ones on SimCanNetwork ----


def _bus_trace(make: Callable[..., Any], seed: int, ticks: int) -> tuple[list[tuple[float, Frame]], Any, int]:
    """A 1 kHz loop over 32 motors (both revisions, 4 a tick) with cold commands, streams and faults
    mixed in; the host's trace, the motors' states at the end and how many frames Python received."""
    from servobus.sim.canbus import CanBusModel

    rng = random.Random(seed)
    motors = [
        MyActuatorMotor(i, revision=Revision.V4_3 if i % 3 == 0 else Revision.V4_4, has_brake=i % 4 != 0)
        for i in range(1, 33)
    ]
    python_calls = [0]
    for motor in motors:  # counts the frames the model itself receives (an instance wrapper: C stays on)

        def counted(frame: Frame, now_s: float, _receive: Any = motor.receive) -> Any:
            python_calls[0] += 1
            return _receive(frame, now_s)

        motor.receive = counted  # type: ignore[method-assign]
    network = make(motors, bus=CanBusModel(bitrate=1_000_000))
    trace: list[tuple[float, Frame]] = []
    for tick in range(ticks):
        t = tick * 1e-3
        trace += network.advance(t)
        now = max(t, network.now_s)
        for motor in motors[tick % 8 :: 8]:  # 4 a tick: the 1 Mbit/s bus keeps up
            i, revision = motor.motor_id, motor.revision
            roll = rng.random()
            if roll < 0.35:
                command: Any = ma.SpeedControl(
                    speed_dps=rng.uniform(-400, 400), max_torque_pct=rng.choice((None, 50))
                )
            elif roll < 0.6:
                command = ma.ReadStatus2()
            elif roll < 0.7:
                command = ma.AbsolutePositionControl(angle_deg=rng.uniform(-720, 720), max_speed_dps=500.0)
            elif roll < 0.8:
                position = rng.uniform(-3, 3)
                command = ma.MotionCommand(
                    position_rad=position, velocity_rad_s=0.0, kp=20.0, kd=1.0, torque_ff_nm=0.0,
                    scales=motor.motion_scales,
                )  # fmt: skip
            elif roll < 0.85:
                command = rng.choice((ma.ReadStatus1(), ma.ReadEncoderPosition(), ma.ReadMultiTurnAngle()))
            elif roll < 0.87:
                command = ma.ActiveReply(
                    command=ma.StreamableCommand.STATUS_2, enabled=rng.random() < 0.5, interval_ms=20
                )
            else:
                command = _cold_command(rng, revision)
            network.send(request_frame(command, i, revision=revision), now)
        if tick % 97 == 50:
            motor = motors[rng.randrange(32)]
            fault = rng.randrange(4)
            if fault == 0:
                motor.inject_error(ErrorFlags.LOW_VOLTAGE, now)
            elif fault == 1:
                motor.clear_error(ErrorFlags.LOW_VOLTAGE, now)
            elif fault == 2:
                motor.reboot(now)
            else:
                motor.unresponsive = not motor.unresponsive
        network.run_ahead(t)
    trace += network.run_until_idle(0.05)
    states = [(dict(m.counters), _model_state(m), _plant_state(m.plant)) for m in motors]
    return trace, states, python_calls[0]


def test_thirty_two_c_motors_through_the_engine_give_the_python_trace() -> None:
    from servobus.sim import corenet
    from servobus.sim.network import SimCanNetwork

    expected, expected_states, python_frames = _bus_trace(SimCanNetwork, 27, 2000)
    got, got_states, c_python_frames = _bus_trace(corenet.CoreCanNetwork, 27, 2000)
    assert [t for t, _ in got] == [t for t, _ in expected]  # bit for bit
    assert got == expected
    for i, (g, e) in enumerate(zip(got_states, expected_states, strict=True)):
        assert g == e, f"motor {i + 1}"
    assert c_python_frames < python_frames / 4  # the C path answered most of them

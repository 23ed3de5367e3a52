"""LK's C path (csrc/sim_lk.c) against the Python model it copies (issue 27's differential test).

Two motors get the same seeded trace: one Python-only (the reference), one attached to a C twin
(``core_attach(motor, None)``) and driven as the engine drives it: ``lib.sb_lk_receive`` first, the
Python ``receive`` when C says SB_HOT_COLD, ``core_push`` after every Python call. The traces
cover every hot command of both revisions with random field values (limits and the values the
codec refuses included), on every motor type, interleaved with what stays in Python: parameter
writes, zeroing, the brake, calibration, motor off/stop/run, injected errors and their clearing,
reboots, the unresponsive knob, frames of other ids, kinds and revisions, undecodable bytes.
Compared after every step: reply bytes, identifiers and ready times, counters, run state, held
command and the plant's state, all exactly (no tolerance: the C path does the model's float
operations in the model's order, and the plant is integrated on the same grid).

``python tests/sim/devices/test_lk_core.py`` prints what a hot frame costs in C and in Python.
"""

from __future__ import annotations

import math
import random
import sys
import time
from collections import Counter
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import (
    BrakeAction,
    ControlParam,
    ErrorState,
    ErrorStateV235,
    LkCommand,
    LkModel,
    MotorType,
    ParamId,
    Revision,
)
from servobus.protocols.lk.codec import request_frame
from servobus.protocols.lk.sim.core import COUNTER_NAMES
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.lk.sim.state import LK_PLANT_PARAMS
from servobus.sim.canbus import CanBusModel
from servobus.sim.device import Emission
from servobus.sim.plant import PlantParams

V236, V235 = Revision.V2_36, Revision.V2_35
HOT_CODES = (0x9A, 0x9B, 0x9C, 0x9D, 0x90, 0x92, 0x94, 0x80, 0x81, 0x88, *range(0xA0, 0xA9))
GEARED = PlantParams(
    **{**{f: getattr(LK_PLANT_PARAMS, f) for f in LK_PLANT_PARAMS.__dataclass_fields__}, "gear_ratio": 6.0}
)
Reply = tuple[float, int, bytes]


class Twin:
    """The same motor twice: Python only, and attached to a C twin driven as the engine drives it."""

    def __init__(self, motor_id: int, model: LkModel, **kwargs: Any) -> None:
        self.py = LkMotor(motor_id, model=model, **kwargs)
        self.c = LkMotor(motor_id, model=model, **kwargs)
        self.motor = ffi.new("sb_simmotor *")
        self.c.core_attach(self.motor, None)
        self._in = ffi.new("sb_simframe *")
        self._out = ffi.new("sb_simframe[4]")
        self._n = ffi.new("int *")
        self.hot = self.cold = 0

    def receive(self, frame: Frame, now_s: float) -> tuple[list[Reply], list[Reply]]:
        """(Python's replies, the C-attached motor's replies) to ``frame`` at ``now_s``."""
        expected = _replies(self.py.receive(frame, now_s))
        f = self._in
        f.t, f.id, f.len = now_s, frame.arbitration_id, len(frame.data)
        f.flags = (lib.SB_FRAME_EXT if frame.is_extended_id else 0) | (lib.SB_FRAME_FD if frame.is_fd else 0)
        ffi.memmove(f.data, bytes(frame.data), len(frame.data))
        status = lib.sb_lk_receive(self.motor, f, now_s, self._out, 4, self._n)
        if status == lib.SB_HOT_COLD:
            self.cold += 1
            got = _replies(self.c.receive(frame, now_s))
            self.c.core_push()
        else:
            assert status == lib.SB_HOT_DONE
            self.hot += 1
            got = [
                (o.t, o.id, bytes(ffi.buffer(o.data, o.len)))
                for o in (self._out[i] for i in range(self._n[0]))
            ]
        return expected, got

    def both(self, action: str, *args: Any, **kwargs: Any) -> None:
        """A Python-side action (reboot, inject_error, ...) on both motors."""
        getattr(self.py, action)(*args, **kwargs)
        getattr(self.c, action)(*args, **kwargs)
        self.c.core_push()

    def check(self, where: str) -> None:
        py, c = self.py, self.c
        assert c.counters == py.counters, where
        assert (c.state, c.held, c.angles) == (py.state, py.held, py.angles), where
        for name in ("now_s", "position_deg", "speed_dps", "current_a", "temperature_c"):
            assert getattr(c.plant, name) == getattr(py.plant, name), (where, name)
        assert c.plant.control == py.plant.control, where


def _replies(emissions: list[Emission]) -> list[Reply]:
    return [(e.ready_s, e.frame.arbitration_id, bytes(e.frame.data)) for e in emissions]


# ---- the traces ----


def _i16(rng: random.Random, lo: int = -2048, hi: int = 2048) -> int:
    return rng.choice(
        [0, 1, -1, lo, hi, lo - 1, hi + 1, -32768, 32767, rng.randint(lo, hi), rng.randint(lo, hi)]
    )


def hot_frame(rng: random.Random, model: LkModel, motor_id: int) -> Frame:
    """A frame of a hot command with random (also out-of-range) fields and random NULL bytes."""
    data = bytearray(rng.randbytes(8) if rng.random() < 0.2 else bytes(8))
    if model.revision is V235 and rng.random() < 0.08:  # the multi-motor frame
        for i in range(4):
            data[2 * i : 2 * i + 2] = _i16(rng, -2000, 2000).to_bytes(2, "little", signed=True)
        return Frame(arbitration_id=0x280, data=bytes(data))
    code = data[0] = rng.choice(HOT_CODES)
    put = data.__setitem__
    if code in (0xA0, 0xA1):
        put(
            slice(4, 6),
            _i16(rng, -850 if code == 0xA0 else -2048, 850 if code == 0xA0 else 2048).to_bytes(
                2, "little", signed=True
            ),
        )
    if code == 0xA2 and model.revision is V236:
        put(slice(2, 4), _i16(rng).to_bytes(2, "little", signed=True))
    if code in (0xA4, 0xA6, 0xA8):
        put(slice(2, 4), rng.choice([0, 1, 65535, rng.randint(1, 3000)]).to_bytes(2, "little"))
    if code in (0xA5, 0xA6):
        data[1] = rng.choice([0, 1, 0, 1, 2])
        if model.revision is V235:
            put(slice(4, 6), rng.choice([0, 35999, 36000, rng.randint(0, 35999)]).to_bytes(2, "little"))
        else:
            put(
                slice(4, 8),
                rng.choice([0, 2**32 - 1, rng.randint(0, 72000), rng.randint(0, 2**32 - 1)]).to_bytes(
                    4, "little"
                ),
            )
    if code in (0xA2, 0xA3, 0xA4, 0xA7, 0xA8):
        value = rng.choice([0, rng.randint(-36000, 36000), rng.randint(-400000, 400000), -(2**31), 2**31 - 1])
        put(slice(4, 8), value.to_bytes(4, "little", signed=True))
    length = 8 if rng.random() > 0.02 else rng.randint(0, 7)
    return Frame(arbitration_id=0x140 + motor_id, data=bytes(data[:length]))


def cold_command(rng: random.Random, model: LkModel) -> LkCommand:
    """A valid command the C path leaves to Python."""
    if model.revision is V236:
        param = rng.choice(
            [
                ControlParam.TORQUE_LIMIT,
                ControlParam.SPEED_LIMIT,
                ControlParam.ANGLE_UPPER_LIMIT,
                ControlParam.ANGLE_LOWER_LIMIT,
            ]
        )
        values = {
            ControlParam.TORQUE_LIMIT: rng.choice([0, 2000, rng.randint(0, 2000)]),
            ControlParam.SPEED_LIMIT: rng.choice([0, 600_000, rng.randint(0, 200_000)]),
            ControlParam.ANGLE_UPPER_LIMIT: rng.randint(0, 72000),
            ControlParam.ANGLE_LOWER_LIMIT: -rng.randint(0, 72000),
        }
        return rng.choice(
            [
                lk.WriteControlParam(param=param, value=values[param]),
                lk.BrakeControl(action=rng.choice(list(BrakeAction))),
                lk.SetZeroRam(),
                lk.SetZeroRom(),
                lk.CalibrateEncoder(),
                lk.ReadControlParam(param=ControlParam.SPEED_LIMIT),
            ]
        )
    param = rng.choice([ParamId.MAX_TORQUE_CURRENT, ParamId.MAX_SPEED, ParamId.MAX_ANGLE_HIGH])
    value = {
        ParamId.MAX_TORQUE_CURRENT: rng.randint(-5, 2000),
        ParamId.MAX_SPEED: rng.randint(0, 300_000),
    }.get(param, rng.randint(0, 2))
    write = rng.choice([lk.WriteParamRam, lk.WriteParamRom])
    return rng.choice(
        [
            write(param=param, value=value),
            lk.WriteAcceleration(acceleration_dps2=rng.choice([0, 100, 60000, rng.randint(1, 100000)])),
            lk.WriteEncoderOffset(
                offset_counts=rng.randint(0, (1 << min(model.encoder_bits, 16)) - 1),
                encoder_bits=model.encoder_bits,
            ),
            lk.SetZeroRam(),
            lk.SetZeroRom(),
            lk.ReadParam(param=ParamId.MAX_SPEED),
        ]
    )


def odd_frame(rng: random.Random, model: LkModel, motor_id: int) -> Frame:
    """A frame the model ignores or cannot decode: other ids, kinds, revisions, unknown bytes."""
    other = (motor_id % 32) + 1
    choice = rng.randrange(6)
    if choice == 5:  # anything at all on its identifiers
        can_id = rng.choice([0x140 + motor_id, 0x280])
        return Frame(arbitration_id=can_id, data=rng.randbytes(rng.choice([8, 8, 8, rng.randint(0, 8)])))
    if choice == 0:
        return Frame(arbitration_id=0x140 + other, data=bytes([0x9C] + [0] * 7))
    if choice == 1:
        return Frame(arbitration_id=0x140 + motor_id, data=bytes([0x9C] + [0] * 7), is_extended_id=True)
    if choice == 2:  # the other revision's commands (and 0x280 on V2.36)
        if model.revision is V236:
            return rng.choice(
                [
                    Frame(arbitration_id=0x140 + motor_id, data=bytes([0x34] + [0] * 7)),
                    Frame(arbitration_id=0x280, data=bytes(8)),
                ]
            )
        return Frame(arbitration_id=0x140 + motor_id, data=bytes([0x8C, 0x10] + [0] * 6))
    return Frame(
        arbitration_id=0x140 + motor_id, data=bytes([rng.choice([0x00, 0x01, 0xFF, 0x9E])] + [0] * 7)
    )


def run_trace(seed: int, revision: Revision, steps: int = 1500) -> Twin:
    rng = random.Random(seed)
    motor_type = rng.choice(list(MotorType))
    model = LkModel(revision=revision, motor_type=motor_type, encoder_bits=rng.choice([14, 15, 16, 18]))
    motor_id = rng.choice([1, 2, 3, 4, 7, 32])
    twin = Twin(
        motor_id,
        model,
        plant_params=rng.choice([LK_PLANT_PARAMS, GEARED]),
        calibration_s=0.004,
        turnaround_s=rng.choice([200e-6, 0.0, 1e-4]),
        encoder_offset_counts=rng.randint(0, (1 << min(model.encoder_bits, 16)) - 1),
    )
    errors = list(ErrorState) if revision is V236 else list(ErrorStateV235)
    now = rng.random() * 1e-3
    for step in range(steps):
        now += rng.choice([1e-4, 2.5e-4, 5e-4, 1e-3, 1e-3, 2.3e-3, 0.02, 0.3])
        where = f"seed {seed} step {step} t={now}"
        roll = rng.random()
        if roll < 0.75:
            expected, got = twin.receive(hot_frame(rng, model, twin.py.motor_id), now)
        elif roll < 0.85:
            frame = request_frame(cold_command(rng, model), motor_id=twin.py.motor_id, model=model)
            expected, got = twin.receive(frame, now)
        elif roll < 0.92:
            expected, got = twin.receive(odd_frame(rng, model, twin.py.motor_id), now)
        else:
            expected = got = []
            action = rng.randrange(8)
            if action == 0:
                twin.both("inject_error", rng.choice(errors), now, persistent=rng.random() < 0.5)
            elif action < 4:  # the fault is over (or not, one flag of several) and 0x9B clears it
                flags = errors[0].__class__(sum(errors)) if rng.random() < 0.7 else rng.choice(errors)
                twin.both("end_error", flags, now)
                clear = Frame(arbitration_id=0x140 + twin.py.motor_id, data=bytes([0x9B] + [0] * 7))
                expected, got = twin.receive(clear, now)
            elif action == 4:
                twin.both("reboot", now)
            else:
                flag = rng.random() < 0.2
                twin.py.unresponsive = twin.c.unresponsive = flag
        assert got == expected, where
        twin.check(where)
    return twin


@pytest.mark.parametrize("revision", [V236, V235], ids=["v2.36", "v2.35"])
@pytest.mark.parametrize("seed", range(12))
def test_c_path_matches_the_python_model(revision: Revision, seed: int) -> None:
    twin = run_trace(seed, revision)
    assert twin.hot > (twin.hot + twin.cold) / 3  # the trace exercised C, not only the fallback


def test_every_hot_command_is_handled_in_c_on_both_revisions() -> None:
    """Each hot command byte (and 0x280) is answered by C, not handed to Python, in a valid frame."""
    for revision in (V236, V235):
        model = LkModel(revision=revision)
        twin = Twin(1, model)
        for i, code in enumerate(HOT_CODES):
            data = bytearray(8)
            data[0] = code
            if code == 0xA0:
                data[4] = 10
            if code == 0xA2 and revision is V236:
                data[2] = 100  # a torque limit of 0 does not decode
            cold = twin.cold
            expected, got = twin.receive(Frame(arbitration_id=0x141, data=bytes(data)), 0.01 * (i + 1))
            assert got == expected and len(got) == 1 and twin.cold == cold, hex(code)
        if revision is V235:
            expected, got = twin.receive(Frame(arbitration_id=0x280, data=bytes([10, 0] * 4)), 1.0)
            assert got == expected and got[0][2][0] == 0xA1 and twin.cold == 0
        twin.check(revision.name)


@pytest.mark.parametrize("revision", [V236, V235], ids=["v2.36", "v2.35"])
@pytest.mark.parametrize("motor_type", list(MotorType), ids=lambda t: t.name)
def test_readings_on_a_tie_round_as_the_model(revision: Revision, motor_type: MotorType) -> None:
    """Python's round() goes half to even, the wire fields half away from zero: readings placed
    exactly on .5 (iq counts, speed, temperature, phase currents) come out the same in C."""
    model = LkModel(revision=revision, motor_type=motor_type)
    for k, tie in enumerate((0.5, 1.5, 2.5, -0.5, -2.5)):
        twin = Twin(1, model)
        apc = twin.py.amps_per_count
        for motor in (twin.py, twin.c):
            motor.plant.advance(0.001)
            motor.plant.current_a = tie * apc
            motor.plant.speed_dps = tie
            motor.plant.temperature_c = 25 + tie
        for code in (0x9C, 0x9A, 0x9D, 0x92, 0x94, 0x90):
            frame = Frame(arbitration_id=0x141, data=bytes([code] + [0] * 7))
            expected, got = twin.receive(frame, 0.001)  # no time passes: the tie stays
            assert got == expected, (tie, hex(code))
        twin.check(f"tie {k}")
        assert twin.cold == 0


def test_cold_means_unchanged() -> None:
    """A frame C hands to Python leaves the twin exactly as it was (state, counters, plant)."""
    twin = Twin(1, LkModel(revision=V236))
    twin.receive(Frame(arbitration_id=0x141, data=bytes([0xA2, 0, 100, 0, 0x10, 0x27, 0, 0])), 0.01)
    before = bytes(ffi.buffer(twin.motor))
    f = ffi.new(
        "sb_simframe *", {"t": 0.02, "id": 0x141, "len": 8, "data": list(bytes([0xC1, 0x1E] + [0] * 6))}
    )
    out, n = ffi.new("sb_simframe[1]"), ffi.new("int *")
    assert lib.sb_lk_receive(twin.motor, f, 0.02, out, 1, n) == lib.SB_HOT_COLD and n[0] == 0
    assert bytes(ffi.buffer(twin.motor)) == before


def test_a_latched_error_makes_the_twin_cold_until_cleared() -> None:
    twin = Twin(1, LkModel(revision=V235))
    twin.both("inject_error", ErrorStateV235.LOW_VOLTAGE, 0.001, persistent=False)
    assert twin.motor.hot == 0
    expected, got = twin.receive(Frame(arbitration_id=0x141, data=bytes([0x9B] + [0] * 7)), 0.002)
    assert got == expected and twin.motor.hot == 1 and twin.cold == 1


def test_the_c_functions_check_their_arguments() -> None:
    twin = Twin(1, LkModel())
    motor, null = twin.motor, ffi.NULL
    f = ffi.new("sb_simframe *", {"id": 0x141, "len": 8, "data": [0x9C] + [0] * 7})
    out, n = ffi.new("sb_simframe[1]"), ffi.new("int *")
    receive, poll = lib.sb_lk_receive, lib.sb_lk_poll
    assert receive(null, f, 0.0, out, 1, n) == lib.SB_E_ARG
    assert receive(motor, null, 0.0, out, 1, n) == lib.SB_E_ARG
    assert receive(motor, f, 0.0, null, 1, n) == lib.SB_E_ARG
    assert receive(motor, f, 0.0, out, 0, n) == lib.SB_E_ARG
    assert receive(motor, f, 0.0, out, 1, null) == lib.SB_E_ARG
    assert receive(motor, f, math.nan, out, 1, n) == lib.SB_E_ARG
    assert poll(null, 0.0, out, 1, n) == lib.SB_E_ARG and poll(motor, 0.0, out, 1, null) == lib.SB_E_ARG
    f.len = 65
    assert receive(motor, f, 0.0, out, 1, n) == lib.SB_E_ARG
    f.len = 8
    state = ffi.cast("sb_lk_state *", motor.state)
    for field, bad in (
        ("motor_id", 33),
        ("revision", 7),
        ("per_turn", 1000),
        ("run_state", 3),
        ("angle_offset", -1),
    ):
        saved = getattr(state, field)
        setattr(state, field, bad)
        assert receive(motor, f, 0.0, out, 1, n) == lib.SB_E_ARG and n[0] == 0, field
        setattr(state, field, saved)
    motor.family = lib.SB_FAMILY_MYACTUATOR
    assert receive(motor, f, 0.0, out, 1, n) == lib.SB_E_ARG
    motor.family = lib.SB_FAMILY_LK
    step, motor.plant.max_step_s = motor.plant.max_step_s, 0.0  # a plant sb_plant_check refuses
    assert receive(motor, f, 0.0, out, 1, n) == lib.SB_E_ARG and poll(motor, 0.0, out, 1, n) == lib.SB_E_ARG
    motor.plant.max_step_s = step
    assert receive(motor, f, 0.0, out, 1, n) == lib.SB_HOT_DONE and n[0] == 1
    assert lib.sb_lk_next_deadline(motor) == math.inf and lib.sb_lk_next_deadline(null) == math.inf


def test_detach_hands_the_state_back_to_python() -> None:
    twin = Twin(2, LkModel(revision=V236))
    for i, data in enumerate(([0xA2, 0, 100, 0, 0x10, 0x27, 0, 0], [0x81] + [0] * 7, [0x9C] + [0] * 7)):
        twin.receive(Frame(arbitration_id=0x142, data=bytes(data)), 0.01 * (i + 1))
    twin.c.core_detach()
    twin.check("detached")
    expected = twin.py.receive(Frame(arbitration_id=0x142, data=bytes([0x9A] + [0] * 7)), 0.5)
    assert _replies(
        twin.c.receive(Frame(arbitration_id=0x142, data=bytes([0x9A] + [0] * 7)), 0.5)
    ) == _replies(expected)
    twin.check("after")


def test_c_counts_under_the_models_keys() -> None:
    """Every counter C keeps is one the model keeps, counted by C for the frames it handles."""
    twin = Twin(1, LkModel(revision=V236, motor_type=MotorType.MG), calibration_s=0.1)
    frames: list[tuple[float, Frame]] = []

    def request(*data: int, can_id: int = 0x141, extended: bool = False) -> Frame:
        return Frame(
            arbitration_id=can_id, data=bytes([*data] + [0] * (8 - len(data))), is_extended_id=extended
        )

    frames = [
        (0.01, request(0x9C)),  # received, accepted, replied
        (0.02, request(0x9C, can_id=0x142)),  # ignored_id
        (0.03, request(0x9C, extended=True)),  # ignored_kind
        (0.04, request(0, can_id=0x280)),  # other_revision (0x280 is V2.35's)
        (0.05, request(0x80)),
        (0.06, request(0xA1, 0, 0, 0, 100)),  # not_executed_off
        (0.07, request(0x88)),
        (0.08, request(0xA0, 0, 0, 0, 100)),  # not_implemented (0xA0 is MS only on V2.36)
        (0.09, request(0x18)),  # calibration: Python
        (0.10, request(0x9C)),  # busy
    ]
    for now, frame in frames:
        expected, got = twin.receive(frame, now)
        assert got == expected
    twin.py.unresponsive = twin.c.unresponsive = True
    expected, got = twin.receive(request(0x9C), 0.3)  # unanswered
    assert got == expected == []
    twin.check("counters")
    assert twin.cold == 1 and all(twin.c.counters[name] > 0 for name in COUNTER_NAMES)


# ---- cost ----


def measure(repeat: int = 20000) -> dict[str, float]:
    """ns per sb_lk_receive (set-point + reply, status read) and µs per Python ``receive``."""
    results: dict[str, float] = {}
    frames = {
        "setpoint": Frame(arbitration_id=0x141, data=bytes([0xA2, 0, 100, 0, 0x10, 0x27, 0, 0])),
        "status": Frame(arbitration_id=0x141, data=bytes([0x9C] + [0] * 7)),
    }
    for name, frame in frames.items():
        twin = Twin(1, LkModel())
        f = ffi.new("sb_simframe *", {"id": 0x141, "len": 8, "data": list(frame.data)})
        out, n = ffi.new("sb_simframe[4]"), ffi.new("int *")
        receive, motor, step = lib.sb_lk_receive, twin.motor, 1e-3
        start = time.perf_counter()
        for i in range(repeat):
            receive(motor, f, i * step, out, 4, n)
        c_s = (time.perf_counter() - start) / repeat
        py = twin.py
        start = time.perf_counter()
        for i in range(repeat // 10):
            py.receive(frame, i * step)
        py_s = (time.perf_counter() - start) / (repeat // 10)
        results[f"{name}.c_ns"] = c_s * 1e9
        results[f"{name}.python_us"] = py_s * 1e6
    start = time.perf_counter()
    for _ in range(repeat):
        lib.sb_lk_next_deadline(motor)
    results["cffi_call_ns"] = (time.perf_counter() - start) / repeat * 1e9
    return results


if __name__ == "__main__":
    for key, value in measure(int(sys.argv[1]) if len(sys.argv) > 1 else 20000).items():
        print(f"{key:20s} {value:10.1f}")


# ---- fuzz: any frame into any state the glue can push ----


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    revision=st.sampled_from([V236, V235]),
    motor_type=st.sampled_from(list(MotorType)),
    run_state=st.integers(0, 2),
    held=st.integers(0, 4),
    brake=st.booleans(),
    frames=st.lists(
        st.tuples(
            st.sampled_from([0x141, 0x280, 0x142, 0x7FF]),
            st.integers(0, 7),  # flags: extended, FD, BRS
            st.binary(min_size=0, max_size=64),
            st.floats(0.0, 10.0),
        ),
        max_size=20,
    ),
)
def test_random_frames_into_the_c_path(
    revision: Revision,
    motor_type: MotorType,
    run_state: int,
    held: int,
    brake: bool,
    frames: list[tuple[int, int, bytes, float]],
) -> None:
    """C answers a status (DONE with at most one reply, COLD leaving every byte as it was, or
    SB_E_ARG) for any frame in any pushed state; .ci/sanitize runs this under ASan + UBSan."""
    motor = ffi.new("sb_simmotor *")
    device = LkMotor(1, model=LkModel(revision=revision, motor_type=motor_type), brake_engaged=brake)
    device.core_attach(motor, None)
    state = ffi.cast("sb_lk_state *", motor.state)
    state.run_state, state.has_held = run_state, held > 0
    state.held.mode, state.held.a, state.held.b = held, 1.0, math.nan
    f, out, n = ffi.new("sb_simframe *"), ffi.new("sb_simframe[1]"), ffi.new("int *")
    for can_id, flags, data, now in sorted(frames, key=lambda x: x[3]):
        f.id, f.flags, f.len, f.t = can_id, flags, len(data), now
        ffi.memmove(f.data, data, len(data))
        before = bytes(ffi.buffer(motor))
        status = lib.sb_lk_receive(motor, f, now, out, 1, n)
        assert status in (lib.SB_HOT_DONE, lib.SB_HOT_COLD) and 0 <= n[0] <= 1
        if status == lib.SB_HOT_COLD:
            assert bytes(ffi.buffer(motor)) == before and n[0] == 0
        elif n[0]:
            assert out[0].len == 8 and out[0].id == (0x181 if revision is V236 else 0x141)
            assert out[0].t == now + motor.turnaround_s


# ---- through the engine (CoreCanNetwork) against the reference network ----


def _bus_state(network: Any) -> dict[str, Any]:
    out: dict[str, Any] = {"now": network.now_s, "frames": network.bus.frames}
    for name, device in network.devices.items():
        plant = device.plant
        out[name] = (
            dict(device.counters),
            device.state,
            device.held,
            device.angles,
            (plant.position_deg, plant.speed_dps, plant.current_a, plant.temperature_c, plant.now_s),
        )
    return out


def _drive_bus(
    make: Any, revision: Revision, seed: int, sends: int = 600
) -> tuple[list[Any], dict[str, Any]]:
    rng = random.Random(seed)
    models = [LkModel(revision=revision, motor_type=rng.choice(list(MotorType))) for _ in range(6)]
    ids = [1, 2, 3, 4, 9, 17]
    devices = [LkMotor(i, model=m, calibration_s=0.003) for i, m in zip(ids, models, strict=True)]
    network = make(devices, bus=CanBusModel(bitrate=1_000_000))
    trace: list[Any] = []
    t = 0.0
    for _ in range(sends):
        t += rng.choice((0.0, 1e-5, 1.3e-4, 4e-4, 1e-3, 2e-3))
        trace += network.advance(t)
        k = rng.randrange(len(ids))
        roll = rng.random()
        if roll < 0.8:
            frame = hot_frame(rng, models[k], ids[k])
        elif roll < 0.9:
            frame = request_frame(cold_command(rng, models[k]), motor_id=ids[k], model=models[k])
        else:
            frame = odd_frame(rng, models[k], ids[k])
        network.send(frame, max(t, network.now_s))
        network.run_ahead(t)
    trace += network.run_until_idle(0.05)
    return trace, _bus_state(network)


@pytest.mark.parametrize("revision", [V236, V235], ids=["v2.36", "v2.35"])
@pytest.mark.parametrize("seed", [1, 2])
def test_lk_motors_through_the_engine_give_the_reference_trace(
    revision: Revision, seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from servobus.sim import corenet
    from servobus.sim.network import SimCanNetwork

    expected = _drive_bus(SimCanNetwork, revision, seed)
    calls = Counter[str]()
    handed = corenet.CoreCanNetwork._receive  # the engine handing a frame to a Python model

    def counted(self: corenet.CoreCanNetwork, node: int, frame: Frame, t: float, flags: int) -> None:
        calls["python"] += 1
        handed(self, node, frame, t, flags)

    # (Patched on the network, not on LkMotor: a motor whose receive() is replaced stays in Python.)
    monkeypatch.setattr(corenet.CoreCanNetwork, "_receive", counted)
    got = _drive_bus(corenet.CoreCanNetwork, revision, seed)
    assert got[0] == expected[0]
    assert [t for t, _ in got[0]] == [t for t, _ in expected[0]]  # bit for bit
    assert got[1] == expected[1]
    acted = sum(
        d[0].get("accepted", 0) + d[0].get("undecodable", 0) for d in got[1].values() if isinstance(d, tuple)
    )
    assert calls["python"] < 0.7 * acted  # most frames the motors acted on were answered in C

"""The hollow motor's C hot path (csrc/sim_hollow.c) against the Python model, its reference.

Two motors get the same seeded traces: one Python-only, one attached to a C twin and driven as the
engine drives it (``lib.sb_hollow_receive`` first; on SB_HOT_COLD the Python ``receive``, then
``core_push``). Every reply (bytes, kind, ready time), every counter, the motor's RAM state and its
plant must be identical, bit for bit: both sides make the same changes at the same times and the
plant's grid rule makes its state depend only on those, and the C side scales, clamps and rounds as
the codec and the model do (``-ffp-contract=off``). So no tolerance is used anywhere.

The same holds a level up: hollow motors on the C engine (``CoreCanNetwork``, classic and CAN FD
buses) against the same motors on ``SimCanNetwork``.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servobus.core._lib import ffi, lib
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    MODEL_3507,
    CanMode,
    CanModeSwitch,
    ControlMode,
    FdCommand,
    HollowCommand,
    HollowModel,
    IncrementalSetpoint,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    Start,
    Stop,
)
from servobus.protocols.hollow.codec import request_frame
from servobus.protocols.hollow.sim.core import COUNTER_KEYS, HollowCore
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Emission
from servobus.sim.network import SimCanNetwork

MOTOR_ID = 5
CAP = 4


def _simframe(frame: Frame, end_s: float) -> Any:
    c = ffi.new("sb_simframe *")
    c.t = end_s
    c.id = frame.arbitration_id
    c.flags = (
        (lib.SB_FRAME_EXT if frame.is_extended_id else 0)
        | (lib.SB_FRAME_FD if frame.is_fd else 0)
        | (lib.SB_FRAME_BRS if frame.bitrate_switch else 0)
    )
    c.len = len(frame.data)
    c.data[0 : len(frame.data)] = frame.data
    return c


def _frame(c: Any) -> Frame:
    return Frame(
        arbitration_id=c.id,
        data=bytes(c.data[0 : c.len]),
        is_extended_id=bool(c.flags & lib.SB_FRAME_EXT),
        is_fd=bool(c.flags & lib.SB_FRAME_FD),
        bitrate_switch=bool(c.flags & lib.SB_FRAME_BRS),
    )


Sent = list[tuple[float, Frame]]


def _sent(emissions: list[Emission]) -> Sent:
    return [(e.ready_s, e.frame) for e in emissions]


class Twin:
    """A HollowMotor on a C twin, driven as the engine drives it."""

    def __init__(self, **kwargs: Any) -> None:
        self.device = HollowMotor(MOTOR_ID, **kwargs)
        self.motor = ffi.new("sb_simmotor *")
        self.device.core_attach(self.motor, None)
        self.out = ffi.new("sb_simframe[]", CAP)
        self.n_out = ffi.new("int *")
        self.hot = self.cold = 0

    def receive(self, frame: Frame, now_s: float) -> Sent:
        status = lib.sb_hollow_receive(self.motor, _simframe(frame, now_s), now_s, self.out, CAP, self.n_out)
        if status == lib.SB_HOT_COLD:
            assert self.n_out[0] == 0
            self.cold += 1
            sent = _sent(self.device.receive(frame, now_s))
            self.device.core_push()
            return sent
        assert status == lib.SB_HOT_DONE
        self.hot += 1
        return [(self.out[i].t, _frame(self.out[i])) for i in range(self.n_out[0])]

    def poll(self, now_s: float) -> Sent:
        assert lib.sb_hollow_next_deadline(self.motor) == math.inf
        status = lib.sb_hollow_poll(self.motor, now_s, self.out, CAP, self.n_out)
        if status == lib.SB_HOT_COLD:
            sent = _sent(self.device.poll(now_s))
            self.device.core_push()
            return sent
        assert status == lib.SB_HOT_DONE and self.n_out[0] == 0
        return []


def _same_state(py: HollowMotor, twin: HollowMotor) -> None:
    assert twin.counters == py.counters
    for attr in ("enabled", "can_mode", "ctrl_mode", "setpoint", "zero_offset_deg", "pi_multipliers"):
        assert getattr(twin, attr) == getattr(py, attr), attr
    a, b = py.plant, twin.plant
    for attr in ("now_s", "control", "position_deg", "speed_dps", "current_a", "temperature_c"):
        assert getattr(b, attr) == getattr(a, attr), attr  # == on floats: bit for bit (no NaN here)


# ---- seeded traces ----


def _real(rng: random.Random, lo: float, hi: float) -> float:
    """Random values across [lo, hi] with the edges and zero often."""
    pick = rng.random()
    if pick < 0.08:
        return lo
    if pick < 0.16:
        return hi
    if pick < 0.22:
        return 0.0
    return rng.uniform(lo, hi)


def _setpoint(rng: random.Random, model: HollowModel, incremental: bool) -> HollowCommand[Any]:
    full = model.position_full_scale_deg
    fields: dict[str, Any] = {
        "speed_rad_s": _real(rng, -model.speed_full_scale_rad_s, model.speed_full_scale_rad_s),
        "kp": rng.choice((0, 0x800, 0xFFF, rng.randrange(0x1000))),
        "kd": rng.choice((0, 0xFFF, rng.randrange(0x1000))),
        "current_a": _real(rng, -model.current_full_scale_a, model.current_full_scale_a),
        "model": model,
    }
    if incremental:
        return IncrementalSetpoint(step_deg=_real(rng, -full, full) * rng.choice((1.0, 0.01)), **fields)
    return Setpoint(position_deg=_real(rng, -full, full), **fields)


def _fd_command(rng: random.Random, model: HollowModel) -> FdCommand:
    return FdCommand(
        position_deg=rng.choice((0.0, rng.uniform(-720.0, 720.0), rng.uniform(-1e5, 1e5))),
        velocity_rpm=_real(rng, -3000.0, 3000.0),
        current_raw=rng.choice((0, -32768, 32767, rng.randrange(-6000, 6000))),
        mode=rng.choice(list(ControlMode)),
        run=rng.random() < 0.7,
        kp=rng.randrange(256),
        kd=rng.randrange(256),
        zero=rng.random() < 0.1,
        model=model,
    )


def _raw(rng: random.Random, fd: bool) -> Frame:
    """Random bytes on the motor's id: setpoints of every code, undecodable FD bytes, wrong lengths."""
    if fd:
        data = bytearray(rng.randbytes(16))
        data[11] = rng.choice((0, 1, 2, 2, 3, 0xFF))  # Mode Sel (3 and up: undecodable)
        data[12] = rng.choice((0, 1, 1, 2))  # Run Cmd
        data[15] = rng.choice((0, 0, 0, 1, 7))  # Zero
        cut = rng.choice((8, 12, 20)) if rng.random() < 0.1 else 16
        return Frame(
            arbitration_id=MOTOR_ID, data=bytes(data + bytes(4))[:cut], is_fd=True, bitrate_switch=True
        )
    return Frame(arbitration_id=MOTOR_ID, data=rng.randbytes(rng.choice((8, 8, 8, 8, 8, 6, 0))))


def _odd(rng: random.Random, fd: bool) -> Frame:
    """A frame the motor drops: another id, the other interface's kind, a special-looking pattern."""
    pick = rng.randrange(4)
    if pick == 0:
        return Frame(arbitration_id=MOTOR_ID + 1, data=bytes(8))
    if pick == 1:
        return Frame(arbitration_id=MOTOR_ID, data=bytes(16), is_fd=True)  # ignored by a classic motor
    if pick == 2:
        return Frame(arbitration_id=MOTOR_ID, data=bytes(8))  # ignored by an FD motor
    return Frame(arbitration_id=MOTOR_ID, data=bytes(8), is_extended_id=True, is_fd=True)


def _cold(rng: random.Random) -> HollowCommand[Any]:
    return rng.choice(
        (
            Start(),
            Start(),
            Stop(),
            SetZero(),
            SelectMode(mode=rng.choice(list(ControlMode))),
            CanModeSwitch(mode=rng.choice(list(CanMode))),
            PiMultiplier(gain=rng.choice(list(PiGain)), multiplier=rng.choice((0.5, 1.0, 2.0))),
        )
    )


Step = Callable[[HollowMotor, float], Any]


def _trace(seed: int, fd: bool, model: HollowModel, steps: int) -> list[tuple[float, str, Any]]:
    """(time, kind, what): frames to receive, polls, reboots and unresponsive toggles."""
    rng = random.Random(seed)
    now, out = 0.0, list[tuple[float, str, Any]]()
    incremental = False
    for _ in range(steps):
        now += rng.choice((1e-4, 5e-4, 1e-3, rng.uniform(0.0, 4e-3), rng.uniform(0.0, 0.05)))
        pick = rng.random()
        if pick < 0.45:
            command: HollowCommand[Any] = (
                _fd_command(rng, model) if fd else _setpoint(rng, model, incremental)
            )
            out.append((now, "frame", request_frame(MOTOR_ID, command)))
        elif pick < 0.6:
            out.append((now, "frame", _raw(rng, fd)))
        elif pick < 0.78:
            command = _cold(rng)
            if isinstance(command, CanModeSwitch):
                incremental = command.mode is CanMode.EXTENDED and not fd
            out.append((now, "frame", request_frame(MOTOR_ID, command)))
        elif pick < 0.86:
            out.append((now, "frame", _odd(rng, fd)))
        elif pick < 0.94:
            out.append((now, "poll", None))
        elif pick < 0.97:
            out.append((now, "reboot", None))
            incremental = False
        else:
            out.append((now, "unresponsive", rng.random() < 0.25))
    return out


CASES = {
    "classic": {"fd": False, "model": DEFAULT_MODEL},
    "classic-3507": {"fd": False, "model": MODEL_3507},
    "fd": {"fd": True, "model": DEFAULT_MODEL},
    "fd-3507-amps": {"fd": True, "model": MODEL_3507, "fd_current_a_per_count": 0.002},
    "classic-pmax2-velocity": {
        "fd": False,
        "model": HollowModel(pmax_turns=2.0),
        "mode": ControlMode.VELOCITY,
    },
}


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_c_twin_answers_and_moves_exactly_as_the_python_model(case: dict[str, Any], seed: int) -> None:
    fd, model = case["fd"], case["model"]
    kwargs: dict[str, Any] = {"fd_enabled": fd, "model": model}
    if "fd_current_a_per_count" in case:
        kwargs["fd_current_a_per_count"] = case["fd_current_a_per_count"]
    if "mode" in case:
        kwargs["control_mode"] = case["mode"]
    py = HollowMotor(MOTOR_ID, **kwargs)
    twin = Twin(**kwargs)
    for now, kind, what in _trace(seed * 1000 + len(str(case)), fd, model, steps=1500):
        if kind == "frame":
            assert twin.receive(what, now) == _sent(py.receive(what, now)), (now, what)
        elif kind == "poll":
            assert twin.poll(now) == _sent(py.poll(now))
        elif kind == "reboot":
            py.reboot(now)
            twin.device.reboot(now)  # no push: the RAM state is C's only copy
        else:
            py.unresponsive = twin.device.unresponsive = what
        if kind != "frame" or twin.hot % 97 == 0:
            _same_state(py, twin.device)
    _same_state(py, twin.device)
    # The trace exercised both paths, and C took the set-points.
    assert twin.hot > 400 and twin.cold > 100
    assert py.counters["accepted"] > 400


def test_a_setpoint_reply_is_the_models_byte_for_byte_at_the_scale_edges() -> None:
    """Positions past ±Pmax stick at the end codes (A34); speeds and currents clamp at full scale."""
    for can_mode in CanMode:
        for sign in (1.0, -1.0):
            py, twin = HollowMotor(MOTOR_ID), Twin()
            for motor in (py, twin.device):
                motor.can_mode = can_mode
                motor.plant.position_deg = sign * 5000.0
                motor.plant.speed_dps = sign * 1e6
                motor.plant.current_a = sign * 9.0
            command = Setpoint(position_deg=360.0, speed_rad_s=200.0, kp=0xFFF, kd=0xFFF, current_a=4.0)
            frame = request_frame(MOTOR_ID, command)
            assert twin.receive(frame, 0.0) == _sent(py.receive(frame, 0.0))
            assert twin.hot == 1
            _same_state(py, twin.device)


@pytest.mark.parametrize("current_a", [1.25, -1.25, 0.75, -0.25, 20000.0, -20000.0])
@pytest.mark.parametrize("temperature_c", [24.5, 25.5, -0.5, 2.5, 125.5, -125.5, -126.0, 130.0])
def test_an_fd_reply_rounds_half_to_even_and_clamps_as_the_model(
    current_a: float, temperature_c: float
) -> None:
    """round() of the current counts and the temperature is Python's (half to even), after the clamp."""
    kwargs: dict[str, Any] = {"fd_enabled": True, "fd_current_a_per_count": 0.5}
    py, twin = HollowMotor(MOTOR_ID, **kwargs), Twin(**kwargs)
    for motor in (py, twin.device):
        motor.plant.current_a = current_a
        motor.plant.temperature_c = temperature_c
    frame = request_frame(MOTOR_ID, FdCommand())
    assert twin.receive(frame, 0.0) == _sent(py.receive(frame, 0.0))
    assert twin.hot == 1


def test_fd_zero_acts_only_while_not_running_and_the_reply_reports_the_new_zero() -> None:
    py, twin = HollowMotor(MOTOR_ID, fd_enabled=True), Twin(fd_enabled=True)
    for motor in (py, twin.device):
        motor.plant.position_deg = 123.0
    for at, run, zero in ((1e-3, False, True), (2e-3, True, False), (3e-3, True, True), (4e-3, False, True)):
        frame = request_frame(MOTOR_ID, FdCommand(position_deg=10.0, run=run, zero=zero, current_raw=500))
        assert twin.receive(frame, at) == _sent(py.receive(frame, at))
        _same_state(py, twin.device)
    assert twin.hot == 4 and twin.device.counters["zero_refused"] == 1


def test_cold_frames_leave_the_c_twin_untouched() -> None:
    """SB_HOT_COLD means "nothing changed": the special commands, the extended-id frames, a
    non-hot motor; the engine then hands the frame to Python."""
    twin = Twin()
    before = bytes(ffi.buffer(twin.motor))
    out, n_out = ffi.new("sb_simframe[]", 1), ffi.new("int *")
    for command in (
        Start(),
        Stop(),
        SetZero(),
        SelectMode(mode=ControlMode.TORQUE),
        CanModeSwitch(mode=CanMode.NORMAL),
    ):
        frame = _simframe(request_frame(MOTOR_ID, command), 0.5)
        assert lib.sb_hollow_receive(twin.motor, frame, 0.5, out, 1, n_out) == lib.SB_HOT_COLD
        assert n_out[0] == 0
    twin.device.unresponsive = True
    setpoint = _simframe(
        request_frame(MOTOR_ID, Setpoint(position_deg=1.0, speed_rad_s=1.0, kp=1, kd=1, current_a=1.0)), 0.6
    )
    hot_state = bytes(ffi.buffer(twin.motor))
    assert lib.sb_hollow_receive(twin.motor, setpoint, 0.6, out, 1, n_out) == lib.SB_HOT_COLD
    assert bytes(ffi.buffer(twin.motor)) == hot_state
    twin.device.unresponsive = False
    assert bytes(ffi.buffer(twin.motor)) == before
    # no room for the reply: the model answers
    assert lib.sb_hollow_receive(twin.motor, setpoint, 0.6, out, 0, n_out) == lib.SB_HOT_COLD
    assert bytes(ffi.buffer(twin.motor)) == before


def test_jitter_keeps_the_motor_in_python() -> None:
    twin = Twin(turnaround_jitter_s=1e-4)
    assert twin.motor.hot == 0
    py = HollowMotor(MOTOR_ID, turnaround_jitter_s=1e-4)
    frame = request_frame(MOTOR_ID, Setpoint(position_deg=1.0, speed_rad_s=1.0, kp=1, kd=1, current_a=1.0))
    assert twin.receive(frame, 0.1) == _sent(py.receive(frame, 0.1))
    assert twin.cold == 1


_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def fuzz_receive(blob: bytes) -> None:
    """Any frame C may be handed (flags, length and bytes from ``blob``) into a classic or FD twin in
    either CAN mode: C answers or goes cold, never touches memory past the frame; a frame a
    Frame can carry gets the Python model's answer."""
    if len(blob) < 3:
        return
    fd_motor, can_mode, flags, length = blob[0] & 1, (blob[0] >> 1) & 1, blob[1] & 7, blob[2] % 65
    data = (blob[3:] + bytes(64))[:length]
    py, twin = HollowMotor(MOTOR_ID, fd_enabled=bool(fd_motor)), Twin(fd_enabled=bool(fd_motor))
    for motor in (py, twin.device):
        motor.can_mode = CanMode(can_mode)
    c_frame = ffi.new("sb_simframe *", {"id": MOTOR_ID, "flags": flags, "len": length})
    c_frame.data[0:length] = data
    try:
        frame = Frame(
            arbitration_id=MOTOR_ID,
            data=data,
            is_extended_id=bool(flags & lib.SB_FRAME_EXT),
            is_fd=bool(flags & lib.SB_FRAME_FD),
            bitrate_switch=bool(flags & lib.SB_FRAME_BRS),
        )
    except (ValueError, ProtocolError):
        frame = None
    if (
        frame is None
        or (not frame.is_fd and frame.bitrate_switch)
        or (frame.is_fd and length not in _FD_LENGTHS)
    ):
        status = lib.sb_hollow_receive(twin.motor, c_frame, 0.01, twin.out, CAP, twin.n_out)
        assert status in (lib.SB_HOT_DONE, lib.SB_HOT_COLD) and twin.n_out[0] <= 1
        return
    assert twin.receive(frame, 0.01) == _sent(py.receive(frame, 0.01))
    _same_state(py, twin.device)


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=70))
def test_fuzz_random_frames_into_the_c_path(blob: bytes) -> None:
    fuzz_receive(blob)


def test_fuzz_the_set_point_shapes() -> None:
    """Every flag combination and length, with the bytes that reach the decoders' edges."""
    for head in range(4):
        for flags in range(8):
            for length in (0, 6, 8, 9, 16, 64):
                for fill in (b"\x00", b"\xff", b"\x02", b"\x01"):
                    fuzz_receive(bytes([head, flags, length]) + fill * 64)


def test_the_c_functions_check_their_arguments() -> None:
    twin = Twin()
    frame = _simframe(request_frame(MOTOR_ID, Stop()), 0.0)
    out, n_out, null = ffi.new("sb_simframe[]", 1), ffi.new("int *"), ffi.NULL
    receive, poll = lib.sb_hollow_receive, lib.sb_hollow_poll
    assert receive(null, frame, 0.0, out, 1, n_out) == lib.SB_E_ARG
    assert receive(twin.motor, null, 0.0, out, 1, n_out) == lib.SB_E_ARG
    assert receive(twin.motor, frame, 0.0, null, 1, n_out) == lib.SB_E_ARG
    assert receive(twin.motor, frame, 0.0, out, -1, n_out) == lib.SB_E_ARG
    assert receive(twin.motor, frame, math.nan, out, 1, n_out) == lib.SB_E_ARG
    assert receive(twin.motor, frame, 0.0, out, 1, null) == lib.SB_E_ARG
    frame.len = 65
    assert receive(twin.motor, frame, 0.0, out, 1, n_out) == lib.SB_E_ARG
    assert poll(null, 0.0, out, 1, n_out) == lib.SB_E_ARG
    assert poll(twin.motor, 0.0, out, 1, null) == lib.SB_E_ARG
    assert poll(twin.motor, math.nan, out, 1, n_out) == lib.SB_E_ARG
    other = ffi.new("sb_simmotor *")  # not a hollow twin
    assert receive(other, frame, 0.0, out, 1, n_out) == lib.SB_E_ARG
    assert lib.sb_hollow_next_deadline(null) == math.inf


def test_the_counter_indexes_are_the_headers() -> None:
    names = {key: getattr(lib, "SB_HOLLOW_" + key.upper()) for key in COUNTER_KEYS}
    assert list(names.values()) == list(range(len(COUNTER_KEYS))) == list(range(lib.SB_HOLLOW_COUNTERS))
    assert ffi.sizeof("sb_hollow_state") <= ffi.sizeof(ffi.typeof(ffi.new("sb_simmotor *").state))


def test_detach_hands_the_state_back_to_python() -> None:
    py, twin = HollowMotor(MOTOR_ID), Twin()
    trace = [
        request_frame(MOTOR_ID, Setpoint(position_deg=90.0, speed_rad_s=50.0, kp=100, kd=5, current_a=2.0)),
        request_frame(MOTOR_ID, Start()),
        request_frame(MOTOR_ID, Setpoint(position_deg=-30.0, speed_rad_s=80.0, kp=100, kd=5, current_a=3.0)),
    ]
    for i, frame in enumerate(trace):
        assert twin.receive(frame, i * 1e-3) == _sent(py.receive(frame, i * 1e-3))
    twin.device.core_detach()
    assert isinstance(twin.device, HollowCore) and twin.device._core is None
    _same_state(py, twin.device)
    later = request_frame(MOTOR_ID, Setpoint(position_deg=10.0, speed_rad_s=20.0, kp=1, kd=1, current_a=1.0))
    assert _sent(twin.device.receive(later, 0.2)) == _sent(py.receive(later, 0.2))
    _same_state(py, twin.device)


# ---- through the C engine (servobus.sim.corenet) against SimCanNetwork ----


def _network_trace(seed: int, ids: list[int], fd: bool, ticks: int) -> list[tuple[float, str, Any]]:
    """A 500 Hz control loop (six classic pairs fill 1.5 of its 2 ms): a set-point to every motor each
    tick, cold commands, reboots and silent motors in between (time, kind, what)."""
    rng = random.Random(seed)
    out: list[tuple[float, str, Any]] = []
    modes = dict.fromkeys(ids, CanMode.NORMAL)
    silent_until = dict.fromkeys(ids, -1)
    for tick in range(ticks):
        now = tick * 2e-3
        for motor_id in ids:
            if silent_until[motor_id] == tick:
                out.append((now, "unresponsive", (motor_id, False)))
            pick = rng.random()
            if pick < 0.06:
                command = _cold(rng)
                if isinstance(command, CanModeSwitch) and not fd:
                    modes[motor_id] = command.mode
                out.append((now, "frame", request_frame(motor_id, command)))
            elif pick < 0.07:
                out.append((now, "reboot", motor_id))
                modes[motor_id] = CanMode.NORMAL
            elif pick < 0.075 and silent_until[motor_id] < tick:
                out.append((now, "unresponsive", (motor_id, True)))
                silent_until[motor_id] = tick + rng.randrange(1, 20)
            else:
                command = (
                    _fd_command(rng, DEFAULT_MODEL)
                    if fd
                    else _setpoint(rng, DEFAULT_MODEL, modes[motor_id] is CanMode.EXTENDED)
                )
                out.append((now, "frame", request_frame(motor_id, command)))
        out.append((now + 1.9e-3, "advance", None))
    return out


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
def test_motors_on_the_c_engine_answer_as_on_the_python_network(fd: bool) -> None:
    ids = list(range(1, 7))
    bus: dict[str, Any] = {"bitrate": 1_000_000, "data_bitrate": 5_000_000 if fd else None}
    python = [HollowMotor(i, fd_enabled=fd) for i in ids]
    core = [HollowMotor(i, fd_enabled=fd) for i in ids]
    py_net = SimCanNetwork(python, bus=CanBusModel(**bus))
    c_net = CoreCanNetwork(core, bus=CanBusModel(**bus))
    for now, kind, what in _network_trace(7 + fd, ids, fd, ticks=400):
        if kind == "frame":
            py_net.send(what, now)
            c_net.send(what, now)
        elif kind == "reboot":
            python[what - 1].reboot(now)
            core[what - 1].reboot(now)
        elif kind == "unresponsive":
            motor_id, silent = what
            python[motor_id - 1].unresponsive = core[motor_id - 1].unresponsive = silent
        else:
            assert c_net.advance(now) == py_net.advance(now), now
    assert c_net.run_until_idle() == py_net.run_until_idle()
    for a, b in zip(python, core, strict=True):
        _same_state(a, b)
        assert b._core is not None and a.counters["replied"] > 100
    assert c_net.bus.busy_s == py_net.bus.busy_s
    for motor in core:  # leaving the C network hands the state back
        c_net.remove(motor.name)
        assert motor._core is None
    for a, b in zip(python, core, strict=True):
        _same_state(a, b)


# ---- cost: PYTHONPATH=src python tests/sim/devices/test_hollow_core.py ----


def measure(n: int = 20000) -> dict[str, float]:
    """ns per sb_hollow_receive call (from Python, the FFI crossing included) and µs per Python
    ``receive`` for a set-point and its reply, classic and CAN FD."""
    import time

    results: dict[str, float] = {}
    for fd in (False, True):
        name = "fd" if fd else "normal"
        command: HollowCommand[Any] = (
            FdCommand(
                position_deg=30.0, velocity_rpm=100.0, current_raw=800, mode=ControlMode.POSITION, run=True
            )
            if fd
            else Setpoint(position_deg=30.0, speed_rad_s=20.0, kp=100, kd=5, current_a=2.0)
        )
        frame = request_frame(MOTOR_ID, command)
        twin = Twin(fd_enabled=fd)
        twin.receive(request_frame(MOTOR_ID, Start()), 0.0)
        c_frame, out, n_out = _simframe(frame, 0.0), twin.out, twin.n_out
        receive, m = lib.sb_hollow_receive, twin.motor
        start = time.perf_counter()
        for i in range(n):
            receive(m, c_frame, i * 1e-3, out, CAP, n_out)
        results[f"c_ns_{name}"] = (time.perf_counter() - start) / n * 1e9
        py = HollowMotor(MOTOR_ID, fd_enabled=fd)
        py.receive(request_frame(MOTOR_ID, Start()), 0.0)
        start = time.perf_counter()
        for i in range(n):
            py.receive(frame, i * 1e-3)
        results[f"py_us_{name}"] = (time.perf_counter() - start) / n * 1e6
    return results


if __name__ == "__main__":
    print(measure())

"""Fuzz the simulator's C device path (issue 27: "one fuzz target feeds random frames into the C device
path"): random frames, straight into each family's ``sb_<family>_receive`` / ``sb_<family>_poll``, and
through a C-core network of 32 motors.

Per family, a motor's C twin (``device.core_attach(motor, None)``) is driven as the engine drives it:
C first, the Python model when C says SB_HOT_COLD (then ``core_push``), polls when C's or the model's
deadline comes. Frames have random identifiers around the motor's own (and anywhere), any length,
flags and bytes (first bytes mostly the families' command codes), at increasing random times.
Checked at every call: no crash (the file runs under ASan + UBSan in .ci/sanitize), a known status,
``n_out`` within the capacity, every frame out a valid CAN / CAN FD frame (``sb_can_frame_bits``
accepts it) ready no earlier than now, SB_HOT_COLD and SB_E_ARG leave the motor as it was (only
``py_deadline_s`` and the plant's advance to now may move), and the Python model accepts what C
left to it.

The network part puts 32 motors of the families with a C path on one CoreCanNetwork and the same
32 Python-only motors on a SimCanNetwork (the reference), sends both the same random frames and
compares what the host receives (times and frames) and every device's counters.

Every family's device must have its C path (``core_attach``): one without fails, never skips.
"""

from __future__ import annotations

import importlib
import math
import random
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reference.settings import ORACLE_EXAMPLES
from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import hollow, lk
from servobus.protocols import myactuator as ma

EXT, FD, BRS = lib.SB_FRAME_EXT, lib.SB_FRAME_FD, lib.SB_FRAME_BRS
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
ENGINE_CAP = 16  # SB_NET_OUT: what the engine gives a family's C path to answer into
STATUSES = {lib.SB_HOT_DONE, lib.SB_HOT_COLD, lib.SB_E_ARG}
# First data bytes: the three families' command codes (hot and cold ones), hollow's special frames'
# leading 0xFF, and anything.
CODES = (
    *(0x9A, 0x9B, 0x9C, 0x9D, 0x90, 0x92, 0x94, 0x80, 0x81, 0x88, 0x8C, 0x8D, 0x9E, 0x9F),
    *range(0xA0, 0xAA),
    *(0x60, 0x61, 0x62, 0x63, 0x64, 0x76, 0x77, 0x78, 0x79, 0xB1, 0xB2, 0xB3, 0xB5, 0xB6, 0x20, 0x19),
    *(0x30, 0x31, 0x32, 0x33, 0x34, 0x36, 0x42, 0x43, 0xFF, 0x00, 0x01),
)
_PY_DEADLINE = ffi.offsetof("sb_simmotor", "py_deadline_s")
# The plant's grid bookkeeping: advancing the plant to now is an observation (on the grid, the state at
# any later time is the same whether or not it was looked at in between), so a C path may do it before
# it decides to leave a frame cold. Everything else of the motor must stay as it was.
_PLANT = ffi.offsetof("sb_simmotor", "plant")
_PLANT_GRID = [
    (_PLANT + field.offset, _PLANT + field.offset + ffi.sizeof(field.type))
    for name, field in ffi.typeof("sb_plant").fields
    if name in ("steps", "resting", "committed", "now_s", "now")
]


@dataclass(frozen=True)
class FamilyPath:
    """How to build a family's motor and reach its C path."""

    name: str  # the family package (servobus.protocols.<name>) and the C prefix below
    prefix: str  # sb_<prefix>_receive / _poll / _next_deadline
    device: str  # the device class in servobus.protocols.<name>.sim.device
    kwargs: Callable[[st.DrawFn, int], dict[str, Any]]  # constructor arguments for a motor id
    ids: tuple[int, int]  # motor ids it takes (inclusive)
    codes: tuple[int, ...]  # first data bytes of its hot commands (drawn most often)

    def device_class(self) -> Any:
        module = importlib.import_module(f"servobus.protocols.{self.name}.sim.device")
        return getattr(module, self.device)

    def has_c_path(self) -> bool:
        return hasattr(self.device_class(), "core_attach")

    def build(self, draw: st.DrawFn, motor_id: int) -> Any:
        return self.device_class()(motor_id, **self.kwargs(draw, motor_id))


def _ma_kwargs(draw: st.DrawFn, motor_id: int) -> dict[str, Any]:
    return {
        "revision": draw(st.sampled_from(list(ma.Revision))),
        "has_brake": draw(st.booleans()),
        "can_id_filter": draw(st.booleans()),
    }


def _lk_kwargs(draw: st.DrawFn, motor_id: int) -> dict[str, Any]:
    model = lk.LkModel(
        revision=draw(st.sampled_from(list(lk.Revision))),
        motor_type=draw(st.sampled_from(list(lk.MotorType))),
        encoder_bits=draw(st.sampled_from([14, 16, 18])),
    )
    return {"model": model, "brake_engaged": draw(st.booleans())}


def _hollow_kwargs(draw: st.DrawFn, motor_id: int) -> dict[str, Any]:
    return {
        "fd_enabled": draw(st.booleans()),
        "control_mode": draw(st.sampled_from(list(hollow.ControlMode))),
        "host_id": draw(st.sampled_from([100, 0, motor_id + 1 if motor_id < 100 else 1])),
    }


FAMILIES = {
    "myactuator": FamilyPath(
        "myactuator",
        "ma",
        "MyActuatorMotor",
        _ma_kwargs,
        (1, 32),
        (0xA1, 0xA2, 0xA4, 0xA6, 0xA8, 0x9C, 0x92, 0x60, 0x61, 0x62, 0x9A, 0xB6, 0xB3, 0x80, 0x81, 0x88),
    ),
    "lk": FamilyPath(
        "lk",
        "lk",
        "LkMotor",
        _lk_kwargs,
        (1, 32),
        (0x9A, 0x9B, 0x9C, 0x9D, 0x90, 0x92, 0x94, 0x80, 0x81, 0x88, *range(0xA0, 0xA9)),
    ),
    # Set-points are any 8 bytes (the code is the position's high byte); FF x7 + F9..FE are special.
    "hollow": FamilyPath(
        "hollow", "hollow", "HollowMotor", _hollow_kwargs, (0, 100), (0x7F, 0x80, 0xFF, 0x00)
    ),
}


def _require_c_path(family: FamilyPath) -> None:
    assert family.has_c_path(), f"{family.name}: {family.device} has no core_attach (its C path is gone)"


# ---- frames ----


def _ident(rng: random.Random, ids: list[int]) -> int:
    """An identifier: one the motor listens on (most often), one next to it, a family's usual one, or any."""
    pick = rng.random()
    if pick < 0.55:
        return rng.choice(ids)
    if pick < 0.7:
        return max(0, rng.choice(ids) + rng.choice([-0x100, -2, -1, 1, 2, 0x40, 0x100]))
    if pick < 0.8:
        return rng.choice(
            [0x140 + rng.randint(0, 33), 0x240 + rng.randint(0, 33), 0x280, 0x300, 0x400, 0x500, 100]
        )
    return rng.randint(0, 0x1FFFFFFF if pick < 0.85 else 0x7FF)


def random_frame(rng: random.Random, ids: list[int], codes: tuple[int, ...] = CODES) -> Frame:
    """A valid CAN / CAN FD frame near ``ids``, what a bus can carry to the motor: classic 8-byte frames
    most often, the first byte mostly a command code, the rest random, zeros, ones or a repeated byte."""
    kind = rng.random()
    extended, is_fd = (kind > 0.9 or 0.7 < kind <= 0.8), kind > 0.8
    classic_length = 8 if rng.random() < 0.75 else rng.randint(0, 8)
    length = rng.choice(FD_LENGTHS) if is_fd else classic_length
    fill = rng.random()
    if fill < 0.4:
        rest = rng.randbytes(63)
    elif fill < 0.8:
        rest = bytes([rng.choice([0x00, 0x00, 0xFF, 0x7F, 0x80, 0x01])]) * 63
    else:
        rest = bytes(rng.choice([0x00, 0x01, 0x7F, 0x80, 0xFF]) for _ in range(63))
    pick = rng.random()
    code = rng.choice(codes) if pick < 0.6 else rng.choice(CODES) if pick < 0.85 else rng.randrange(256)
    if rng.random() < 0.05:  # hollow's special commands: FF x7 + F9..FE (and a byte next to them)
        code, rest = 0xFF, b"\xff" * 6 + bytes([rng.randint(0xF8, 0xFF)]) + rest[7:]
    return Frame(
        arbitration_id=_ident(rng, ids) & (0x1FFFFFFF if extended else 0x7FF),
        data=(bytes([code]) + rest)[:length],
        is_extended_id=extended,
        is_fd=is_fd,
        bitrate_switch=is_fd and rng.random() < 0.5,
    )


def program(
    rng: random.Random, ids: list[int], steps: int, codes: tuple[int, ...] = CODES
) -> Iterator[tuple[float, Frame, int]]:
    """(time step, frame, capacity): mostly the engine's capacity, sometimes a small one."""
    for _ in range(steps):
        step = (
            rng.choice([0.0, 1e-6, 1e-4, 2e-4, 1e-3, 0.02, 0.5])
            if rng.random() < 0.6
            else rng.uniform(0, 0.05)
        )
        cap = ENGINE_CAP if rng.random() < 0.85 else rng.randint(0, 2)
        yield step, random_frame(rng, ids, codes), cap


def _flags(frame: Frame) -> int:
    return (
        (EXT if frame.is_extended_id else 0)
        | (FD if frame.is_fd else 0)
        | (BRS if frame.bitrate_switch else 0)
    )


def _to_c(frame: Frame, t: float, out: Any) -> None:
    out.t, out.id, out.flags, out.len = t, frame.arbitration_id, _flags(frame), len(frame.data)
    out.node = out.tag = 0  # from the host; a frame C did not get from Python
    ffi.memmove(out.data, frame.data, len(frame.data))


# ---- one motor, driven as the engine drives it ----


class Driver:
    """One device on its C twin: C first, the Python model for what C leaves cold."""

    def __init__(self, family: FamilyPath, device: Any) -> None:
        self.device = device
        self.motor = ffi.new("sb_simmotor *")
        device.core_attach(self.motor, None)
        self.receive_c = getattr(lib, f"sb_{family.prefix}_receive")
        self.poll_c = getattr(lib, f"sb_{family.prefix}_poll")
        self.deadline_c = getattr(lib, f"sb_{family.prefix}_next_deadline")
        self.frame = ffi.new("sb_simframe *")
        self.out = ffi.new(f"sb_simframe[{ENGINE_CAP}]")
        self.n_out = ffi.new("int *")
        self.now_s = 0.0
        self.statuses: dict[int, int] = {}

    def listen_ids(self) -> list[int]:
        m = self.motor
        return [int(m.listen[i]) for i in range(m.n_listen)] or [0x141]

    def _snapshot(self) -> bytes:
        raw = bytearray(ffi.buffer(self.motor))
        raw[_PY_DEADLINE : _PY_DEADLINE + 8] = bytes(8)
        for start, end in _PLANT_GRID:
            raw[start:end] = bytes(end - start)
        return bytes(raw)

    def _check_c(self, status: int, cap: int, before: bytes, now_s: float) -> int:
        self.statuses[status] = self.statuses.get(status, 0) + 1
        assert status in STATUSES, status
        n = self.n_out[0]
        if status != lib.SB_HOT_DONE:
            assert n == 0
            assert self._snapshot() == before, "a COLD or refused call changed the motor"
            return status
        assert 0 <= n <= cap
        bits = ffi.new("int[2]")
        for frame in self.out[0:n]:
            assert (
                lib.sb_can_frame_bits(frame.id, frame.flags, frame.data, frame.len, bits, bits + 1)
                == lib.SB_OK
            ), f"invalid frame out: id={frame.id:#x} flags={frame.flags} len={frame.len}"
            assert math.isfinite(frame.t) and frame.t >= now_s, (frame.t, now_s)
        return status

    def _check_python(self, emissions: list[Any], now_s: float) -> None:
        for emission in emissions:
            assert emission.ready_s >= now_s
            assert isinstance(emission.frame, Frame)
        self.device.core_push()

    def _at(self, t: float) -> float:
        self.now_s = max(self.now_s, t)
        return self.now_s

    def receive(self, frame: Frame, t: float, cap: int = ENGINE_CAP) -> None:
        now = self._at(t)
        self.deadlines(now)
        _to_c(frame, now, self.frame)
        before = self._snapshot()
        status = self._check_c(
            self.receive_c(self.motor, self.frame, now, self.out, cap, self.n_out), cap, before, now
        )
        if status == lib.SB_HOT_COLD:
            self._check_python(self.device.receive(frame, now), now)

    def deadlines(self, until_s: float) -> None:
        """What the engine does up to ``until_s``: C's own deadlines and the model's, in time order."""
        for _ in range(64):  # a deadline that does not move on would loop: the bound says so below
            c_due = self.deadline_c(self.motor)
            py_due = self.motor.py_deadline_s
            due = min(c_due, py_due)
            if not due <= until_s:
                return
            now = self._at(due)
            if c_due <= py_due:
                before = self._snapshot()
                status = self._check_c(
                    self.poll_c(self.motor, now, self.out, ENGINE_CAP, self.n_out), ENGINE_CAP, before, now
                )
                if status == lib.SB_HOT_DONE:
                    assert self.deadline_c(self.motor) > now or self.n_out[0] > 0, (
                        "a C deadline that stays due"
                    )
                    continue
            self._check_python(self.device.poll(now), now)
        raise AssertionError(f"deadlines still due at {until_s} after 64 polls")


FUZZ = settings(
    deadline=None,
    max_examples=max(ORACLE_EXAMPLES // 3, 10),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_fuzz_c_device_path(name: str) -> None:
    family = FAMILIES[name]
    _require_c_path(family)

    @FUZZ
    @given(st.data())
    def fuzz(data: st.DataObject) -> None:
        motor_id = data.draw(st.integers(*family.ids), label="motor_id")
        driver = Driver(family, family.build(data.draw, motor_id))
        t = 0.0
        rng = random.Random(data.draw(st.integers(0, 2**32 - 1), label="seed"))
        for step, frame, cap in program(
            rng, driver.listen_ids(), data.draw(st.integers(1, 200), label="frames")
        ):
            t += step
            driver.receive(frame, t, cap)
        driver.deadlines(t + 1.0)
        driver.device.settle()
        assert all(value >= 0 for value in driver.device.counters.values())

    fuzz()


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_c_path_refuses_bad_arguments(name: str) -> None:
    """NULL pointers, a negative capacity, a NaN time, an oversized length and a motor of another
    family: SB_E_ARG (or COLD), never a crash, and the motor unchanged."""
    family = FAMILIES[name]
    _require_c_path(family)
    device = family.device_class()(family.ids[0] + 1)
    driver = Driver(family, device)
    receive, poll = driver.receive_c, driver.poll_c
    m, frame, out, n = driver.motor, driver.frame, driver.out, driver.n_out
    _to_c(Frame(arbitration_id=driver.listen_ids()[0], data=bytes(8)), 0.0, frame)
    before = driver._snapshot()
    for args in (
        (ffi.NULL, frame, 0.0, out, ENGINE_CAP, n),
        (m, ffi.NULL, 0.0, out, ENGINE_CAP, n),
        (m, frame, 0.0, ffi.NULL, ENGINE_CAP, n),
        (m, frame, 0.0, out, -1, n),
        (m, frame, math.nan, out, ENGINE_CAP, n),
    ):
        assert receive(*args) in (lib.SB_E_ARG, lib.SB_HOT_COLD)
    assert receive(m, frame, 0.0, out, ENGINE_CAP, ffi.NULL) == lib.SB_E_ARG
    for length in (65, 128, 255):
        frame.len = length
        assert receive(m, frame, 0.0, out, ENGINE_CAP, n) == lib.SB_E_ARG
    frame.len = 8
    assert poll(ffi.NULL, 0.0, out, ENGINE_CAP, n) == lib.SB_E_ARG
    assert poll(m, 0.0, out, ENGINE_CAP, ffi.NULL) == lib.SB_E_ARG
    assert poll(m, math.nan, out, ENGINE_CAP, n) == lib.SB_E_ARG
    assert poll(m, 0.0, out, -1, n) == lib.SB_E_ARG
    assert driver._snapshot() == before
    # A motor the family never attached (zeroed, another family's number): refused or left cold.
    for family_number in (lib.SB_FAMILY_PYTHON, 99):
        other = ffi.new("sb_simmotor *")
        other.family = family_number
        assert receive(other, frame, 0.0, out, ENGINE_CAP, n) in (lib.SB_E_ARG, lib.SB_HOT_COLD)
        assert poll(other, 0.0, out, ENGINE_CAP, n) in (lib.SB_E_ARG, lib.SB_HOT_COLD)


# ---- 32 C motors on one network ----


def _corenet() -> Any:
    return importlib.import_module("servobus.sim.corenet")


def _fleet(draw: st.DrawFn, families: list[FamilyPath]) -> Iterator[tuple[FamilyPath, int, dict[str, Any]]]:
    """32 motors over the families with a C path. MyActuator and LK share the 0x140+ID identifiers,
    so they split ids 1..32 between them; hollow motors take ids 33..."""
    shared = [f for f in families if f.name != "hollow"]
    hollow_family = [f for f in families if f.name == "hollow"]
    n_hollow = 32 if not shared else (11 if hollow_family else 0)
    n_shared = 32 - n_hollow
    for i in range(n_shared):
        family = shared[i * len(shared) // n_shared]
        yield family, i + 1, family.kwargs(draw, i + 1)
    for i in range(n_hollow):
        yield hollow_family[0], 33 + i, hollow_family[0].kwargs(draw, 33 + i)


def test_fuzz_network_of_32_c_motors() -> None:
    corenet = _corenet()
    from servobus.sim.network import SimCanNetwork

    families = list(FAMILIES.values())
    for family in families:
        _require_c_path(family)

    @settings(
        deadline=None,
        max_examples=max(ORACLE_EXAMPLES // 30, 5),
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(st.data())
    def fuzz(data: st.DataObject) -> None:
        fleet = list(_fleet(data.draw, families))
        c_devices = [f.device_class()(motor_id, **kwargs) for f, motor_id, kwargs in fleet]
        py_devices = [f.device_class()(motor_id, **kwargs) for f, motor_id, kwargs in fleet]
        core = corenet.CoreCanNetwork(c_devices)
        reference = SimCanNetwork(py_devices)
        cores = sum(1 for node in range(1, 64) if core._net.motors[node].family != lib.SB_FAMILY_PYTHON)
        assert cores == 32
        ids = sorted(
            {0x140 + k for k in range(1, 33)} | {33 + k for k in range(32)} | {0x280, 0x400 + 1, 100}
        )
        codes = tuple(code for family in families for code in family.codes)
        t = 0.0
        got: list[tuple[float, Frame]] = []
        expected: list[tuple[float, Frame]] = []
        rng = random.Random(data.draw(st.integers(0, 2**32 - 1), label="seed"))
        for step, frame, _cap in program(rng, ids, data.draw(st.integers(1, 150), label="frames"), codes):
            t += step
            for network, trace in ((core, got), (reference, expected)):
                trace += network.advance(t)
                network.send(frame, t)
        got += core.run_until_idle(t + 1.0)
        expected += reference.run_until_idle(t + 1.0)
        assert [(s, f) for s, f in got] == [(s, f) for s, f in expected]
        for c_device, py_device in zip(c_devices, py_devices, strict=True):
            assert c_device.counters == py_device.counters, c_device.name

    fuzz()

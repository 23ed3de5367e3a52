"""The C plant (csrc/sim_plant.c through servobus.sim.coreplant) against the Python reference.

Differential: the same seeded traces of changes and looks (tests/sim/test_plant_grid.py) drive a
:class:`~servobus.sim.plant.Plant` and a :class:`~servobus.sim.coreplant.CorePlant`; every snapshot
must be bit-identical, the grid included. Then the C entry points' argument checks, and a simulated
MyActuator motor on a CorePlant answering byte for byte as on a Python Plant.
"""

from __future__ import annotations

import gc
import math
import random
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.protocols import hollow, lk
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.codec import request_frame as hollow_request_frame
from servobus.protocols.hollow.sim.device import HOLLOW_PLANT_PARAMS, HollowMotor
from servobus.protocols.lk.codec import request_frame as lk_request_frame
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.lk.sim.state import LK_PLANT_PARAMS
from servobus.protocols.myactuator.codec import request_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.protocols.myactuator.sim.state import MYACTUATOR_PLANT_PARAMS
from servobus.sim.coreplant import CorePlant
from servobus.sim.plant import (
    Brake,
    Control,
    CurrentControl,
    Impedance,
    Off,
    Plant,
    PlantParams,
    PositionControl,
    SpeedControl,
)

from .test_plant_grid import Segment, controls, run, snapshot, traces

PARAMS = [
    PlantParams(),
    MYACTUATOR_PLANT_PARAMS,
    LK_PLANT_PARAMS,
    HOLLOW_PLANT_PARAMS,
    PlantParams(max_current_a=2.0, current_time_constant_s=2e-3, thermal_capacity_j_per_c=5.0),
    PlantParams(speed_limit_dps=300.0, max_speed_dps=300.0),  # (a limits file's: servobus.sim.limits)
]


def grid(plant: Plant | CorePlant) -> tuple[Any, ...]:
    """The grid and the committed state, which a snapshot does not show."""
    if isinstance(plant, CorePlant):
        pl = plant.ptr
        c = pl.committed
        state = (c.position_deg, c.speed_dps, c.current_a, c.temperature_c, c.speed_integral, c.speed_ref)
        return (pl.anchor_s.hex(), int(pl.steps), bool(pl.resting), *(float(x).hex() for x in state))
    c = plant._committed
    state = (c.position_deg, c.speed_dps, c.current_a, c.temperature_c, c.speed_integral, c.speed_ref)
    return (float(plant._anchor).hex(), plant._steps, plant._resting, *(float(x).hex() for x in state))


@given(
    trace=traces,
    start_s=st.floats(0.0, 100.0),
    params=st.sampled_from(PARAMS),
    max_step_s=st.sampled_from([5e-4, 1e-4, 1e-3, 3.3e-4]),
)
@settings(deadline=None)  # the profile's count: this is the differential test
def test_the_c_plant_is_the_python_plant_bit_for_bit(
    trace: list[Segment], start_s: float, params: PlantParams, max_step_s: float
) -> None:
    python = Plant(params, now_s=start_s, max_step_s=max_step_s)
    core = CorePlant(params, now_s=start_s, max_step_s=max_step_s)
    assert run(core, trace, start_s, lambda i, j: True) == run(python, trace, start_s, lambda i, j: True)
    assert grid(core) == grid(python)


@given(trace=traces, split=st.integers(0, 8), start_s=st.floats(0.0, 10.0))
@settings(deadline=None, max_examples=150)
def test_adopt_and_to_python_carry_the_whole_state_grid_included(
    trace: list[Segment], split: int, start_s: float
) -> None:
    """A Plant copied into C (inside an sb_simmotor) halfway goes on as the Plant does, and back."""
    first, rest = trace[:split], trace[split:]
    python = Plant(now_s=start_s)
    run(python, first, start_s, lambda i, j: True)
    motor = ffi.new("sb_simmotor *")
    core = CorePlant.adopt(python, motor.plant, motor)
    assert snapshot(core) == snapshot(python) and grid(core) == grid(python)
    end_s = python.now_s  # where run() left it: the end of the first part
    assert run(core, rest, end_s, lambda i, j: True) == run(python, rest, end_s, lambda i, j: True)
    moved = CorePlant.adopt(core)  # a CorePlant copied into another sb_plant
    assert snapshot(moved) == snapshot(core) and grid(moved) == grid(core)
    back = core.to_python()
    assert snapshot(back) == snapshot(python) and grid(back) == grid(python)
    later = python.now_s + 0.0123
    for plant in (back, python):
        plant.set_control(SpeedControl(speed_dps=50.0))
        plant.advance(later)
    assert snapshot(back) == snapshot(python) and grid(back) == grid(python)


@given(control=controls)
def test_controls_read_back_as_the_same_dataclasses(control: Control) -> None:
    core = CorePlant()
    core.set_control(control)
    assert core.control == control and type(core.control) is type(control)


def test_none_limits_are_nan_in_c_and_none_again_in_python() -> None:
    core = CorePlant()
    core.set_control(PositionControl(position_deg=1.0))
    c = core.ptr.control
    assert (c.mode, c.a) == (lib.SB_CONTROL_POSITION, 1.0) and math.isnan(c.b) and math.isnan(c.c)
    assert core.control == PositionControl(position_deg=1.0, max_speed_dps=None, max_current_a=None)
    core.set_control(SpeedControl(speed_dps=2.0, max_current_a=0.0))  # 0 is a limit, not "none"
    assert core.control == SpeedControl(speed_dps=2.0, max_current_a=0.0)
    with pytest.raises(TypeError, match="not a plant control"):
        core.set_control("off")  # type: ignore[arg-type]


def test_a_core_plant_is_a_drop_in_plant() -> None:
    """Every public name of Plant, and the same answers for the same calls."""
    overridden = {n for n in vars(CorePlant) if not n.startswith("_")} | {"params"}
    assert {n for n in dir(Plant) if not n.startswith("_")} <= overridden
    assert isinstance(CorePlant(), Plant)  # typed as one wherever a Plant goes
    python, core = Plant(PARAMS[1], now_s=1.0), CorePlant(PARAMS[1], now_s=1.0)
    for plant in (python, core):
        assert plant.resting and plant.params is PARAMS[1]
        plant.set_control(Impedance(position_rad=1.0, velocity_rad_s=0.0, kp=20.0, kd=1.0, torque_ff_nm=0.5))
        plant.external_torque_nm = -0.3
        plant.acceleration_dps2 = math.inf
        plant.advance(1.5)
        plant.temperature_c = 70.0
        plant.set_control(Brake())
        plant.advance(2.0)
    assert snapshot(core) == snapshot(python) and grid(core) == grid(python)
    with pytest.raises(ValueError, match="max_step_s=0 must be > 0"):
        CorePlant(max_step_s=0)
    with pytest.raises(ValueError, match="now_s=nan must be finite"):
        CorePlant(now_s=math.nan)
    for plant in (python, core):
        with pytest.raises(ValueError, match="now_s=inf"):
            plant.advance(math.inf)


def test_many_plants_advance_in_one_call() -> None:
    plants = ffi.new("sb_plant[]", 32)
    one_by_one = []
    for i in range(32):
        core = CorePlant.adopt(Plant(), ffi.addressof(plants, i), plants)
        core.set_control(SpeedControl(speed_dps=10.0 * i) if i % 3 else Off())
        one_by_one.append(CorePlant.adopt(core.to_python()))
    for k in range(1, 20):
        lib.sb_plants_advance(plants, 32, k * 0.00071)
        for plant in one_by_one:
            plant.advance(k * 0.00071)
    for i, plant in enumerate(one_by_one):
        assert snapshot(CorePlant.adopt(plant.to_python(), ffi.addressof(plants, i), plants)) == snapshot(
            plant
        )
    lib.sb_plants_advance(ffi.NULL, 5, 1.0)  # refused, nothing happens
    lib.sb_plants_advance(plants, 0, 1.0)


def test_the_owner_of_a_plant_inside_a_struct_is_kept_alive() -> None:
    motor = ffi.new("sb_simmotor *")
    core = CorePlant.adopt(Plant(), motor.plant, motor)
    del motor
    gc.collect()
    core.set_control(CurrentControl(current_a=1.0))
    core.advance(0.01)
    assert core.speed_dps > 0  # (ASan, .ci/sanitize, would see a freed motor)


# ---- the C entry points check their arguments ----


def _params_struct(**changes: float) -> Any:
    values = {name: getattr(PlantParams(), name) for name in PlantParams.__dataclass_fields__}
    values.update(changes)
    return ffi.new("sb_plant_params *", values)


@pytest.mark.parametrize(
    "bad",
    [
        {"inertia_kgm2": 0.0},
        {"torque_constant_nm_per_a": -1.0},
        {"gear_ratio": math.nan},
        {"max_current_a": 0.0},
        {"max_speed_dps": 0.0},
        {"current_time_constant_s": 0.0},
        {"speed_bandwidth_hz": 0.0},
        {"position_bandwidth_hz": -2.0},
        {"thermal_capacity_j_per_c": 0.0},
    ],
)
def test_init_refuses_what_plant_params_refuses(bad: dict[str, float]) -> None:
    pl = ffi.new("sb_plant *")
    assert lib.sb_plant_init(pl, _params_struct(**bad), 0.0, 5e-4) == lib.SB_E_ARG
    assert lib.sb_plant_check(pl) == lib.SB_E_ARG  # a failed init leaves a plant every call refuses
    with pytest.raises(ValueError):
        PlantParams(**bad)


def test_init_refuses_null_pointers_bad_steps_and_times() -> None:
    pl, good = ffi.new("sb_plant *"), _params_struct()
    assert lib.sb_plant_init(ffi.NULL, good, 0.0, 5e-4) == lib.SB_E_ARG
    assert lib.sb_plant_init(pl, ffi.NULL, 0.0, 5e-4) == lib.SB_E_ARG
    for step in (0.0, -1e-4, math.nan):
        assert lib.sb_plant_init(pl, good, 0.0, step) == lib.SB_E_ARG
    for now in (math.nan, math.inf, -math.inf):
        assert lib.sb_plant_init(pl, good, now, 5e-4) == lib.SB_E_ARG
    assert lib.sb_plant_init(pl, good, 0.0, 5e-4) == lib.SB_OK and lib.sb_plant_check(pl) == lib.SB_OK


def _bytes(pl: Any) -> bytes:
    return bytes(ffi.buffer(pl))


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_step_s", 0.0),
        ("max_step_s", math.nan),
        ("steps", -1),
        ("steps", 1 << 62),
        ("steps", 1000),  # the committed time after now_s
        ("anchor_s", math.nan),
        ("anchor_s", 0.5),
        ("now_s", math.inf),
    ],
)
def test_a_plant_written_bad_from_outside_is_left_untouched(field: str, value: float) -> None:
    core = CorePlant()
    core.set_control(SpeedControl(speed_dps=100.0))
    core.advance(0.01)
    pl = core.ptr
    setattr(pl, field, value)
    before = _bytes(pl)
    control = ffi.new("sb_control *", {"mode": lib.SB_CONTROL_CURRENT, "a": 1.0})
    state = ffi.new("sb_plant_state *")
    assert lib.sb_plant_check(pl) == lib.SB_E_ARG
    lib.sb_plant_advance(pl, 1.0)
    lib.sb_plant_set_control(pl, control)
    lib.sb_plant_set_acceleration(pl, 5.0)
    lib.sb_plant_set_external_torque(pl, 5.0)
    lib.sb_plant_set_state(pl, state)
    lib.sb_plants_advance(pl, 1, 2.0)
    assert _bytes(pl) == before


def test_unknown_control_modes_and_null_arguments_change_nothing() -> None:
    core = CorePlant()
    core.set_control(SpeedControl(speed_dps=100.0))
    core.advance(0.01)
    pl = core.ptr
    before = _bytes(pl)
    for mode in (-1, 6, 99):
        lib.sb_plant_set_control(pl, ffi.new("sb_control *", {"mode": mode}))
    lib.sb_plant_set_control(pl, ffi.NULL)
    lib.sb_plant_set_state(pl, ffi.NULL)
    for call in (lib.sb_plant_set_acceleration, lib.sb_plant_set_external_torque, lib.sb_plant_advance):
        call(ffi.NULL, 1.0)
    lib.sb_plant_set_control(ffi.NULL, ffi.new("sb_control *"))
    lib.sb_plant_set_state(ffi.NULL, ffi.new("sb_plant_state *"))
    for t in (math.nan, math.inf, 0.005, -math.inf):
        lib.sb_plant_advance(pl, t)
    assert _bytes(pl) == before
    assert lib.sb_plant_check(ffi.NULL) == lib.SB_E_ARG
    pl.control.mode = 17  # written from outside: refused, and Python says so
    assert lib.sb_plant_check(pl) == lib.SB_E_ARG
    with pytest.raises(ValueError, match="unknown control mode 17"):
        core.control  # noqa: B018


# ---- a device model on a CorePlant ----


def _commands(rng: random.Random) -> list[tuple[float, Any]]:
    """A seeded trace of MyActuator set-points, reads, stops and brake commands, with times."""
    t, out = 0.0, []
    for _ in range(400):
        t += rng.choice([1e-4, 2.5e-4, 1e-3, 1e-3, 1e-3, 3.7e-3, 0.02])
        pick = rng.randrange(14)
        if pick == 0:
            command: Any = ma.TorqueControl(current_a=round(rng.uniform(-5, 5), 2))
        elif pick == 1:
            command = ma.SpeedControl(
                speed_dps=round(rng.uniform(-900, 900), 2), max_torque_pct=rng.choice([None, 20, 80])
            )
        elif pick == 2:
            command = ma.AbsolutePositionControl(
                angle_deg=round(rng.uniform(-360, 360), 2), max_speed_dps=rng.choice([None, 100.0, 600.0])
            )
        elif pick == 3:
            command = ma.IncrementalPositionControl(
                angle_deg=round(rng.uniform(-90, 90), 2), max_speed_dps=300.0
            )
        elif pick == 4:
            command = ma.MotionCommand(
                position_rad=rng.uniform(-3, 3),
                velocity_rad_s=rng.uniform(-5, 5),
                kp=rng.uniform(0, 50),
                kd=rng.uniform(0, 3),
                torque_ff_nm=rng.uniform(-2, 2),
            )
        elif pick == 5:
            command = rng.choice([ma.MotorStop(), ma.MotorShutdown()])
        elif pick == 6:
            command = rng.choice([ma.BrakeRelease(), ma.BrakeLock()])
        elif pick == 7:
            command = ma.WriteAcceleration(
                index=rng.choice(list(ma.AccelIndex)), acceleration_dps_s=rng.choice([None, 500.0, 20000.0])
            )
        else:
            command = rng.choice(
                [
                    ma.ReadStatus1(),
                    ma.ReadStatus2(),
                    ma.ReadStatus3(),
                    ma.ReadMultiTurnAngle(),
                    ma.ReadStatus2(),
                ]
            )
        out.append((t, command))
    return out


def _answers(motor: MyActuatorMotor, trace: list[tuple[float, Any]]) -> list[tuple[str, int, bytes]]:
    seen = []
    for t, command in trace:
        frame: Frame = request_frame(command, motor.motor_id, revision=motor.revision)
        for emission in motor.receive(frame, t):
            seen.append((emission.ready_s.hex(), emission.frame.arbitration_id, bytes(emission.frame.data)))
    return seen


@pytest.mark.parametrize("seed", range(6))
def test_a_myactuator_motor_on_a_core_plant_answers_byte_for_byte(seed: int) -> None:
    trace = _commands(random.Random(seed))
    python, core = MyActuatorMotor(1), MyActuatorMotor(1)
    core._plant = CorePlant.adopt(core._plant)
    assert _answers(core, trace) == _answers(python, trace)
    assert snapshot(core.plant) == snapshot(python.plant)
    assert core.counters == python.counters


def _lk_commands(rng: random.Random) -> list[tuple[float, Any]]:
    mg = lk.MotorType.MG
    t, out = 0.0, []
    for _ in range(400):
        t += rng.choice([1e-4, 2.5e-4, 1e-3, 1e-3, 3.7e-3, 0.02])
        pick = rng.randrange(11)
        if pick == 0:
            command: Any = lk.TorqueControl(motor_type=mg, current_a=round(rng.uniform(-5, 5), 2))
        elif pick == 1:
            command = lk.SpeedControl(
                speed_dps=round(rng.uniform(-3000, 3000), 2),
                motor_type=mg,
                current_limit_a=rng.choice([1.0, 8.0]),
            )
        elif pick == 2:
            command = lk.MultiTurnPositionSpeed(
                angle_deg=round(rng.uniform(-2000, 2000), 2), max_speed_dps=rng.choice([None, 600.0, 3000.0])
            )
        elif pick == 3:
            command = lk.IncrementalPositionSpeed(
                increment_deg=round(rng.uniform(-500, 500), 2), max_speed_dps=900.0
            )
        elif pick == 4:
            command = rng.choice([lk.MotorOff(), lk.MotorStop(), lk.MotorRun()])
        elif pick == 5:
            command = lk.BrakeControl(action=rng.choice([lk.BrakeAction.ENGAGE, lk.BrakeAction.RELEASE]))
        else:
            command = rng.choice(
                [lk.ReadStatus1(), lk.ReadStatus2(), lk.ReadStatus3(), lk.ReadMultiTurnAngle()]
            )
        out.append((t, command))
    return out


@pytest.mark.parametrize("seed", range(4))
def test_an_lk_motor_on_a_core_plant_answers_byte_for_byte(seed: int) -> None:
    trace = _lk_commands(random.Random(seed))
    python, core = LkMotor(1, calibration_s=0.0), LkMotor(1, calibration_s=0.0)
    core._plant = CorePlant.adopt(core._plant)

    def answers(motor: LkMotor) -> list[tuple[str, int, bytes]]:
        seen = []
        for t, command in trace:
            frame = lk_request_frame(command, motor_id=1, model=motor.model)
            for emission in motor.receive(frame, t):
                seen.append(
                    (emission.ready_s.hex(), emission.frame.arbitration_id, bytes(emission.frame.data))
                )
        return seen

    assert answers(core) == answers(python)
    assert snapshot(core.plant) == snapshot(python.plant)


def _hollow_commands(rng: random.Random) -> list[tuple[float, Any]]:
    t, out = 0.0, []
    for _ in range(400):
        t += rng.choice([1e-4, 2.5e-4, 1e-3, 1e-3, 3.7e-3, 0.02])
        pick = rng.randrange(6)
        if pick < 3:
            command: Any = hollow.Setpoint(
                position_deg=round(rng.uniform(-300, 300), 2),
                speed_rad_s=round(rng.uniform(-50, 50), 2),
                kp=rng.randrange(0, 100),
                kd=rng.randrange(0, 100),
                current_a=round(rng.uniform(-3, 3), 2),
            )
        elif pick == 3:
            command = hollow.SelectMode(mode=rng.choice(list(hollow.ControlMode)))
        else:
            command = rng.choice([hollow.Start(), hollow.Stop()])
        out.append((t, command))
    return out


@pytest.mark.parametrize("seed", range(4))
def test_a_hollow_motor_on_a_core_plant_answers_byte_for_byte(seed: int) -> None:
    trace = _hollow_commands(random.Random(seed))
    python, core = HollowMotor(1), HollowMotor(1)
    core._plant = CorePlant.adopt(core._plant)

    def answers(motor: HollowMotor) -> list[tuple[str, int, bytes]]:
        seen = []
        for t, command in trace:
            for emission in motor.receive(hollow_request_frame(1, command), t):
                seen.append(
                    (emission.ready_s.hex(), emission.frame.arbitration_id, bytes(emission.frame.data))
                )
        return seen

    assert answers(core) == answers(python)
    assert snapshot(core.plant) == snapshot(python.plant)

"""The simulated actuator's mechanics and heat (servobus.sim.plant)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.sim.plant import (
    Brake,
    CurrentControl,
    Impedance,
    Off,
    Plant,
    PlantParams,
    PositionControl,
    SpeedControl,
)


def _run(plant: Plant, seconds: float, step: float = 0.001) -> list[tuple[float, float]]:
    """(position, speed) sampled every ``step`` while advancing ``seconds``."""
    samples = []
    start = plant.now_s
    for i in range(1, round(seconds / step) + 1):
        plant.advance(start + i * step)
        samples.append((plant.position_deg, plant.speed_dps))
    return samples


@given(st.floats(-5, 5), st.floats(0.0, 0.3))
# 25, not the profile's count: an example steps the plant up to 3,000 times (0.3 s at 0.1 ms).
@settings(max_examples=25, deadline=None)
def test_position_is_the_integral_of_the_reported_speed(current_a: float, seconds: float) -> None:
    plant = Plant(max_step_s=1e-4)
    plant.set_control(CurrentControl(current_a=current_a))
    step = 1e-4
    travelled = 0.0
    for i in range(1, round(seconds / step) + 1):
        plant.advance(i * step)
        travelled += plant.speed_dps * step
    assert plant.position_deg == pytest.approx(travelled, abs=1e-9)


def test_speed_mode_reaches_its_target_and_holds_it() -> None:
    plant = Plant()
    plant.set_control(SpeedControl(speed_dps=500.0))
    _run(plant, 1.0)
    assert plant.speed_dps == pytest.approx(500.0, rel=0.01)
    # steady state: the current only overcomes viscous friction
    friction_a = 0.05 * 500 * math.pi / 180 / 2.0
    assert plant.current_a == pytest.approx(friction_a, rel=0.05)


def test_current_limit_caps_acceleration() -> None:
    params = PlantParams(max_current_a=2.0)
    plant = Plant(params)
    plant.set_control(SpeedControl(speed_dps=5000.0, max_current_a=1.0))
    samples = _run(plant, 0.05)
    assert abs(plant.current_a) <= 1.0 + 1e-9
    # with 1 A (2 N·m) on 0.005 kg·m², speed grows by at most 400 rad/s² x 0.05 s
    assert samples[-1][1] <= 400 * 0.05 * 180 / math.pi + 1e-6
    plant.set_control(CurrentControl(current_a=50.0))
    _run(plant, 0.01)
    assert plant.current_a <= params.max_current_a


def test_position_mode_settles_without_exceeding_its_speed_limit() -> None:
    plant = Plant()
    plant.set_control(PositionControl(position_deg=90.0, max_speed_dps=200.0))
    samples = _run(plant, 3.0)
    assert plant.position_deg == pytest.approx(90.0, abs=0.5)
    assert max(abs(v) for _, v in samples) <= 200.0 * 1.05


def test_impedance_law_holds_a_spring_against_a_load() -> None:
    plant = Plant()
    plant.external_torque_nm = -1.0
    plant.set_control(Impedance(position_rad=0.5, velocity_rad_s=0.0, kp=10.0, kd=1.0, torque_ff_nm=0.0))
    _run(plant, 3.0)
    # kp·(p_des - p) = 1 N·m at rest
    assert math.radians(plant.position_deg) == pytest.approx(0.5 - 0.1, abs=0.005)
    assert plant.torque_nm == pytest.approx(1.0, rel=0.02)


def test_off_coasts_down_and_brake_holds() -> None:
    plant = Plant()
    plant.set_control(SpeedControl(speed_dps=300.0))
    _run(plant, 0.5)
    plant.set_control(Off())
    _run(plant, 0.05)
    assert plant.current_a == pytest.approx(0.0, abs=1e-3)
    assert 0 < plant.speed_dps < 300.0  # viscous friction slows it
    plant.set_control(Brake())
    held = plant.position_deg
    plant.external_torque_nm = 5.0
    _run(plant, 0.1)
    assert plant.speed_dps == 0.0 and plant.position_deg == held


def test_winding_heats_with_current_and_cools_to_ambient() -> None:
    plant = Plant(PlantParams(ambient_c=25.0))
    plant.set_control(Brake())
    _run(plant, 1.0, step=0.01)
    assert plant.temperature_c == 25.0
    plant.set_control(CurrentControl(current_a=20.0))
    plant.external_torque_nm = -40.0  # stall: all the current, no motion
    _run(plant, 10.0, step=0.01)
    # 120 W into 100 J/°C: about 1.2 °C/s at first
    assert 30.0 < plant.temperature_c < 37.0
    hot = plant.temperature_c
    plant.set_control(Off())
    plant.external_torque_nm = 0.0
    _run(plant, 300.0, step=0.1)
    assert 25.0 < plant.temperature_c < hot - 5
    assert plant.voltage_v == pytest.approx(48.0, abs=0.01)


def test_same_inputs_give_the_same_run() -> None:
    def run() -> tuple[float, float, float, float]:
        plant = Plant()
        plant.set_control(PositionControl(position_deg=-45.0))
        _run(plant, 0.3)
        return plant.position_deg, plant.speed_dps, plant.current_a, plant.temperature_c

    assert run() == run()


def test_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="inertia_kgm2=0 must be > 0"):
        PlantParams(inertia_kgm2=0)


def test_an_idle_motor_costs_one_step_and_cools_exactly() -> None:
    plant = Plant(PlantParams(ambient_c=20.0, thermal_resistance_c_per_w=1.0, thermal_capacity_j_per_c=100.0))
    plant.temperature_c = 60.0
    plant.set_control(Off())
    plant.advance(100.0)  # one time constant
    assert plant.temperature_c == pytest.approx(20.0 + 40.0 / math.e)
    plant.set_control(SpeedControl(speed_dps=100.0))
    _run(plant, 0.2)
    plant.set_control(Off())
    _run(plant, 5.0, step=0.1)
    assert plant.speed_dps == 0.0 and plant.current_a == 0.0  # coasted to a stop, back on the fast path


def test_long_fast_moves_brake_in_time_instead_of_ringing() -> None:
    plant = Plant(PlantParams(max_acceleration_dps2=6000.0, max_speed_dps=3000.0))
    plant.set_control(PositionControl(position_deg=800.0, max_speed_dps=2000.0))
    samples = _run(plant, 1.5)
    # 800 deg at 6000 dps/s: a triangle profile of about 0.73 s; settled well before 1.5 s
    assert plant.position_deg == pytest.approx(800.0, abs=1.0)
    assert max(p for p, _ in samples) <= 800.0 + 5.0

"""The plant's integration grid: its state at a time never depends on when it was looked at.

Whole steps of ``max_step_s`` run from the last change (the anchor) and are committed; a read at
``now_s`` adds one partial step that is not kept. These tests pin that rule bit for bit, since the C
plant (csrc/sim_plant.c) is checked against this one byte for byte and devices advance their plant
only when they are addressed or observed. The traces here are also the differential test's
(tests/sim/test_coreplant.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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

STEP_S = 5e-4


class PlantLike(Protocol):
    """What a trace drives: :class:`Plant` and ``servobus.sim.coreplant.CorePlant``."""

    position_deg: float
    speed_dps: float
    current_a: float
    temperature_c: float
    external_torque_nm: float
    acceleration_dps2: float

    @property
    def now_s(self) -> float: ...
    @property
    def control(self) -> Control: ...
    @property
    def torque_nm(self) -> float: ...
    @property
    def voltage_v(self) -> float: ...
    @property
    def motor_position_deg(self) -> float: ...
    @property
    def resting(self) -> bool: ...
    def set_control(self, control: Control) -> None: ...
    def advance(self, now_s: float) -> None: ...


def snapshot(plant: PlantLike) -> tuple[Any, ...]:
    """Everything a device can read, floats as hex (bit-identical, -0.0 and NaN included)."""
    floats = (
        plant.now_s,
        plant.position_deg,
        plant.speed_dps,
        plant.current_a,
        plant.temperature_c,
        plant.torque_nm,
        plant.voltage_v,
        plant.motor_position_deg,
        plant.external_torque_nm,
        plant.acceleration_dps2,
    )
    return (*(float(x).hex() for x in floats), plant.resting, plant.control)


# ---- seeded traces: changes at times, and the times the plant is looked at in between ----

_amps = st.floats(-40.0, 40.0)
_limit = st.none() | st.floats(0.0, 40.0)
controls: st.SearchStrategy[Control] = st.one_of(
    st.just(Off()),
    st.just(Brake()),
    st.builds(CurrentControl, current_a=_amps),
    st.builds(SpeedControl, speed_dps=st.floats(-3000.0, 3000.0), max_current_a=_limit),
    st.builds(
        PositionControl,
        position_deg=st.floats(-720.0, 720.0),
        max_speed_dps=st.none() | st.floats(0.0, 3000.0),
        max_current_a=_limit,
    ),
    st.builds(
        Impedance,
        position_rad=st.floats(-10.0, 10.0),
        velocity_rad_s=st.floats(-20.0, 20.0),
        kp=st.floats(0.0, 100.0),
        kd=st.floats(0.0, 5.0),
        torque_ff_nm=st.floats(-20.0, 20.0),
    ),
)


@dataclass(frozen=True)
class Change:
    """What happens at one time: ``what`` is a Control or (attribute, value)."""

    what: Control | tuple[str, float]


changes = st.one_of(
    controls.map(Change),
    controls.map(Change),  # controls twice as often as the rest
    st.tuples(st.just("external_torque_nm"), st.floats(-20.0, 20.0) | st.just(0.0)).map(Change),
    st.tuples(st.just("acceleration_dps2"), st.floats(100.0, 1e5) | st.just(math.inf)).map(Change),
    st.tuples(
        st.sampled_from(["position_deg", "speed_dps", "current_a", "temperature_c"]),
        st.floats(-100.0, 100.0),
    ).map(Change),
)


@dataclass(frozen=True)
class Segment:
    """A change, then ``length_s`` of time looked at at ``looks`` (fractions of the length)."""

    change: Change
    length_s: float
    looks: tuple[float, ...]


segments = st.builds(
    Segment,
    change=changes,
    # a few steps to a few hundred: long enough to come to rest now and then
    length_s=st.floats(1e-6, 0.08) | st.sampled_from([STEP_S, 2 * STEP_S, 0.3]),
    looks=st.lists(st.floats(0.0, 1.0, exclude_min=True), max_size=8).map(lambda xs: tuple(sorted(xs))),
)
traces = st.lists(segments, min_size=1, max_size=8)


def apply(plant: PlantLike, change: Change) -> None:
    what = change.what
    if isinstance(what, tuple):
        setattr(plant, what[0], what[1])
    else:
        plant.set_control(what)


def run(plant: PlantLike, trace: list[Segment], start_s: float, look: Any) -> list[tuple[Any, ...]]:
    """Drive ``plant`` through ``trace``; snapshots at every change and at every look that
    ``look(segment index, look index)`` selects, and at the end."""
    seen = []
    t = start_s
    for i, segment in enumerate(trace):
        plant.advance(t)
        seen.append(snapshot(plant))
        apply(plant, segment.change)
        seen.append(snapshot(plant))
        for j, fraction in enumerate(segment.looks):
            if look(i, j):
                plant.advance(t + fraction * segment.length_s)
                seen.append(snapshot(plant))
        t += segment.length_s
    plant.advance(t)
    seen.append(snapshot(plant))
    return seen


@given(trace=traces, start_s=st.floats(0.0, 10.0), data=st.data())
@settings(deadline=None, max_examples=150)
def test_the_state_at_a_time_is_the_same_however_it_is_reached(
    trace: list[Segment], start_s: float, data: st.DataObject
) -> None:
    """Two plants with the same changes, one looked at often, one only at the changes: every
    snapshot they both take (at the changes and at the end) is bit-identical."""
    often = Plant(now_s=start_s)
    seldom = Plant(now_s=start_s)
    looked_often = run(often, trace, start_s, lambda i, j: True)
    looked_seldom = run(seldom, trace, start_s, lambda i, j: False)
    # the seldom run's snapshots are the often run's without the looks in between
    looks = [len(s.looks) for s in trace]
    keep, at = [], 0
    for n in looks:
        keep += [at, at + 1]
        at += 2 + n
    keep.append(at)
    assert [looked_often[k] for k in keep] == looked_seldom
    # and a third plant looking at a random subset of the same times sees the same at each
    chosen = {(i, j) for i, n in enumerate(looks) for j in range(n) if data.draw(st.booleans())}
    some = Plant(now_s=start_s)
    looked_some = run(some, trace, start_s, lambda i, j: (i, j) in chosen)
    expected = []
    at = 0
    for i, n in enumerate(looks):
        expected += looked_often[at : at + 2]
        expected += [looked_often[at + 2 + j] for j in range(n) if (i, j) in chosen]
        at += 2 + n
    expected.append(looked_often[at])
    assert looked_some == expected


def test_a_long_advance_equals_many_short_ones() -> None:
    one, many = Plant(), Plant()
    for plant in (one, many):
        plant.set_control(PositionControl(position_deg=90.0, max_speed_dps=500.0))
    one.advance(0.4567)
    for k in range(1, 4568):
        many.advance(k * 1e-4)
    assert snapshot(one) == snapshot(many)


def _fresh_from(plant: Plant, control: Control) -> Plant:
    """A plant created at ``plant.now_s`` with its state (written) and ``control``."""
    fresh = Plant(plant.params, now_s=plant.now_s)
    fresh.set_control(control)
    fresh.position_deg = plant.position_deg
    fresh.speed_dps = plant.speed_dps
    fresh.current_a = plant.current_a
    fresh.temperature_c = plant.temperature_c
    fresh.external_torque_nm = plant.external_torque_nm
    return fresh


@pytest.mark.parametrize("change_s", [0.00123, 0.0125, 0.2000001])
def test_a_control_change_restarts_the_grid_at_its_time(change_s: float) -> None:
    """After a change at a time off the old grid, the plant steps from that time: it goes on as a
    plant created then with the same state and control (the current loop has no other memory)."""
    plant = Plant()
    plant.set_control(CurrentControl(current_a=5.0))
    plant.advance(change_s)
    fresh = _fresh_from(plant, CurrentControl(current_a=-3.0))
    plant.set_control(CurrentControl(current_a=-3.0))
    for dt in (STEP_S / 3, STEP_S, 2.5 * STEP_S, 0.05):
        plant.advance(change_s + dt)
        fresh.advance(change_s + dt)
        assert snapshot(plant) == snapshot(fresh), dt


def test_the_old_grid_is_not_kept_across_a_change() -> None:
    """The same control set again at an off-grid time changes the later state a little (the step
    it cut in two is committed): the grid is the last change's, not the first's."""
    kept, cut = Plant(), Plant()
    for plant in (kept, cut):
        plant.set_control(SpeedControl(speed_dps=500.0))
    cut.advance(0.00123)
    cut.set_control(SpeedControl(speed_dps=500.0))
    kept.advance(0.01)
    cut.advance(0.01)
    assert kept.speed_dps != cut.speed_dps
    assert kept.speed_dps == pytest.approx(cut.speed_dps, rel=1e-3)


def test_load_and_acceleration_writes_restart_the_grid() -> None:
    plant = Plant()
    plant.set_control(CurrentControl(current_a=2.0))
    plant.advance(0.0333)
    plant.external_torque_nm = -1.0
    fresh = _fresh_from(plant, CurrentControl(current_a=2.0))
    plant.advance(0.05)
    fresh.advance(0.05)
    assert snapshot(plant) == snapshot(fresh)
    speed = Plant()
    speed.set_control(SpeedControl(speed_dps=1000.0))
    speed.advance(0.0101)
    speed.acceleration_dps2 = 2000.0
    assert speed.acceleration_dps2 == 2000.0
    before = speed.speed_dps
    speed.advance(0.0201)  # the reference now ramps at 2000 dps/s: about 20 dps more
    assert speed.speed_dps - before == pytest.approx(20.0, abs=5.0)


def test_a_resting_plant_cools_in_one_exponential_from_when_it_came_to_rest() -> None:
    params = PlantParams(thermal_resistance_c_per_w=1.0, thermal_capacity_j_per_c=10.0)

    def heated() -> Plant:
        plant = Plant(params)
        plant.set_control(CurrentControl(current_a=20.0))
        plant.advance(2.0)
        plant.set_control(Brake())  # the current loop lets go in one step: at rest from 2.0005
        return plant

    plant, looked = heated(), heated()
    plant.advance(2.0 + STEP_S)
    assert plant.current_a == 0.0 and plant.speed_dps == 0.0
    assert not plant.resting  # still warm
    rest_s, warm_c = plant.now_s, plant.temperature_c
    for k in range(1, 200):
        looked.advance(2.0 + k * 0.05)
    plant.advance(2.0 + 199 * 0.05)
    assert snapshot(looked) == snapshot(plant)
    tau_s = 10.0
    expected = 25.0 + (warm_c - 25.0) * math.exp(-(plant.now_s - rest_s) / tau_s)
    assert plant.temperature_c == pytest.approx(expected, rel=1e-12)
    assert 25.0 < plant.temperature_c < warm_c


def test_a_brake_holds_a_loaded_shaft_and_it_cools() -> None:
    plant = Plant()
    plant.set_control(SpeedControl(speed_dps=300.0))
    plant.advance(0.3)
    plant.set_control(Brake())
    plant.external_torque_nm = 5.0
    plant.advance(0.3 + STEP_S)  # one step: the brake stops it, the current loop lets go
    held = plant.position_deg
    for k in range(2, 50):
        plant.advance(0.3 + k * 0.01)
        assert plant.speed_dps == 0.0 and plant.position_deg == held and plant.current_a == 0.0


def test_state_writes_commit_and_read_back() -> None:
    plant = Plant(PlantParams(ambient_c=20.0, thermal_resistance_c_per_w=1.0, thermal_capacity_j_per_c=100.0))
    plant.advance(1.2345)
    plant.temperature_c = 60.0  # at rest, off: cooling runs from the write
    assert plant.temperature_c == 60.0 and not plant.resting
    plant.advance(101.2345)
    assert plant.temperature_c == 20.0 + 40.0 * math.exp(-100.0 / 100.0)
    plant.position_deg = 50.0
    assert plant.position_deg == 50.0 and plant.motor_position_deg == 300.0
    plant.advance(102.0)
    assert plant.position_deg == 50.0  # off and still: nothing moves it
    plant.set_control(PositionControl(position_deg=0.0))
    plant.advance(105.0)
    assert plant.position_deg == pytest.approx(0.0, abs=0.5)
    plant.speed_dps = 100.0
    plant.current_a = 0.0
    plant.set_control(Off())
    assert plant.speed_dps == 100.0 and plant.current_a == 0.0
    plant.advance(105.0 + STEP_S)
    assert 0.0 < plant.speed_dps < 100.0  # coasting down from the written speed


def test_a_time_not_later_than_now_changes_nothing() -> None:
    plant = Plant()
    plant.set_control(SpeedControl(speed_dps=100.0))
    plant.advance(0.01)
    before = snapshot(plant)
    for t in (0.01, 0.005, -1.0, math.nan):
        plant.advance(t)
        assert snapshot(plant) == before


def test_a_step_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_step_s=0 must be > 0"):
        Plant(max_step_s=0)

"""A plant's whole state, grid included (:class:`~servobus.sim.plant.PlantGrid`): a copy made from it,
in Python or in C, goes on exactly as the plant it was read from."""

from __future__ import annotations

import pytest

from servobus.sim.coreplant import CorePlant
from servobus.sim.plant import Plant, PlantGrid, PositionControl, SpeedControl


def _moving(plant_cls: type[Plant] = Plant) -> Plant:
    plant = plant_cls(now_s=0.0)
    plant.set_control(SpeedControl(speed_dps=90.0))
    plant.advance(0.0123)  # mid-step: the grid's partial step matters
    plant.external_torque_nm = 0.05
    plant.advance(0.0311)
    return plant


@pytest.mark.parametrize("copy_cls", [Plant, CorePlant], ids=["python", "c"])
def test_a_copy_from_the_grid_goes_on_exactly_as_the_original(copy_cls: type[Plant]) -> None:
    original = _moving()
    grid = original.grid()
    assert isinstance(grid, PlantGrid) and grid.steps > 0
    copy = copy_cls.from_grid(original.params, grid)
    assert copy.grid() == grid
    for plant in (original, copy):
        plant.set_control(PositionControl(position_deg=3.0))
        plant.advance(0.25)
    assert copy.grid() == original.grid()
    assert (copy.position_deg, copy.speed_dps, copy.current_a) == (
        original.position_deg,
        original.speed_dps,
        original.current_a,
    )


def test_restore_takes_the_state_but_keeps_the_params() -> None:
    original = _moving()
    other = Plant(now_s=5.0)
    other.restore(original.grid())
    assert other.grid() == original.grid() and other.params is not None
    core = CorePlant.adopt(original)
    assert core.to_python().grid() == original.grid()

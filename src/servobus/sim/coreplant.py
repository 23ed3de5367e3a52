"""The plant in the C core: :class:`CorePlant` is :class:`~servobus.sim.plant.Plant` over an ``sb_plant``.

csrc/sim_plant.c integrates the same equations as :mod:`servobus.sim.plant` on the same grid, in the
same floating-point order, so a CorePlant's state is the Python Plant's bit for bit (the
differential test, tests/sim/test_coreplant.py, holds it to that). A device model may therefore
swap one for the other: the public API is the same (``params``, ``control``, the state attributes
and their setters, ``advance``, ``set_control``), and the state lives in C memory that the
simulator's C paths (csrc/sim_*.c) advance and change without Python.

The ``sb_plant`` is either the CorePlant's own or one inside a bigger C struct (an ``sb_simmotor``'s
``plant``): then the CorePlant keeps that struct's owner alive. :meth:`CorePlant.adopt` copies a
Python Plant in, grid included, and :meth:`CorePlant.to_python` copies it back out.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from servobus.core._lib import ffi, lib
from servobus.sim.plant import (
    STATE_FIELDS,
    Brake,
    Control,
    CurrentControl,
    Impedance,
    Off,
    Plant,
    PlantGrid,
    PlantParams,
    PositionControl,
    SpeedControl,
)

__all__ = ["CorePlant", "control_fields", "control_from_fields"]

_OFF, _BRAKE = Off(), Brake()
_PLANT_TYPE = ffi.typeof("sb_plant")


def _limit(value: float | None) -> float:
    return math.nan if value is None else value


def _optional(value: float) -> float | None:
    return None if math.isnan(value) else value


def control_fields(control: Control) -> tuple[int, float, float, float, float, float]:
    """(mode, a, b, c, d, e) of ``sb_control`` (csrc/sim_plant.h) for a Control."""
    if isinstance(control, Off):
        return (lib.SB_CONTROL_OFF, 0.0, 0.0, 0.0, 0.0, 0.0)
    if isinstance(control, Brake):
        return (lib.SB_CONTROL_BRAKE, 0.0, 0.0, 0.0, 0.0, 0.0)
    if isinstance(control, CurrentControl):
        return (lib.SB_CONTROL_CURRENT, control.current_a, 0.0, 0.0, 0.0, 0.0)
    if isinstance(control, SpeedControl):
        return (lib.SB_CONTROL_SPEED, control.speed_dps, _limit(control.max_current_a), 0.0, 0.0, 0.0)
    if isinstance(control, PositionControl):
        return (
            lib.SB_CONTROL_POSITION,
            control.position_deg,
            _limit(control.max_speed_dps),
            _limit(control.max_current_a),
            0.0,
            0.0,
        )
    if isinstance(control, Impedance):
        return (
            lib.SB_CONTROL_IMPEDANCE,
            control.position_rad,
            control.velocity_rad_s,
            control.kp,
            control.kd,
            control.torque_ff_nm,
        )
    raise TypeError(f"not a plant control: {control!r}")


def control_from_fields(c: Any) -> Control:
    """The Control dataclass an ``sb_control`` holds."""
    mode = c.mode
    if mode == lib.SB_CONTROL_OFF:
        return _OFF
    if mode == lib.SB_CONTROL_BRAKE:
        return _BRAKE
    if mode == lib.SB_CONTROL_CURRENT:
        return CurrentControl(current_a=c.a)
    if mode == lib.SB_CONTROL_SPEED:
        return SpeedControl(speed_dps=c.a, max_current_a=_optional(c.b))
    if mode == lib.SB_CONTROL_POSITION:
        return PositionControl(position_deg=c.a, max_speed_dps=_optional(c.b), max_current_a=_optional(c.c))
    if mode == lib.SB_CONTROL_IMPEDANCE:
        return Impedance(position_rad=c.a, velocity_rad_s=c.b, kp=c.c, kd=c.d, torque_ff_nm=c.e)
    raise ValueError(f"sb_plant holds an unknown control mode {mode}")


def _params(params: PlantParams) -> Any:
    return ffi.new("sb_plant_params *", {f.name: getattr(params, f.name) for f in fields(params)})


def _pointer(ptr: Any) -> Any:
    """An ``sb_plant *`` from an ``sb_plant *`` or an ``sb_plant`` (a struct member: ``motor.plant``)."""
    kind = ffi.typeof(ptr)
    if kind == _PLANT_TYPE:
        return ffi.addressof(ptr)
    if kind.kind == "pointer" and kind.item == _PLANT_TYPE:
        return ptr
    raise TypeError(f"expected an sb_plant * or an sb_plant, got {kind.cname}")


class CorePlant(Plant):
    """:class:`~servobus.sim.plant.Plant`'s API and behaviour (bit for bit) over a C ``sb_plant``.

    A subclass so that it goes wherever a Plant is typed (device models, replies); it overrides the
    whole public API and keeps none of Plant's Python state.

    Args:
        params, now_s, max_step_s: as :class:`~servobus.sim.plant.Plant`.
        ptr: the ``sb_plant`` to use (``sb_plant *`` or a struct member such as ``motor.plant``);
            None: a new one of its own.
        owner: the cdata that owns ``ptr``'s memory, kept alive with this plant.
    """

    __slots__ = ("_at_now", "_control_in", "_owner", "_pl", "params")

    def __init__(
        self,
        params: PlantParams | None = None,
        *,
        now_s: float = 0.0,
        max_step_s: float = 5e-4,
        ptr: Any = None,
        owner: Any = None,
    ):
        if not max_step_s > 0:
            raise ValueError(f"max_step_s={max_step_s!r} must be > 0")
        if not math.isfinite(now_s):
            raise ValueError(f"now_s={now_s!r} must be finite")
        # (Plant.__init__ is not called: the state is the sb_plant's)
        self._bind(params or PlantParams(), ptr, owner)
        if lib.sb_plant_init(self._pl, _params(self.params), now_s, max_step_s) != lib.SB_OK:
            raise ValueError(f"sb_plant_init refused {self.params!r}")  # pragma: no cover - checked above

    def _bind(self, params: PlantParams, ptr: Any, owner: Any) -> None:
        self.params = params
        if ptr is None:
            ptr = owner = ffi.new("sb_plant *")
        self._pl = _pointer(ptr)
        self._at_now = self._pl.now  # the state at now_s, in place (one attribute read less per read)
        self._owner = owner
        self._control_in = ffi.new("sb_control *")

    @classmethod
    def adopt(cls, plant: Plant, ptr: Any = None, owner: Any = None) -> CorePlant:
        """A CorePlant in ``ptr`` (None: its own) with ``plant``'s whole state, grid included: it
        goes on exactly as ``plant`` would have. ``plant`` may be a CorePlant (its struct is copied)."""
        if isinstance(plant, CorePlant):
            source = plant.ptr
            core = cls(
                plant.params, now_s=source.anchor_s, max_step_s=source.max_step_s, ptr=ptr, owner=owner
            )
            core.ptr[0] = source[0]
            return core
        core = cls(plant.params, now_s=plant.now_s, ptr=ptr, owner=owner)
        core.restore(plant.grid())
        return core

    @classmethod
    def from_grid(cls, params: PlantParams, grid: PlantGrid) -> CorePlant:
        """A CorePlant of its own with ``grid``'s whole state, as :meth:`Plant.from_grid
        <servobus.sim.plant.Plant.from_grid>`."""
        core = cls(params, now_s=grid.anchor_s, max_step_s=grid.max_step_s)
        core.restore(grid)
        return core

    def restore(self, grid: PlantGrid) -> None:
        """Take ``grid``'s whole state, grid included (the params stay this plant's own)."""
        pl = self._pl
        if lib.sb_plant_init(pl, _params(self.params), grid.anchor_s, grid.max_step_s) != lib.SB_OK:
            raise ValueError(f"sb_plant_init refused {self.params!r}")  # pragma: no cover
        pl.control = control_fields(grid.control)
        pl.acceleration_dps2 = grid.acceleration_dps2
        pl.external_torque_nm = grid.external_torque_nm
        pl.steps = grid.steps
        pl.resting = int(grid.resting)
        pl.committed = list(grid.committed)
        pl.now_s = grid.now_s
        pl.now = list(grid.now)

    def grid(self) -> PlantGrid:
        """The whole state, grid included, as :meth:`Plant.grid <servobus.sim.plant.Plant.grid>`."""
        pl = self._pl
        return PlantGrid(
            control=self.control,
            acceleration_dps2=float(pl.acceleration_dps2),
            external_torque_nm=float(pl.external_torque_nm),
            max_step_s=float(pl.max_step_s),
            anchor_s=float(pl.anchor_s),
            steps=int(pl.steps),
            resting=bool(pl.resting),
            committed=tuple(float(getattr(pl.committed, name)) for name in STATE_FIELDS),
            now_s=float(pl.now_s),
            now=tuple(float(getattr(pl.now, name)) for name in STATE_FIELDS),
        )

    def to_python(self) -> Plant:
        """A Python :class:`~servobus.sim.plant.Plant` with this plant's whole state (grid included)."""
        return Plant.from_grid(self.params, self.grid())

    @property
    def ptr(self) -> Any:
        """The ``sb_plant *`` this plant lives in (for the simulator's C paths)."""
        return self._pl

    # ---- Plant's API ----

    @property
    def now_s(self) -> float:
        return float(self._pl.now_s)

    @property
    def control(self) -> Control:
        """What the drive is asked to do (as C holds it: the C paths may have changed it)."""
        return control_from_fields(self._pl.control)

    @property
    def position_deg(self) -> float:
        return float(self._at_now.position_deg)

    @position_deg.setter
    def position_deg(self, value: float) -> None:
        self._write("position_deg", value)

    @property
    def speed_dps(self) -> float:
        return float(self._at_now.speed_dps)

    @speed_dps.setter
    def speed_dps(self, value: float) -> None:
        self._write("speed_dps", value)

    @property
    def current_a(self) -> float:
        return float(self._at_now.current_a)

    @current_a.setter
    def current_a(self, value: float) -> None:
        self._write("current_a", value)

    @property
    def temperature_c(self) -> float:
        return float(self._at_now.temperature_c)

    @temperature_c.setter
    def temperature_c(self, value: float) -> None:
        self._write("temperature_c", value)

    @property
    def external_torque_nm(self) -> float:
        return float(self._pl.external_torque_nm)

    @external_torque_nm.setter
    def external_torque_nm(self, value: float) -> None:
        lib.sb_plant_set_external_torque(self._pl, value)

    @property
    def acceleration_dps2(self) -> float:
        return float(self._pl.acceleration_dps2)

    @acceleration_dps2.setter
    def acceleration_dps2(self, value: float) -> None:
        lib.sb_plant_set_acceleration(self._pl, value)

    @property
    def torque_nm(self) -> float:
        return float(self._at_now.current_a * self.params.torque_constant_nm_per_a)

    @property
    def voltage_v(self) -> float:
        p = self.params
        return float(p.supply_v - abs(self._at_now.current_a) * p.supply_resistance_ohm)

    @property
    def motor_position_deg(self) -> float:
        """Rotor angle (before the gear), what a motor-side encoder counts."""
        return float(self._at_now.position_deg * self.params.gear_ratio)

    @property
    def resting(self) -> bool:
        """Unpowered, still and at ambient temperature: :meth:`advance` only moves its clock."""
        now, mode = self._at_now, self._pl.control.mode
        if now.current_a != 0.0 or now.speed_dps != 0.0:
            return False
        return bool(mode == lib.SB_CONTROL_OFF or mode == lib.SB_CONTROL_BRAKE) and (
            now.temperature_c == self.params.ambient_c
        )

    def set_control(self, control: Control) -> None:
        c = self._control_in
        c.mode, c.a, c.b, c.c, c.d, c.e = control_fields(control)
        lib.sb_plant_set_control(self._pl, c)

    def advance(self, now_s: float) -> None:
        """Integrate up to ``now_s`` (no-op if it is not later than the plant's time).

        Raises:
            ValueError: ``now_s`` is infinite (the grid would never get there).
        """
        if now_s == math.inf:
            raise ValueError("now_s=inf: a plant cannot advance to infinity")
        lib.sb_plant_advance(self._pl, now_s)

    def _write(self, name: str, value: float) -> None:
        state = ffi.new("sb_plant_state *", self._pl.now)
        setattr(state, name, value)
        lib.sb_plant_set_state(self._pl, state)

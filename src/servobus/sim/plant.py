"""The mechanical and thermal plant behind a simulated motor, apart from any protocol.

A rigid output shaft with inertia and viscous friction, driven by a current-controlled motor
through a gear; the closed-loop modes the manuals describe (current, speed, position, MIT
impedance) are cascaded loops around it with the motor's limits; the winding heats with I²R and
cools towards ambient. Everything is given at the **output shaft** (after the gear), as the
manuals report angles and speeds; ``gear_ratio`` only converts to motor-side values (encoders).

Sans-IO: :meth:`Plant.advance` takes the simulated time, integrates in fixed sub-steps on a grid
from the last change (semi-implicit Euler, so the reported position is exactly the integral of the
reported speed; see :class:`Plant`), and never reads a clock. Device models own a Plant and set
its :class:`Control`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "STATE_FIELDS",
    "Brake",
    "Control",
    "CurrentControl",
    "Impedance",
    "Off",
    "Plant",
    "PlantGrid",
    "PlantParams",
    "PositionControl",
    "SpeedControl",
]

_RAD_PER_DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True, kw_only=True)
class PlantParams:
    """Physical constants of one actuator (defaults: a mid-size geared servo, RMD-X8 class).

    Attributes:
        inertia_kgm2: rotor + gear inertia reflected at the output shaft.
        viscous_friction_nm_s_per_rad: output-shaft damping.
        torque_constant_nm_per_a: output-shaft torque per ampere of q-axis current.
        gear_ratio: motor turns per output turn.
        max_current_a: the drive's current limit.
        max_speed_dps: the fastest output speed the position loop commands.
        max_acceleration_dps2: slew limit of the speed reference in speed and position modes
            (the drives' acceleration setting; device models may change ``Plant.acceleration_dps2``).
        current_time_constant_s: first-order lag of the current loop.
        speed_bandwidth_hz, position_bandwidth_hz: outer-loop bandwidths.
        winding_resistance_ohm, thermal_resistance_c_per_w, thermal_capacity_j_per_c: I²R heating.
        ambient_c: start and ambient temperature.
        supply_v, supply_resistance_ohm: bus voltage and its sag under load.
        speed_limit_dps: the drive's speed limit in speed mode: a faster target is clamped to it
            (``math.inf``: none; the host-side limits give the simulated motors theirs:
            :mod:`servobus.sim.limits`).
    """

    inertia_kgm2: float = 0.005
    viscous_friction_nm_s_per_rad: float = 0.05
    torque_constant_nm_per_a: float = 2.0
    gear_ratio: float = 6.0
    max_current_a: float = 30.0
    max_speed_dps: float = 1800.0
    max_acceleration_dps2: float = 10000.0
    current_time_constant_s: float = 0.0005
    speed_bandwidth_hz: float = 20.0
    position_bandwidth_hz: float = 4.0
    winding_resistance_ohm: float = 0.3
    thermal_resistance_c_per_w: float = 1.5
    thermal_capacity_j_per_c: float = 100.0
    ambient_c: float = 25.0
    supply_v: float = 48.0
    supply_resistance_ohm: float = 0.02
    speed_limit_dps: float = math.inf

    def __post_init__(self) -> None:
        for name in (
            "inertia_kgm2",
            "torque_constant_nm_per_a",
            "gear_ratio",
            "max_current_a",
            "max_speed_dps",
            "current_time_constant_s",
            "speed_bandwidth_hz",
            "position_bandwidth_hz",
            "thermal_capacity_j_per_c",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be > 0")
        if not self.speed_limit_dps >= 0:
            raise ValueError(f"speed_limit_dps={self.speed_limit_dps!r} must be >= 0")


# ---- what the drive is asked to do (set by the device model from decoded commands) ----


@dataclass(frozen=True, slots=True)
class Off:
    """Output off: no current, the shaft coasts (0x80 motor off, hollow stop)."""


@dataclass(frozen=True, slots=True)
class Brake:
    """Holding brake engaged: the shaft does not move."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CurrentControl:
    """Current (torque) control: the drive holds ``current_a``."""

    current_a: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedControl:
    """Speed control: the drive holds ``speed_dps``, its current within ``max_current_a`` (None:
    the plant's own limit)."""

    speed_dps: float
    max_current_a: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionControl:
    """Position control: the drive moves to ``position_deg`` at most at ``max_speed_dps``, its
    current within ``max_current_a`` (None: the plant's own limits)."""

    position_deg: float
    max_speed_dps: float | None = None
    max_current_a: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Impedance:
    """MIT law: torque = kp·(p_des - p) + kd·(v_des - v) + t_ff, in rad, rad/s, N·m."""

    position_rad: float
    velocity_rad_s: float
    kp: float
    kd: float
    torque_ff_nm: float


Control = Off | Brake | CurrentControl | SpeedControl | PositionControl | Impedance
"""What a device model asks of its :class:`Plant` (``plant.control``), set from decoded commands."""


STATE_FIELDS = ("position_deg", "speed_dps", "current_a", "temperature_c", "speed_integral", "speed_ref")
"""The plant's integrated quantities, in csrc/sim_plant.h ``sb_plant_state``'s order."""


@dataclass(frozen=True, slots=True)
class PlantGrid:
    """A plant's whole state, its integration grid included: a plant made from it (``Plant.from_grid``,
    or the C plant's ``CorePlant.adopt``) goes on exactly as the one it was taken from (``Plant.grid``).

    ``committed`` and ``now`` are the :data:`STATE_FIELDS` at ``anchor_s + steps * max_step_s`` and at
    ``now_s``."""

    control: Control
    acceleration_dps2: float
    external_torque_nm: float
    max_step_s: float
    anchor_s: float
    steps: int
    resting: bool
    committed: tuple[float, ...]
    now_s: float
    now: tuple[float, ...]


class _State:
    """The integrated quantities (csrc/sim_plant.h ``sb_plant_state``), committed or observed."""

    __slots__ = ("current_a", "position_deg", "speed_dps", "speed_integral", "speed_ref", "temperature_c")

    def __init__(self, temperature_c: float) -> None:
        self.position_deg = 0.0
        self.speed_dps = 0.0
        self.current_a = 0.0
        self.temperature_c = temperature_c
        self.speed_integral = 0.0  # A, the speed loop's integral term
        self.speed_ref = 0.0  # dps, the slew-limited reference the speed loop follows

    def copy_from(self, other: _State) -> None:
        self.position_deg = other.position_deg
        self.speed_dps = other.speed_dps
        self.current_a = other.current_a
        self.temperature_c = other.temperature_c
        self.speed_integral = other.speed_integral
        self.speed_ref = other.speed_ref


class Plant:
    """State and dynamics of one actuator; the device model reads it to fill its replies.

    Integration runs on a grid: whole steps of ``max_step_s`` from the **anchor**, the time of the
    last change (:meth:`set_control`, a write of ``external_torque_nm``, ``acceleration_dps2`` or a
    state attribute), are committed; the state read at :attr:`now_s` is the last committed one plus
    one partial step, which is not committed. So the state at a time depends only on the changes
    and their times, never on when (or how often) the plant was advanced: a device may advance it
    only when it is addressed or observed. A change first commits the state observed at
    :attr:`now_s` and starts a new grid there. Once a committed step leaves the plant at rest
    (unpowered and still, or braked) stepping stops, and the temperature read later is one
    exponential cooling from that step's time. csrc/sim_plant.c is the same, bit for bit.

    Args:
        params: physical constants.
        now_s: simulated time of creation.
        max_step_s: integration sub-step. 500 µs keeps the default loops well inside stability
            (speed loop: 2π·20 Hz x 0.5 ms = 0.06 rad per step) and 32 simulated motors cheap.
    """

    def __init__(self, params: PlantParams | None = None, *, now_s: float = 0.0, max_step_s: float = 5e-4):
        if not max_step_s > 0:
            raise ValueError(f"max_step_s={max_step_s!r} must be > 0")
        if not math.isfinite(now_s):
            raise ValueError(f"now_s={now_s!r} must be finite")
        self.params = params or PlantParams()
        self._control: Control = Off()
        self._load = 0.0  # N·m, a load the test or user applies to the shaft
        self._accel = self.params.max_acceleration_dps2
        self._max_step = max_step_s
        self._anchor = now_s  # the grid's origin: the last change
        self._steps = 0  # whole steps committed since the anchor
        self._committed = _State(self.params.ambient_c)  # at anchor + steps * max_step
        self._resting = True  # the committed state is at rest: no more steps, only cooling
        self._now = now_s
        self._obs = _State(self.params.ambient_c)  # the state at _now

    def grid(self) -> PlantGrid:
        """The whole state, grid included (for a copy that goes on exactly as this plant would)."""
        return PlantGrid(
            control=self._control,
            acceleration_dps2=self._accel,
            external_torque_nm=self._load,
            max_step_s=self._max_step,
            anchor_s=self._anchor,
            steps=self._steps,
            resting=self._resting,
            committed=tuple(getattr(self._committed, name) for name in STATE_FIELDS),
            now_s=self._now,
            now=tuple(getattr(self._obs, name) for name in STATE_FIELDS),
        )

    @classmethod
    def from_grid(cls, params: PlantParams, grid: PlantGrid) -> Plant:
        """A plant with ``grid``'s whole state: it goes on exactly as the one :meth:`grid` was read from."""
        plant = cls(params, now_s=grid.anchor_s, max_step_s=grid.max_step_s)
        plant.restore(grid)
        return plant

    def restore(self, grid: PlantGrid) -> None:
        """Take ``grid``'s whole state (the params stay this plant's own)."""
        self._control = grid.control
        self._accel = grid.acceleration_dps2
        self._load = grid.external_torque_nm
        self._max_step = grid.max_step_s
        self._anchor = grid.anchor_s
        self._steps = grid.steps
        self._resting = grid.resting
        self._now = grid.now_s
        for name, committed, now in zip(STATE_FIELDS, grid.committed, grid.now, strict=True):
            setattr(self._committed, name, committed)
            setattr(self._obs, name, now)

    # ---- what the device model reads (the state at now_s) ----

    @property
    def now_s(self) -> float:
        return self._now

    @property
    def control(self) -> Control:
        """What the drive is asked to do (change it with :meth:`set_control`)."""
        return self._control

    @property
    def position_deg(self) -> float:
        return self._obs.position_deg

    @position_deg.setter
    def position_deg(self, value: float) -> None:
        self._write("position_deg", value)

    @property
    def speed_dps(self) -> float:
        return self._obs.speed_dps

    @speed_dps.setter
    def speed_dps(self, value: float) -> None:
        self._write("speed_dps", value)

    @property
    def current_a(self) -> float:
        return self._obs.current_a

    @current_a.setter
    def current_a(self, value: float) -> None:
        self._write("current_a", value)

    @property
    def temperature_c(self) -> float:
        return self._obs.temperature_c

    @temperature_c.setter
    def temperature_c(self, value: float) -> None:
        self._write("temperature_c", value)

    @property
    def external_torque_nm(self) -> float:
        """A load applied to the shaft (tests, users)."""
        return self._load

    @external_torque_nm.setter
    def external_torque_nm(self, value: float) -> None:
        self._commit()
        self._load = value

    @property
    def acceleration_dps2(self) -> float:
        """Slew limit of the speed reference (``math.inf``: limited by the current only)."""
        return self._accel

    @acceleration_dps2.setter
    def acceleration_dps2(self, value: float) -> None:
        self._commit()
        self._accel = value

    @property
    def torque_nm(self) -> float:
        return self._obs.current_a * self.params.torque_constant_nm_per_a

    @property
    def voltage_v(self) -> float:
        return self.params.supply_v - abs(self._obs.current_a) * self.params.supply_resistance_ohm

    @property
    def motor_position_deg(self) -> float:
        """Rotor angle (before the gear), what a motor-side encoder counts."""
        return self._obs.position_deg * self.params.gear_ratio

    @property
    def resting(self) -> bool:
        """Unpowered, still and at ambient temperature: :meth:`advance` only moves its clock."""
        obs = self._obs
        return self._at_rest(obs) and obs.speed_dps == 0.0 and obs.temperature_c == self.params.ambient_c

    # ---- changes ----

    def set_control(self, control: Control) -> None:
        self._commit()
        if type(control) is not type(self._control):
            state = self._committed  # a new mode starts its loops fresh, from the present speed
            state.speed_integral = 0.0
            state.speed_ref = state.speed_dps
            self._obs.copy_from(state)
        self._control = control
        self._resting = self._at_rest(self._committed)

    def advance(self, now_s: float) -> None:
        """Integrate up to ``now_s`` (no-op if it is not later than the plant's time).

        Raises:
            ValueError: ``now_s`` is infinite (the grid would never get there).
        """
        if not now_s > self._now:
            return
        if now_s == math.inf:
            raise ValueError("now_s=inf: a plant cannot advance to infinity")
        self._now = now_s
        state = self._committed
        if self._resting:
            if state.speed_dps == 0.0 and state.temperature_c == self.params.ambient_c:
                return  # still and at ambient: the observed state is the committed one, as it was
        else:
            anchor, step, steps = self._anchor, self._max_step, self._steps
            while anchor + (steps + 1) * step <= now_s:
                self._step(state, step)
                steps += 1
                if self._at_rest(state):
                    self._resting = True
                    break
            self._steps = steps
        obs = self._obs
        obs.copy_from(state)
        dt = now_s - (self._anchor + self._steps * self._max_step)
        if dt > 1e-12:
            if self._resting:
                if obs.temperature_c != self.params.ambient_c or obs.speed_dps != 0.0:
                    self._cool(obs, dt)  # (at ambient and still, cooling would change nothing)
            else:
                self._step(obs, dt)

    def _commit(self) -> None:
        """Make the state at now_s the committed one and start a new grid there."""
        self._committed.copy_from(self._obs)
        self._anchor = self._now
        self._steps = 0

    def _write(self, name: str, value: float) -> None:
        self._commit()
        setattr(self._committed, name, value)
        self._obs.copy_from(self._committed)
        self._resting = self._at_rest(self._committed)

    # ---- dynamics (csrc/sim_plant.c: the same operations in the same order) ----

    def _at_rest(self, s: _State) -> bool:
        unpowered = isinstance(self._control, Off | Brake) and s.current_a == 0.0
        return unpowered and (s.speed_dps == 0.0 or isinstance(self._control, Brake))

    def _cool(self, s: _State, dt: float) -> None:
        p = self.params
        tau = p.thermal_resistance_c_per_w * p.thermal_capacity_j_per_c
        s.temperature_c = p.ambient_c + (s.temperature_c - p.ambient_c) * math.exp(-dt / tau)
        if isinstance(self._control, Brake):
            s.speed_dps = 0.0

    def _current_command(self, s: _State, dt: float) -> float:
        p = self.params
        control = self._control
        if isinstance(control, Off | Brake):
            return 0.0
        if isinstance(control, CurrentControl):
            return _clamp(control.current_a, p.max_current_a)
        if isinstance(control, Impedance):
            error = control.position_rad - s.position_deg * _RAD_PER_DEG
            speed_error = control.velocity_rad_s - s.speed_dps * _RAD_PER_DEG
            torque = control.kp * error + control.kd * speed_error + control.torque_ff_nm
            return _clamp(torque / p.torque_constant_nm_per_a, p.max_current_a)
        if isinstance(control, PositionControl):
            # a limit of 0 means "do not move" (hollow V = 0), not "no limit"
            limit = (
                p.max_speed_dps
                if control.max_speed_dps is None
                else min(control.max_speed_dps, p.max_speed_dps)
            )
            error = control.position_deg - s.position_deg
            wanted = 2 * math.pi * p.position_bandwidth_hz * error
            # never ask for more speed than the acceleration limit can brake to zero within the error:
            # v = sqrt(2·a·|e|), or long fast moves overshoot and ring
            limit = min(limit, math.sqrt(2 * self._accel * abs(error)))
            return self._speed_loop(s, _clamp(wanted, limit), control.max_current_a, dt)
        return self._speed_loop(s, _clamp(control.speed_dps, p.speed_limit_dps), control.max_current_a, dt)

    def _speed_loop(self, s: _State, target_dps: float, max_current_a: float | None, dt: float) -> float:
        p = self.params
        limit = min(max_current_a, p.max_current_a) if max_current_a is not None else p.max_current_a
        step = _clamp(target_dps - s.speed_ref, self._accel * dt)
        s.speed_ref += step
        # inertia feed-forward of the reference's acceleration: the loop follows ramps without lag
        feed_forward = p.inertia_kgm2 * step / dt * _RAD_PER_DEG / p.torque_constant_nm_per_a
        omega = 2 * math.pi * p.speed_bandwidth_hz
        gain = p.inertia_kgm2 * omega / p.torque_constant_nm_per_a  # A per rad/s: closes at the bandwidth
        error = (s.speed_ref - s.speed_dps) * _RAD_PER_DEG
        command = gain * error + s.speed_integral + feed_forward
        if abs(command) < limit:  # anti-windup: integrate only while not saturated
            s.speed_integral += gain * (omega / 4) * error * dt
        return _clamp(command, limit)

    def _step(self, s: _State, dt: float) -> None:
        p = self.params
        command = self._current_command(s, dt)
        s.current_a += (command - s.current_a) * min(1.0, dt / p.current_time_constant_s)
        if command == 0.0 and abs(s.current_a) < 1e-6:
            s.current_a = 0.0  # settled: lets an unpowered motor reach the at-rest fast path
        if isinstance(self._control, Brake):
            s.speed_dps = 0.0
        else:
            speed_rad = s.speed_dps * _RAD_PER_DEG
            torque = (
                s.current_a * p.torque_constant_nm_per_a
                + self._load
                - p.viscous_friction_nm_s_per_rad * speed_rad
            )
            speed_rad += torque / p.inertia_kgm2 * dt
            s.speed_dps = speed_rad / _RAD_PER_DEG
            if s.current_a == 0.0 and self._load == 0.0 and abs(s.speed_dps) < 1e-6:
                s.speed_dps = 0.0  # friction has stopped it (the exponential tail never would)
        s.position_deg += s.speed_dps * dt  # semi-implicit: integrates the speed just reported
        heat_w = s.current_a * s.current_a * p.winding_resistance_ohm  # x*x, not x**2: C's pow may differ
        cooling_w = (s.temperature_c - p.ambient_c) / p.thermal_resistance_c_per_w
        s.temperature_c += (heat_w - cooling_w) / p.thermal_capacity_j_per_c * dt


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))

"""The mechanical and thermal plant behind a simulated motor, apart from any protocol.

A rigid output shaft with inertia and viscous friction, driven by a current-controlled motor
through a gear; the closed-loop modes the manuals describe (current, speed, position, MIT
impedance) are cascaded loops around it with the motor's limits; the winding heats with I²R and
cools towards ambient. Everything is given at the **output shaft** (after the gear), as the
manuals report angles and speeds; ``gear_ratio`` only converts to motor-side values (encoders).

Sans-IO: :meth:`Plant.advance` takes the simulated time, integrates in fixed sub-steps
(semi-implicit Euler, so the reported position is exactly the integral of the reported speed), and
never reads a clock. Device models own a Plant and set its :class:`Control`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "Brake",
    "Control",
    "CurrentControl",
    "Impedance",
    "Off",
    "Plant",
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


# ---- what the drive is asked to do (set by the device model from decoded commands) ----


@dataclass(frozen=True, slots=True)
class Off:
    """Output off: no current, the shaft coasts (0x80 motor off, hollow stop)."""


@dataclass(frozen=True, slots=True)
class Brake:
    """Holding brake engaged: the shaft does not move."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CurrentControl:
    current_a: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedControl:
    speed_dps: float
    max_current_a: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionControl:
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


class Plant:
    """State and dynamics of one actuator; the device model reads it to fill its replies.

    Args:
        params: physical constants.
        now_s: simulated time of creation.
        max_step_s: integration sub-step. 500 µs keeps the default loops well inside stability
            (speed loop: 2π·20 Hz x 0.5 ms = 0.06 rad per step) and 32 simulated motors cheap.
    """

    def __init__(self, params: PlantParams | None = None, *, now_s: float = 0.0, max_step_s: float = 5e-4):
        self.params = params or PlantParams()
        self.control: Control = Off()
        self.position_deg = 0.0
        self.speed_dps = 0.0
        self.current_a = 0.0
        self.temperature_c = self.params.ambient_c
        self.external_torque_nm = 0.0  # a load the test or user applies to the shaft
        self._now = now_s
        self._max_step = max_step_s
        self.acceleration_dps2 = self.params.max_acceleration_dps2
        self._speed_integral = 0.0  # A, the speed loop's integral term
        self._speed_ref = 0.0  # dps, the slew-limited reference the speed loop follows

    @property
    def now_s(self) -> float:
        return self._now

    @property
    def torque_nm(self) -> float:
        return self.current_a * self.params.torque_constant_nm_per_a

    @property
    def voltage_v(self) -> float:
        return self.params.supply_v - abs(self.current_a) * self.params.supply_resistance_ohm

    @property
    def motor_position_deg(self) -> float:
        """Rotor angle (before the gear), what a motor-side encoder counts."""
        return self.position_deg * self.params.gear_ratio

    @property
    def resting(self) -> bool:
        """Unpowered, still and at ambient temperature: :meth:`advance` only moves its clock.

        Until its control changes such a plant reaches the same state however its time is cut into
        steps, so a device may advance it over many frames at once.
        """
        return self._at_rest() and self.speed_dps == 0.0 and self.temperature_c == self.params.ambient_c

    def set_control(self, control: Control) -> None:
        if type(control) is not type(self.control):
            self._speed_integral = 0.0  # a new mode starts its loops fresh, from the present speed
            self._speed_ref = self.speed_dps
        self.control = control

    def advance(self, now_s: float) -> None:
        """Integrate up to ``now_s`` (no-op if it is not later than the plant's time)."""
        remaining = now_s - self._now
        if remaining <= 0:
            return
        if self._at_rest():
            if self.temperature_c != self.params.ambient_c or self.speed_dps != 0.0:
                self._cool(remaining)  # idle motors cost one step however long they idle
            self._now = now_s  # (and nothing at all once cooled to ambient: the step would change nothing)
            return
        while remaining > 1e-12:
            dt = min(self._max_step, remaining)
            self._step(dt)
            remaining -= dt
        self._now = now_s

    # ---- dynamics ----

    def _at_rest(self) -> bool:
        unpowered = isinstance(self.control, Off | Brake) and self.current_a == 0.0
        return unpowered and (self.speed_dps == 0.0 or isinstance(self.control, Brake))

    def _cool(self, dt: float) -> None:
        p = self.params
        tau = p.thermal_resistance_c_per_w * p.thermal_capacity_j_per_c
        self.temperature_c = p.ambient_c + (self.temperature_c - p.ambient_c) * math.exp(-dt / tau)
        if isinstance(self.control, Brake):
            self.speed_dps = 0.0

    def _current_command(self, dt: float) -> float:
        p = self.params
        control = self.control
        if isinstance(control, Off | Brake):
            return 0.0
        if isinstance(control, CurrentControl):
            return _clamp(control.current_a, p.max_current_a)
        if isinstance(control, Impedance):
            error = control.position_rad - self.position_deg * _RAD_PER_DEG
            speed_error = control.velocity_rad_s - self.speed_dps * _RAD_PER_DEG
            torque = control.kp * error + control.kd * speed_error + control.torque_ff_nm
            return _clamp(torque / p.torque_constant_nm_per_a, p.max_current_a)
        if isinstance(control, PositionControl):
            # a limit of 0 means "do not move" (hollow V = 0), not "no limit"
            limit = (
                p.max_speed_dps
                if control.max_speed_dps is None
                else min(control.max_speed_dps, p.max_speed_dps)
            )
            error = control.position_deg - self.position_deg
            wanted = 2 * math.pi * p.position_bandwidth_hz * error
            # never ask for more speed than the acceleration limit can brake to zero within the error:
            # v = sqrt(2·a·|e|), or long fast moves overshoot and ring
            limit = min(limit, math.sqrt(2 * self.acceleration_dps2 * abs(error)))
            return self._speed_loop(_clamp(wanted, limit), control.max_current_a, dt)
        return self._speed_loop(control.speed_dps, control.max_current_a, dt)

    def _speed_loop(self, target_dps: float, max_current_a: float | None, dt: float) -> float:
        p = self.params
        limit = min(max_current_a, p.max_current_a) if max_current_a is not None else p.max_current_a
        step = _clamp(target_dps - self._speed_ref, self.acceleration_dps2 * dt)
        self._speed_ref += step
        # inertia feed-forward of the reference's acceleration: the loop follows ramps without lag
        feed_forward = p.inertia_kgm2 * step / dt * _RAD_PER_DEG / p.torque_constant_nm_per_a
        omega = 2 * math.pi * p.speed_bandwidth_hz
        gain = p.inertia_kgm2 * omega / p.torque_constant_nm_per_a  # A per rad/s: closes at the bandwidth
        error = (self._speed_ref - self.speed_dps) * _RAD_PER_DEG
        command = gain * error + self._speed_integral + feed_forward
        if abs(command) < limit:  # anti-windup: integrate only while not saturated
            self._speed_integral += gain * (omega / 4) * error * dt
        return _clamp(command, limit)

    def _step(self, dt: float) -> None:
        p = self.params
        command = self._current_command(dt)
        self.current_a += (command - self.current_a) * min(1.0, dt / p.current_time_constant_s)
        if command == 0.0 and abs(self.current_a) < 1e-6:
            self.current_a = 0.0  # settled: lets an unpowered motor reach the at-rest fast path
        if isinstance(self.control, Brake):
            self.speed_dps = 0.0
        else:
            speed_rad = self.speed_dps * _RAD_PER_DEG
            torque = self.torque_nm + self.external_torque_nm - p.viscous_friction_nm_s_per_rad * speed_rad
            speed_rad += torque / p.inertia_kgm2 * dt
            self.speed_dps = speed_rad / _RAD_PER_DEG
            if self.current_a == 0.0 and self.external_torque_nm == 0.0 and abs(self.speed_dps) < 1e-6:
                self.speed_dps = 0.0  # friction has stopped it (the exponential tail never would)
        self.position_deg += self.speed_dps * dt  # semi-implicit: integrates the speed just reported
        heat_w = self.current_a**2 * p.winding_resistance_ohm
        cooling_w = (self.temperature_c - p.ambient_c) / p.thermal_resistance_c_per_w
        self.temperature_c += (heat_w - cooling_w) / p.thermal_capacity_j_per_c * dt


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))

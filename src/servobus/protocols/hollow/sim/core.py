"""The hollow motor's C twin: what :class:`~servobus.protocols.hollow.sim.device.HollowMotor` shares
with the C core's hot path (csrc/sim_hollow.c) when a C network attaches it.

C handles the set-point frames (normal, extended, CAN FD) and their replies; the special commands,
the extended-id frames and everything while the model's guards say no stay in the Python model,
which is the reference. While attached, the motor's RAM state (enabled, CAN mode, control mode,
held setpoint, zero) lives in the C struct ``sb_hollow_state`` only: :class:`HollowCore`'s
properties read and write it there, so neither side ever works on a stale copy. Not attached, the
properties are plain attributes and the model behaves exactly as without C.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from servobus.core._lib import ffi, lib
from servobus.protocols.hollow import CanMode, ControlMode, HollowModel
from servobus.sim.device import BusLink, ListeningDevice
from servobus.sim.power import PowerCuts

if TYPE_CHECKING:
    from servobus.sim.coreplant import CorePlant

__all__ = ["COUNTER_KEYS", "HeldSetpoint", "HollowCore"]

# The model's counters C moves, indexed as csrc/sim_hollow.h's SB_HOLLOW_* (sb_simmotor.counters).
COUNTER_KEYS = (
    "received",
    "ignored_id",
    "ignored_kind",
    "undecodable",
    "accepted",
    "replied",
    "zero_refused",
)


@dataclass(frozen=True, slots=True, kw_only=True)
class HeldSetpoint:
    """The motor's last setpoint, in the plant's units (one form for normal, extended and FD frames).

    Attributes:
        target_deg: position target from the mechanical zero: absolute (normal mode, CAN FD, A29)
            or the sum of the increments (extended mode, A11).
        speed_dps: V / Vel: target speed (speed mode) or speed limit (position mode).
        current_a: T / Cur: target current (torque mode) or current limit (speed, position).
        kp, kd: the position gains as received (CAN 0..4095, CAN FD 0..255, A16).
    """

    target_deg: float
    speed_dps: float
    current_a: float
    kp: int
    kd: int


class HollowCore(PowerCuts):
    """The C-twin half of :class:`~servobus.protocols.hollow.sim.device.HollowMotor` (the engine's
    contract: ``CORE_FAMILY``, :meth:`core_attach`, :meth:`core_detach`, :meth:`core_push`)."""

    CORE_FAMILY: ClassVar[int] = lib.SB_FAMILY_HOLLOW

    # The C twin (cdata sb_simmotor *) and its sb_hollow_state, while attached.
    _core: Any = None
    _core_state: Any = None
    # The RAM state while not attached.
    _py_enabled = False
    _py_can_mode = CanMode.NORMAL
    _py_ctrl_mode = ControlMode.POSITION
    _py_setpoint: HeldSetpoint | None = None
    _py_zero_offset_deg = 0.0
    _py_unresponsive = False

    def __init__(
        self,
        *,
        motor_id: int,
        host_id: int,
        model: HollowModel,
        fd_enabled: bool,
        turnaround_s: float,
        turnaround_jitter_s: float,
        fd_current_a_per_count: float,
    ) -> None:
        """The configuration the C twin reads (checked by the motor, which passes it on)."""
        self.motor_id = motor_id
        self.host_id = host_id
        self.model = model
        self.fd_enabled = fd_enabled
        self.turnaround_s = turnaround_s
        self.turnaround_jitter_s = turnaround_jitter_s
        self.fd_current_a_per_count = fd_current_a_per_count

    # ---- the engine's contract ----

    def core_attach(self, motor: Any, link: BusLink | None) -> None:
        """Take ``motor`` (cdata ``sb_simmotor *``, zeroed, the network's) as this motor's C twin.

        The plant moves into ``motor.plant`` and the RAM state into its ``sb_hollow_state``; from
        now on both are read there. ``link`` is the network's account (as :meth:`attach`).

        Raises:
            ValueError: the motor is already on a network or has a C twin.
        """
        from servobus.sim.coreplant import CorePlant  # here: only a C network needs it

        if self._core is not None or (link is not None and self._link is not None):
            raise ValueError(f"{self!r} is already on a network: remove it from that one first")
        self.settle()
        ram = (self.enabled, self.can_mode, self.ctrl_mode, self.setpoint, self.zero_offset_deg)
        motor.family = lib.SB_FAMILY_HOLLOW
        self._core = motor
        self._core_state = ffi.cast("sb_hollow_state *", motor.state)
        self.enabled, self.can_mode, self.ctrl_mode, self.setpoint, self.zero_offset_deg = ram
        self._plant = CorePlant.adopt(self._plant, ffi.addressof(motor, "plant"), motor)
        self._link = link
        self.core_push()

    def core_detach(self) -> None:
        """Leave the C twin and the network: take what C changed, copy the plant and the RAM state back."""
        if self._core is None:
            self.attach(None)
            return
        self.settle()
        ram = (self.enabled, self.can_mode, self.ctrl_mode, self.setpoint, self.zero_offset_deg)
        plant: CorePlant = self._plant  # type: ignore[assignment]
        self._plant = plant.to_python()
        self._core = self._core_state = None
        self._link = None
        self.enabled, self.can_mode, self.ctrl_mode, self.setpoint, self.zero_offset_deg = ram

    def core_push(self) -> None:
        """Write into the C twin everything its hot path reads, and whether it may act now."""
        motor, state = self._core, self._core_state
        if motor is None:
            return
        model = self.model
        state.position_full_scale_deg = model.position_full_scale_deg
        state.speed_full_scale_rad_s = model.speed_full_scale_rad_s
        state.current_full_scale_a = model.current_full_scale_a
        state.fd_velocity_counts_per_rpm = model.fd_velocity_counts_per_rpm
        state.fd_current_a_per_count = self.fd_current_a_per_count
        state.motor_id = self.motor_id
        state.host_id = self.host_id
        state.fd_enabled = self.fd_enabled
        motor.turnaround_s = self.turnaround_s
        motor.listen_all = 0
        motor.n_listen = 1
        motor.listen[0] = self.motor_id
        # The guards: an unresponsive or unpowered motor and jittered turnarounds (Python's random) are
        # the model's.
        motor.hot = (
            not self._py_unresponsive and self.turnaround_jitter_s == 0.0 and self.power_back_s is None
        )
        motor.py_deadline_s = math.inf  # the model has no deadlines of its own

    def settle(self) -> None:
        """Settle up with the network, then take the counters C moved."""
        link = self._link
        if link is not None and link.behind:
            ListeningDevice.settle(self)
        motor = self._core
        if motor is None:
            return
        counts = motor.counters
        counters = self._counters
        for index, key in enumerate(COUNTER_KEYS):
            delta = counts[index]
            if delta:
                counters[key] += delta
                counts[index] = 0

    # ---- the RAM state: in C while attached ----

    @property
    def enabled(self) -> bool:
        """Started (FC / Run Cmd 1) and not stopped since."""
        state = self._core_state
        return self._py_enabled if state is None else bool(state.enabled)

    @enabled.setter
    def enabled(self, value: bool) -> None:
        state = self._core_state
        if state is None:
            self._py_enabled = value
        else:
            state.enabled = bool(value)

    @property
    def can_mode(self) -> CanMode:
        """Normal (absolute) or extended (incremental) classic-CAN mode (§5.1)."""
        state = self._core_state
        return self._py_can_mode if state is None else CanMode(state.can_mode)

    @can_mode.setter
    def can_mode(self, value: CanMode) -> None:
        state = self._core_state
        if state is None:
            self._py_can_mode = value
        else:
            state.can_mode = CanMode(value)

    @property
    def ctrl_mode(self) -> ControlMode:
        """The control mode (§2.3, §4.1)."""
        state = self._core_state
        return self._py_ctrl_mode if state is None else ControlMode(state.ctrl_mode)

    @ctrl_mode.setter
    def ctrl_mode(self, value: ControlMode) -> None:
        state = self._core_state
        if state is None:
            self._py_ctrl_mode = value
        else:
            state.ctrl_mode = ControlMode(value)

    @property
    def setpoint(self) -> HeldSetpoint | None:
        """The last setpoint, in the plant's units (None: none since power-up)."""
        state = self._core_state
        if state is None:
            return self._py_setpoint
        if not state.has_setpoint:
            return None
        return HeldSetpoint(
            target_deg=state.target_deg,
            speed_dps=state.speed_dps,
            current_a=state.current_a,
            kp=state.kp,
            kd=state.kd,
        )

    @setpoint.setter
    def setpoint(self, value: HeldSetpoint | None) -> None:
        state = self._core_state
        if state is None:
            self._py_setpoint = value
        elif value is None:
            state.has_setpoint = 0
        else:
            state.target_deg = value.target_deg
            state.speed_dps = value.speed_dps
            state.current_a = value.current_a
            state.kp = value.kp
            state.kd = value.kd
            state.has_setpoint = 1

    @property
    def zero_offset_deg(self) -> float:
        """The plant angle of the mechanical zero."""
        state = self._core_state
        return self._py_zero_offset_deg if state is None else float(state.zero_offset_deg)

    @zero_offset_deg.setter
    def zero_offset_deg(self, value: float) -> None:
        state = self._core_state
        if state is None:
            self._py_zero_offset_deg = value
        else:
            state.zero_offset_deg = value

    @property
    def unresponsive(self) -> bool:
        """A fault knob of the simulator: the motor applies requests but never answers."""
        return self._py_unresponsive

    @unresponsive.setter
    def unresponsive(self, value: bool) -> None:
        self._py_unresponsive = value
        self.core_push()  # C must not answer for it from now on (or may again)

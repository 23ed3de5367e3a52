"""An :class:`~servobus.protocols.lk.sim.device.LkMotor`'s C twin: what it pushes into its
``sb_simmotor`` and pulls back (the engine/model contract of issue 27; csrc/sim_lk.h).

csrc/sim_lk.c answers LK's control-loop traffic (status reads, motor off/stop/run, set-points, the
0x280 frame) as the Python model does, byte for byte; everything else is handed to the model. The
model stays the owner of its state: :meth:`LkCore.push` writes what C reads (model, limits, run
state, held command, angle frame, knobs) and whether C may act at all (``hot``: no latched error);
:meth:`LkCore.pull` takes back what C changed (counters, run state, held command, the multi-turn
origin) before Python reads any of it.
"""

from __future__ import annotations

import math
from typing import Any, Protocol, cast

from servobus.core._lib import ffi, lib
from servobus.protocols.lk.model import IQ_AMPS_PER_COUNT, LkModel, MotorType, Revision
from servobus.protocols.lk.sim.state import AngleFrame, LkMemory, RunState
from servobus.sim.coreplant import CorePlant
from servobus.sim.plant import Brake, Control, CurrentControl, Off, Plant, PositionControl, SpeedControl

__all__ = [
    "CORE_FAMILY",
    "COUNTER_NAMES",
    "LkCore",
    "LkTwinned",
    "adopt_plant",
    "control_from_c",
    "control_to_c",
    "release_plant",
]

CORE_FAMILY: int = lib.SB_FAMILY_LK

#: The model's counter keys by their index in ``sb_simmotor.counters`` (csrc/sim_lk.h SB_LK_N_*).
COUNTER_NAMES: tuple[str, ...] = (
    "received",
    "accepted",
    "replied",
    "unanswered",
    "ignored_id",
    "ignored_kind",
    "other_revision",
    "busy",
    "not_executed_off",
    "not_implemented",
)
assert [getattr(lib, f"SB_LK_N_{name.upper()}") for name in COUNTER_NAMES] == list(range(lib.SB_LK_N_COUNT))

_REVISIONS = {Revision.V2_36: lib.SB_LK_V2_36, Revision.V2_35: lib.SB_LK_V2_35}
_MOTOR_TYPES = {
    MotorType.MS: lib.SB_LK_MS,
    MotorType.MF: lib.SB_LK_MF,
    MotorType.MH: lib.SB_LK_MH,
    MotorType.MG: lib.SB_LK_MG,
}
_RUN_STATES = ("on", "stopped", "off")  # RunState values by SB_LK_ON, SB_LK_STOPPED, SB_LK_OFF
_REQUEST_BASE, _MULTI_MOTOR_ID = 0x140, 0x280


def _none_nan(value: float | None) -> float:
    return math.nan if value is None else value


def _nan_none(value: float) -> float | None:
    return None if math.isnan(value) else value


def control_to_c(control: Control, out: Any) -> None:
    """Write ``control`` into an ``sb_control`` (None limits as NaN, as csrc/sim_plant.h says)."""
    out.b = out.c = out.d = out.e = 0.0
    if isinstance(control, CurrentControl):
        out.mode, out.a = lib.SB_CONTROL_CURRENT, control.current_a
    elif isinstance(control, SpeedControl):
        out.mode, out.a, out.b = lib.SB_CONTROL_SPEED, control.speed_dps, _none_nan(control.max_current_a)
    elif isinstance(control, PositionControl):
        out.mode, out.a = lib.SB_CONTROL_POSITION, control.position_deg
        out.b, out.c = _none_nan(control.max_speed_dps), _none_nan(control.max_current_a)
    elif isinstance(control, Brake):
        out.mode, out.a = lib.SB_CONTROL_BRAKE, 0.0
    elif isinstance(control, Off):
        out.mode, out.a = lib.SB_CONTROL_OFF, 0.0
    else:  # pragma: no cover - an LK motor holds only the controls above
        raise TypeError(f"an LK motor cannot hold {control!r}")


def control_from_c(c: Any) -> Control:
    """The Python control an ``sb_control`` that C wrote stands for."""
    mode = c.mode
    if mode == lib.SB_CONTROL_CURRENT:
        return CurrentControl(current_a=c.a)
    if mode == lib.SB_CONTROL_SPEED:
        return SpeedControl(speed_dps=c.a, max_current_a=_nan_none(c.b))
    if mode == lib.SB_CONTROL_POSITION:
        return PositionControl(position_deg=c.a, max_speed_dps=_nan_none(c.b), max_current_a=_nan_none(c.c))
    if mode == lib.SB_CONTROL_BRAKE:
        return Brake()
    return Off()


class LkTwinned(Protocol):
    """What the C twin reads of the model and hands back to it (LkMotor is one)."""

    model: LkModel
    memory: LkMemory
    motor_id: int
    brake_engaged: bool
    busy_until_s: float
    latched_errors: int
    power_back_s: float | None

    @property
    def angles(self) -> AngleFrame: ...
    @property
    def amps_per_count(self) -> float: ...
    @property
    def unresponsive(self) -> bool: ...
    @property
    def turnaround_s(self) -> float: ...
    @property
    def state(self) -> RunState: ...
    @property
    def held(self) -> Control | None: ...
    def tally(self, kind: str, n: int = 1) -> None: ...
    def take_from_twin(self, state: RunState, held: Control | None, angle_origin: int) -> None: ...


class LkCore:
    """One motor's ``sb_simmotor`` (cdata, owned by the network or the test) and the copying.

    Args:
        device: the model; its plant has already moved into ``motor.plant``.
        motor: the zeroed ``sb_simmotor *`` the network gave it.
    """

    __slots__ = ("_device", "_run_states", "motor", "state")

    def __init__(self, device: LkTwinned, motor: Any) -> None:
        self._device = device
        self._run_states = tuple(RunState(value) for value in _RUN_STATES)
        self.motor = motor
        self.state = ffi.cast("sb_lk_state *", motor.state)
        motor.family = CORE_FAMILY
        motor.listen_all = 0

    def push(self) -> None:
        """Write everything C reads; ``hot`` says whether C may act (no latched error, powered)."""
        self.pull()  # C's changes first, or the model's stale copy would overwrite them
        device, motor, s = self._device, self.motor, self.state
        model = device.model
        s.revision = _REVISIONS[model.revision]
        s.motor_type = _MOTOR_TYPES[model.motor_type]
        s.motor_id = device.motor_id
        angles = device.angles
        s.per_turn = angles.per_turn
        s.amps_per_count = device.amps_per_count
        iq_amps = IQ_AMPS_PER_COUNT.get(model.motor_type)
        s.iq_counts_per_amp = 0.0 if iq_amps is None else 1 / iq_amps  # as model.iq_field divides
        limits = device.memory.limits()
        s.torque_counts = limits.torque_counts
        s.speed_limit_dps = limits.speed_dps
        s.angle_lo_deg, s.angle_hi_deg = limits.angle_deg
        s.brake_engaged = device.brake_engaged
        s.unresponsive = device.unresponsive
        s.busy_until_s = device.busy_until_s
        s.run_state = self._run_states.index(device.state)
        held = device.held
        s.has_held = held is not None
        if held is not None:
            control_to_c(held, s.held)
        s.angle_offset = angles.offset
        s.angle_origin = angles.origin
        s.pending = 0
        motor.turnaround_s = device.turnaround_s
        motor.listen[0] = _REQUEST_BASE + device.motor_id
        motor.listen[1] = _MULTI_MOTOR_ID
        motor.n_listen = 2
        motor.py_deadline_s = math.inf  # the model has no deadlines of its own
        motor.hot = not device.latched_errors and device.power_back_s is None

    def pull(self) -> None:
        """Take what C changed since the last pull (nothing to do unless it acted)."""
        s = self.state
        if not s.pending:
            return
        s.pending = 0
        device, counts = self._device, self.motor.counters
        for i, name in enumerate(COUNTER_NAMES):
            n = counts[i]
            if n:
                device.tally(name, n)
                counts[i] = 0
        held = control_from_c(s.held) if s.has_held else None
        device.take_from_twin(self._run_states[s.run_state], held, s.angle_origin)


def adopt_plant(plant: Plant, motor: Any) -> Plant:
    """The plant moved into ``motor.plant``: the same API, its state in C from now on."""
    # CorePlant has Plant's API (duck-typed): the model keeps reading it as its Plant.
    return cast(Plant, CorePlant.adopt(plant, ffi.addressof(motor, "plant"), motor))


def release_plant(plant: Plant) -> Plant:
    """A Python :class:`Plant` with the state of ``plant`` (a CorePlant leaving its C twin)."""
    return plant.to_python() if isinstance(plant, CorePlant) else plant

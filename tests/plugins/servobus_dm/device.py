"""The simulated DM-J motor on a CAN bus: requests in, timed feedback out (sans-IO).

The motor decodes requests with the family's own codec (scaled by its model), acts on a
:class:`~servobus.sim.plant.Plant` and answers ``turnaround_s`` later. Each command class is handled
by the method named after it (``MitControl`` -> ``_on_mit_control``).

As the drive does: a MIT set-point moves the shaft only while the motor is enabled (the MIT law is
the plant's :class:`~servobus.sim.plant.Impedance`); disabled, or with an error latched, it is
answered and not acted on (``refused_disabled``, ``refused_fault``). The zero is taken only while
disabled (``refused_zero``). Frames it does not act on count in :attr:`DmMotor.counters`:
``ignored_id``, ``ignored_kind`` (extended or CAN FD), ``undecodable``, ``not_mine`` (a refresh of
another motor).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any

from servobus.authoring import (
    Emission,
    Frame,
    Impedance,
    ListeningDevice,
    Off,
    Plant,
    PlantParams,
    ProtocolError,
    method_name,
)
from servobus_dm.codec import COMMANDS, REFRESH_ID, decode_request, feedback_id, request_id
from servobus_dm.messages import (
    ClearError,
    Disable,
    DmCommand,
    DmState,
    Enable,
    Feedback,
    MitControl,
    RefreshState,
    SaveZero,
)
from servobus_dm.models import DEFAULT_MODEL, DmModel

__all__ = ["DEFAULT_TURNAROUND_S", "DmMotor", "plant_params"]

DEFAULT_TURNAROUND_S = 200e-6


def plant_params(model: DmModel) -> PlantParams:
    """A direct-drive joint of ``model``: 1 N·m per ampere, so the current limit is its T_MAX."""
    return PlantParams(
        inertia_kgm2=0.002,
        torque_constant_nm_per_a=1.0,
        gear_ratio=1.0,
        max_current_a=model.t_max,
        max_speed_dps=math.degrees(model.v_max),
    )


class DmMotor(ListeningDevice):
    """One DM-J motor (a :class:`~servobus.sim.device.Listener`).

    Args:
        motor_id: 1..15: commands on ID (and refreshes on 0x7FF), feedback on ID + 0x10.
        model: the model whose ranges its frames are scaled by.
        turnaround_s: request received -> feedback ready.
        name: the device's name on its bus (default ``dm<id>``).
        now_s: simulated time of power-up.

    Attributes:
        enabled: the MIT law is driven (:class:`Enable`; :class:`Disable` ends it).
        error: the error latched (:meth:`inject_fault`; :class:`ClearError` clears it), or None.
        counters: frames by fate (see the module docstring), and ``replied``, ``zeroed``.

    Raises:
        ValueError: ``motor_id`` outside 1..15 or a negative time.
    """

    def __init__(
        self,
        motor_id: int,
        *,
        model: DmModel = DEFAULT_MODEL,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        name: str | None = None,
        now_s: float = 0.0,
    ) -> None:
        if turnaround_s < 0:
            raise ValueError(f"turnaround_s={turnaround_s} must be >= 0")
        self._listen = frozenset({request_id(motor_id), REFRESH_ID})
        self._feedback_id = feedback_id(motor_id)
        self.motor_id = motor_id
        self.model = model
        self.turnaround_s = turnaround_s
        self.enabled = False
        self.error: DmState | None = None
        self._name = name or f"dm{motor_id}"
        self._plant = Plant(plant_params(model), now_s=now_s)
        self._counters: Counter[str] = Counter()

    # ---- the Device protocol ----

    @property
    def name(self) -> str:
        """The device's name on its bus."""
        return self._name

    def listen_ids(self) -> frozenset[int]:
        """ID and 0x7FF."""
        return self._listen

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s``: act on it if it is ours, and answer it."""
        self._plant.advance(now_s)
        counters = self._counters
        counters["received"] += 1
        if frame.is_extended_id or frame.is_fd:
            counters["ignored_kind"] += 1
            return []
        if frame.arbitration_id not in self._listen:
            counters["ignored_id"] += 1
            return []
        try:
            command = decode_request(frame.arbitration_id, frame.data, model=self.model)
        except ProtocolError:
            counters["undecodable"] += 1
            return []
        if isinstance(command, RefreshState) and command.motor_id != self.motor_id:
            counters["not_mine"] += 1
            return []
        reply = self.handle(command)
        if reply is None:
            return []
        counters["replied"] += 1
        return [
            Emission(now_s + self.turnaround_s, Frame(arbitration_id=self._feedback_id, data=reply.encode()))
        ]

    def poll(self, now_s: float) -> list[Emission]:
        """Nothing: a DM-J motor in MIT mode only answers."""
        self._plant.advance(now_s)
        return []

    def next_deadline_s(self) -> float | None:
        """None: no frames of its own."""
        return None

    # ---- behaviour ----

    def handle(self, command: DmCommand[Any]) -> Feedback | None:
        """Act on ``command`` (already received) and return its feedback, None when none is sent.

        Raises:
            ValueError: not a DM-J command.
        """
        handler = _HANDLERS.get(type(command))
        if handler is None:
            raise ValueError(f"{command!r} is not a dm command")
        return handler(self, command)

    def inject_fault(self, error: DmState) -> None:
        """An error latches: the output goes off, set-points are refused until a :class:`ClearError`."""
        self.settle()
        self.error = error
        self.enabled = False
        self._plant.set_control(Off())

    def feedback(self) -> Feedback:
        """The feedback the motor sends now: its state, and the shaft's within the model's ranges
        (the position wraps at ±P_MAX as the drive's does; speed and torque saturate)."""
        plant, model = self.plant, self.model
        span = 2 * model.p_max
        position = (math.radians(plant.position_deg) + model.p_max) % span - model.p_max
        state = self.error or (DmState.ENABLED if self.enabled else DmState.DISABLED)
        return Feedback(
            state=state,
            motor_id=self.motor_id & 0x0F,
            position_rad=position,
            velocity_rad_s=_clamp(math.radians(plant.speed_dps), model.v_max),
            torque_nm=_clamp(plant.torque_nm, model.t_max),
            temperature_c=_byte(plant.temperature_c),
            rotor_temperature_c=_byte(plant.temperature_c),
            model=model,
        )

    def _on_mit_control(self, command: MitControl) -> Feedback:
        if self.error is not None:
            self._counters["refused_fault"] += 1
        elif not self.enabled:
            self._counters["refused_disabled"] += 1
        else:
            self._plant.set_control(
                Impedance(
                    position_rad=command.position_rad,
                    velocity_rad_s=command.velocity_rad_s,
                    kp=command.kp,
                    kd=command.kd,
                    torque_ff_nm=command.torque_nm,
                )
            )
        return self.feedback()

    def _on_enable(self, command: Enable) -> Feedback:
        if self.error is None:
            self.enabled = True
        return self.feedback()

    def _on_disable(self, command: Disable) -> Feedback:
        self.enabled = False
        self._plant.set_control(Off())
        return self.feedback()

    def _on_save_zero(self, command: SaveZero) -> None:
        if self.enabled:
            self._counters["refused_zero"] += 1
            return
        self._counters["zeroed"] += 1
        self._plant.position_deg = 0.0

    def _on_clear_error(self, command: ClearError) -> None:
        self.error = None

    def _on_refresh_state(self, command: RefreshState) -> Feedback:
        return self.feedback()


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def _byte(value: float) -> int:
    return max(0, min(255, round(value)))


def _handlers() -> dict[type, Callable[[DmMotor, Any], Feedback | None]]:
    """Each declared command class -> the method of :class:`DmMotor` named after it.

    Raises:
        TypeError: a declared command the model has no method for (found on import, not on the bus).
    """
    found = {}
    for cls in COMMANDS:
        name = f"_on_{method_name(cls)}"
        handler = getattr(DmMotor, name, None)
        if handler is None:
            raise TypeError(f"DmMotor has no {name} for {cls.__name__}")
        found[cls] = handler
    return found


_HANDLERS = _handlers()

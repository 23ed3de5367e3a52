"""The simulated toy motor on a CAN bus: requests in, timed replies out (sans-IO).

The motor decodes requests with the family's own codec, acts on a :class:`~servobus.sim.plant.Plant`
and answers ``turnaround_s`` later (a flash write, :class:`WriteSpeedLimit`, ``flash_write_s`` later).
Each command class is handled by the method named after it (``SetSpeed`` -> ``_on_set_speed``): the
model holds behaviour, not a list of commands.

Frames it does not act on count in :attr:`ToyMotor.counters`: ``ignored_id`` (another identifier),
``ignored_kind`` (extended or CAN FD), ``undecodable``; ``refused_fault`` counts set-points not
executed while a fault is latched (the reply still comes).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.authoring import method_name
from servobus.sim.device import Emission, ListeningDevice
from servobus.sim.plant import Off, Plant, PlantParams, PositionControl, SpeedControl
from servobus_toy.codec import BROADCAST_ID, COMMANDS, decode_request, reply_id, request_id
from servobus_toy.messages import (
    MAX_SPEED_DPS,
    ReadState,
    Restart,
    SetSpeed,
    SpeedLimitEcho,
    StateReply,
    Stop,
    ToyCommand,
    ToyFaults,
    ToyReply,
    WriteSpeedLimit,
)

__all__ = ["DEFAULT_TURNAROUND_S", "FLASH_WRITE_S", "ToyMotor"]

DEFAULT_TURNAROUND_S = 200e-6
FLASH_WRITE_S = 0.02
_INT32_SPAN = 1 << 32


class ToyMotor(ListeningDevice):
    """One toy motor (a :class:`~servobus.sim.device.Listener`).

    Args:
        motor_id: 1..31: requests on 0x600+ID (and broadcasts on 0x600), replies on 0x680+ID.
        plant_params: the mechanics (default: servobus's mid-size servo).
        turnaround_s: request received -> reply ready.
        flash_write_s: how long a :class:`WriteSpeedLimit` takes before its echo is ready.
        name: the device's name on its bus (default ``toy<id>``).
        now_s: simulated time of power-up.

    Attributes:
        speed_limit_dps: the highest speed a set-point runs at (written by :class:`WriteSpeedLimit`).
        faults: the latched fault flags (:meth:`inject_fault`; cleared by a restart).
        counters: frames by fate (see the module docstring), and ``replied``, ``restarts``.

    Raises:
        ValueError: ``motor_id`` outside 1..31 or a negative time.
    """

    def __init__(
        self,
        motor_id: int,
        *,
        plant_params: PlantParams | None = None,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        flash_write_s: float = FLASH_WRITE_S,
        name: str | None = None,
        now_s: float = 0.0,
    ) -> None:
        if turnaround_s < 0 or flash_write_s < 0:
            raise ValueError(
                f"times must be >= 0 (turnaround_s={turnaround_s}, flash_write_s={flash_write_s})"
            )
        self._listen = frozenset({request_id(motor_id), BROADCAST_ID})
        self._reply_id = reply_id(motor_id)
        self.motor_id = motor_id
        self.turnaround_s = turnaround_s
        self.flash_write_s = flash_write_s
        self.speed_limit_dps = MAX_SPEED_DPS
        self.faults = ToyFaults.NONE
        self._name = name or f"toy{motor_id}"
        self._plant = Plant(plant_params, now_s=now_s)
        self._counters: Counter[str] = Counter()
        self._speed_set_dps: float | None = None  # the running set-point, before the limit

    # ---- the Device protocol ----

    @property
    def name(self) -> str:
        """The device's name on its bus."""
        return self._name

    def listen_ids(self) -> frozenset[int]:
        """0x600+ID and 0x600."""
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
            command = decode_request(frame.arbitration_id, frame.data)
        except ProtocolError:
            counters["undecodable"] += 1
            return []
        reply = self.handle(command)
        if reply is None:
            return []
        counters["replied"] += 1
        delay = self.flash_write_s if command.SLOW else self.turnaround_s
        return [Emission(now_s + delay, Frame(arbitration_id=self._reply_id, data=reply.encode()))]

    def poll(self, now_s: float) -> list[Emission]:
        """Nothing: a toy motor only answers."""
        self._plant.advance(now_s)
        return []

    def next_deadline_s(self) -> float | None:
        """None: no frames of its own."""
        return None

    # ---- behaviour ----

    def handle(self, command: ToyCommand[ToyReply | None]) -> ToyReply | None:
        """Act on ``command`` (already received) and return its reply, None when none is sent.

        Raises:
            ValueError: not a toy command.
        """
        handler = _HANDLERS.get(type(command))
        if handler is None:
            raise ValueError(f"{command!r} is not a toy command")
        return handler(self, command)

    def inject_fault(self, flags: ToyFaults) -> None:
        """A fault latches: the output goes off and set-points are refused until a :class:`Restart`."""
        self.settle()
        self.faults |= flags
        self._speed_set_dps = None
        self._plant.set_control(Off())

    def state(self) -> StateReply:
        """The state a :class:`ReadState` reports now."""
        plant = self.plant
        code = round(plant.position_deg * 100) + (1 << 31)
        position_deg = (code % _INT32_SPAN - (1 << 31)) / 100  # a 32-bit counter wraps
        return StateReply(position_deg=position_deg, speed_dps=plant.speed_dps, faults=self.faults)

    def _on_read_state(self, command: ReadState) -> StateReply:
        return self.state()

    def _on_set_speed(self, command: SetSpeed) -> StateReply:
        if self.faults:
            self._counters["refused_fault"] += 1
        else:
            self._speed_set_dps = command.speed_dps
            self._apply_speed()
        return self.state()

    def _on_stop(self, command: Stop) -> StateReply:
        if not self.faults:
            self._speed_set_dps = None
            self._plant.set_control(PositionControl(position_deg=self._plant.position_deg))
        return self.state()

    def _on_write_speed_limit(self, command: WriteSpeedLimit) -> SpeedLimitEcho:
        self.speed_limit_dps = command.limit_dps
        self._apply_speed()
        return SpeedLimitEcho(limit_dps=command.limit_dps)

    def _on_restart(self, command: Restart) -> None:
        self._counters["restarts"] += 1
        self.faults = ToyFaults.NONE
        self._speed_set_dps = None
        self._plant.set_control(Off())

    def _apply_speed(self) -> None:
        if self._speed_set_dps is not None:
            limit = self.speed_limit_dps
            self._plant.set_control(SpeedControl(speed_dps=max(-limit, min(limit, self._speed_set_dps))))


def _handlers() -> dict[type, Callable[[ToyMotor, Any], ToyReply | None]]:
    """Each declared command class -> the method of :class:`ToyMotor` named after it.

    Raises:
        TypeError: a declared command the model has no method for (found on import, not on the bus).
    """
    found = {}
    for cls in COMMANDS:
        name = f"_on_{method_name(cls)}"
        handler = getattr(ToyMotor, name, None)
        if handler is None:
            raise TypeError(f"ToyMotor has no {name} for {cls.__name__}")
        found[cls] = handler
    return found


_HANDLERS = _handlers()

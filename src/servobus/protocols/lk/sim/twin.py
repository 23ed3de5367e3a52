"""What an :class:`~servobus.protocols.lk.sim.device.LkMotor` shares with its C twin (issue 27).

On a network that runs the C core, the motor gets a C twin (:meth:`TwinnedMotor.core_attach`,
:class:`~servobus.protocols.lk.sim.core.LkCore`) that answers the control-loop traffic. The
attributes C changes (:attr:`~TwinnedMotor.state`, :attr:`~TwinnedMotor.held`, the counters, the
angle frame) are taken back before Python reads them, and the knobs C reads
(:attr:`~TwinnedMotor.unresponsive`, :attr:`~TwinnedMotor.turnaround_s`) are pushed when they are
set. Without a twin these are plain attributes and the model runs exactly the reference code.
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

from servobus.protocols.lk.sim.core import CORE_FAMILY, LkCore, LkTwinned, adopt_plant, release_plant
from servobus.protocols.lk.sim.state import AngleFrame, RunState
from servobus.sim.device import BusLink, ListeningDevice
from servobus.sim.plant import Control

__all__ = ["RunState", "TwinnedMotor"]


class TwinnedMotor(ListeningDevice):
    """The half of :class:`~servobus.protocols.lk.sim.device.LkMotor` its C twin shares: the network's
    contract (``CORE_FAMILY``, :meth:`core_attach`, :meth:`core_detach`, :meth:`core_push`) and the
    attributes C changes or reads (see the module docstring), which it sets and owns."""

    CORE_FAMILY: ClassVar[int] = CORE_FAMILY
    _twin: LkCore | None = None  # the C twin while on a C-core network

    def __init__(self, *, turnaround_s: float, counts_per_turn: int) -> None:
        self._state = RunState.ON
        self._held: Control | None = None
        self._angles = AngleFrame(counts_per_turn)
        self._unresponsive = False  # a fault knob, not motor RAM: a reboot keeps it
        self._turnaround_s = turnaround_s

    @property
    def state(self) -> RunState:
        """The run state (spec §4.5..§4.7)."""
        if self._twin is not None:
            self._twin.pull()
        return self._state

    @state.setter
    def state(self, value: RunState) -> None:
        if self._twin is not None:
            self._twin.pull()
        self._state = value

    @property
    def held(self) -> Control | None:
        """The control command held (run while ON; 0x80 and protection drop it)."""
        if self._twin is not None:
            self._twin.pull()
        return self._held

    @held.setter
    def held(self, value: Control | None) -> None:
        if self._twin is not None:
            self._twin.pull()
        self._held = value

    @property
    def angles(self) -> AngleFrame:
        """The encoder counts' zero points (V2.36 0x80 moves the multi-turn origin, in C too)."""
        if self._twin is not None:
            self._twin.pull()
        return self._angles

    @property
    def unresponsive(self) -> bool:
        """A simulator fault knob: the motor still acts on requests but never replies."""
        return self._unresponsive

    @unresponsive.setter
    def unresponsive(self, value: bool) -> None:
        self._unresponsive = value
        self.core_push()

    @property
    def turnaround_s(self) -> float:
        """Request received -> reply ready."""
        return self._turnaround_s

    @turnaround_s.setter
    def turnaround_s(self, value: float) -> None:
        self._turnaround_s = value
        self.core_push()

    def core_attach(self, motor: Any, link: BusLink | None) -> None:
        """Take the C twin ``motor`` (a zeroed ``sb_simmotor *``) and ``link`` from a C-core network:
        the plant moves into ``motor.plant`` and C answers the control-loop traffic from now on."""
        if link is not None and link is not self._link:
            self.attach(link)
        self.settle()
        self._plant = adopt_plant(self._plant, motor)
        self._twin = LkCore(cast(LkTwinned, self), motor)  # (the motor this class is half of)
        self._twin.push()

    def core_detach(self) -> None:
        """Leave the C-core network: take C's last changes and the plant back into Python."""
        twin = self._twin
        if twin is None:
            return
        self.settle()
        self._twin = None
        self._plant = release_plant(self._plant)
        if self._link is not None:
            self.attach(None)

    def take_from_twin(self, state: RunState, held: Control | None, angle_origin: int) -> None:
        """What the C twin changed (its ``pull``): the run state, the held control, the multi-turn
        origin; the plain values, without pulling again."""
        self._state, self._held = state, held
        self._angles.origin = angle_origin

    def core_push(self) -> None:
        """Write into the C twin everything it reads (nothing without one)."""
        if self._twin is not None:
            self._twin.push()

    def settle(self) -> None:
        """Take what the C twin changed, then settle up with the network (ListeningDevice)."""
        if self._twin is not None:
            self._twin.pull()
        super().settle()

"""The toy family's simulator part (``FAMILY.part("sim")``): toy motors on classic CAN.

``servobus sim --family toy``, ``python -m servobus.sim --family toy`` and the CLI's ``--sim N`` ask
this object for their devices (the contract is :class:`servobus.sim.family.SimFamily`); it is imported
only then, so using the family's codec never imports the simulator.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from servobus.sim.family import Setup, SimFamily, SimOptions
from servobus_toy.device import DEFAULT_TURNAROUND_S, ToyMotor
from servobus_toy.messages import Revision

__all__ = ["SIM", "ToySim"]


class ToySim(SimFamily):
    """Toy motors on classic CAN (the only medium the protocol has)."""

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        """A :class:`~servobus_toy.device.ToyMotor` per id.

        Raises:
            ValueError: a revision that is not the toy family's.
        """
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not a toy Revision")
        return Setup(can_devices=[ToyMotor(i) for i in ids])


SIM = ToySim(
    family="toy",
    media=("can",),
    turnaround_s=DEFAULT_TURNAROUND_S,
    refusals={"rs485": "the toy protocol is CAN only"},
)

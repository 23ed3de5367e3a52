"""The DM-J family's simulator part (``FAMILY.part("sim")``): DM-J motors on classic CAN.

``servobus sim --family dm``, the CLI's ``--sim N`` and ``servobus demo --family dm`` ask this
object for their devices (the contract is :class:`servobus.sim.family.SimFamily`).
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from servobus.authoring import Setup, SimFamily, SimOptions
from servobus_dm.device import DEFAULT_TURNAROUND_S, DmMotor
from servobus_dm.messages import Revision

__all__ = ["SIM", "DmSim"]


class DmSim(SimFamily):
    """DM-J motors (the default model, DM4310) on classic CAN."""

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        """A :class:`~servobus_dm.device.DmMotor` per id.

        Raises:
            ValueError: a revision that is not the DM-J family's.
        """
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not a dm Revision")
        return Setup(can_devices=[DmMotor(i) for i in ids])


SIM = DmSim(
    family="dm",
    media=("can",),
    turnaround_s=DEFAULT_TURNAROUND_S,
    refusals={
        "rs485": "DM-J motors in MIT mode speak classic CAN only",
        "canfd": "DM-J motors in MIT mode speak classic CAN only",
    },
)

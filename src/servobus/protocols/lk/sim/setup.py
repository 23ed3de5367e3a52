"""The LK simulator part (``FAMILY.part("sim")``): V2.36 or V2.35 motors on classic CAN."""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from servobus.protocols.lk.model import LkModel, Revision
from servobus.protocols.lk.sim.device import DEFAULT_TURNAROUND_S, LkMotor
from servobus.sim.family import Setup, SimFamily, SimOptions

__all__ = ["SIM", "LkSim"]


class LkSim(SimFamily):
    """LK motors of the default model in ``revision``, on classic CAN."""

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not an LK Revision")
        model = LkModel(revision=revision)
        return Setup(can_devices=[LkMotor(i, model=model) for i in ids])


SIM = LkSim(
    family="lk",
    media=("can",),
    turnaround_s=DEFAULT_TURNAROUND_S,
    refusals={"rs485": "neither LK manual defines an RS485 framing (lk-v2.md §1.3)"},
)

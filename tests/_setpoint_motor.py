"""A simulated motor that says whose set-point its reply answers (tests of other hosts and stalls)."""

from __future__ import annotations

import dataclasses

from servobus.frame import Frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.device import Emission


class SetpointMotor(MyActuatorMotor):
    """A motor whose 0xA2 reply carries, in its speed field, the set-point of the request it answers
    (whoever sent it), so a test can tell whose request a reply is for."""

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        out = super().receive(frame, now_s)
        if frame.data[:1] != b"\xa2":
            return out
        dps = int.from_bytes(frame.data[4:8], "little", signed=True) // 100
        tagged = []
        for emission in out:
            data = emission.frame.data
            if data[:1] == b"\xa2":
                data = data[:4] + dps.to_bytes(2, "little", signed=True) + data[6:]
                emission = Emission(emission.ready_s, dataclasses.replace(emission.frame, data=data))
            tagged.append(emission)
        return tagged

"""The simulated MyActuator motor's 0xB6 active-reply streams ([000]/[002] §2.35/§2.34).

Each streamed command has its own timer of ``interval x 10 ms``, the first frame one interval after
the 0xB6 frame; its frames carry the command's normal reply (§4.36). While any stream is on, the
motor answers nothing else (the motor's ``handle``, spec §9 item 18).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command
from servobus.protocols.myactuator import StreamableCommand
from servobus.protocols.myactuator.codec import COMMANDS
from servobus.protocols.myactuator.sim.handlers import handles

if TYPE_CHECKING:
    from servobus.protocols.myactuator.sim.device import MyActuatorMotor

__all__ = ["STREAMED", "STREAM_STEP_S", "Stream"]

STREAM_STEP_S = 0.01  # 0xB6 interval unit: 10 ms/LSB (§4.36, §9 item 29)
#: what each streamable command's frames carry: its normal reply (§4.36)
STREAMED: dict[StreamableCommand, type[Command]] = {
    StreamableCommand(c.CODE): c for c in COMMANDS if c.STREAMABLE and c.CODE is not None
}


@dataclass(slots=True)
class Stream:
    """One 0xB6 active-reply stream: the next frame is due at ``origin_s + count * interval_s``."""

    interval_s: float
    origin_s: float
    count: int = 1

    @property
    def next_s(self) -> float:
        return self.origin_s + self.count * self.interval_s

    def advance_past(self, now_s: float) -> int:
        """Move the schedule past ``now_s``; return how many due slots were skipped (late poll)."""
        due = math.floor((now_s - self.origin_s) / self.interval_s + 1e-9) + 1
        skipped = max(0, due - self.count - 1)
        self.count = max(self.count + 1, due)
        return skipped


@handles(ma.ActiveReply)
def _active_reply(
    motor: MyActuatorMotor, command: ma.ActiveReply, now_s: float, _rs485: bool = False
) -> None:
    if not command.enabled:
        motor.streams.pop(command.command, None)
        return
    interval_s = command.interval_code * STREAM_STEP_S  # >= 1 step: enabled streams need one
    motor.streams[command.command] = Stream(interval_s=interval_s, origin_s=now_s)

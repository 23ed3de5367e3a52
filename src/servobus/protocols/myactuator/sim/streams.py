"""The simulated MyActuator motor's 0xB6 active-reply streams ([000]/[002] §2.35/§2.34).

Each streamed command has its own timer of ``interval x 10 ms``, the first frame one interval after
the 0xB6 frame; its frames carry the command's normal reply (§4.36). While any stream is on, the
motor answers nothing else (the motor's ``handle``, spec §9 item 18).
"""

from __future__ import annotations

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import StreamableCommand
from servobus.protocols.myactuator.codec import COMMANDS
from servobus.protocols.myactuator.sim.handlers import HandledMotor, execute, handles
from servobus.protocols.myactuator.sim.state import STREAM_STEP_S, Stream

__all__ = ["STREAMED", "STREAM_STEP_S", "Stream", "stream_replies"]

#: what each streamable command's frames carry: its normal reply (§4.36)
STREAMED: dict[StreamableCommand, type[Command]] = {
    StreamableCommand(c.CODE): c for c in COMMANDS if c.STREAMABLE and c.CODE is not None
}


@handles(ma.ActiveReply)
def _active_reply(motor: HandledMotor, command: ma.ActiveReply, now_s: float, _rs485: bool = False) -> None:
    if not command.enabled:
        motor.streams.pop(command.command, None)
        return
    interval_s = command.interval_code * STREAM_STEP_S  # >= 1 step: enabled streams need one
    motor.streams[command.command] = Stream(interval_s=interval_s, origin_s=now_s)


def stream_replies(
    motor: HandledMotor,
    streams: dict[StreamableCommand, Stream],
    now_s: float,
    out: list[tuple[float, Reply]],
) -> None:
    """Add to ``out`` the frame of each of ``streams`` due by ``now_s`` (one per stream, however late
    the poll: the slots it slept through count as ``stream_skipped``)."""
    for command, stream in streams.items():
        if stream.next_s <= now_s:
            motor.tally("stream_skipped", stream.advance_past(now_s))
            motor.tally("stream_frames")
            reply = execute(motor, STREAMED[command](), now_s, rs485=False)
            assert reply is not None
            out.append((now_s, reply))

"""A client's commands end with its hold on a motor (:func:`withdraw`).

When a client loses a motor (its token went, its set-points went stale, another client took it
over, the bridge closes), its commands for that motor still queued on the Bus are withdrawn in the
same step that releases the motor, before the bridge's stop is submitted. They wait there behind a
reply still due (requests with one reply key go one at a time), and the stop, which has another
reply key, would overtake them: a killed client's pipelined speed requests reached its motor after
the stop and left it running. A frame already handed to the link stays: it leaves before the stop.

Spared: reads (anyone's, they move nothing) and the motor's safe commands (the bridge's own stop,
a client's stop request). Only the motor's holder can have a command queued for it (another
client's is refused, or takes the motor over, which withdraws the holder's first), so what is
withdrawn is the loser's, including a set-point of the bridge's tick queued behind a request.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from servobus.remote._served import Served
    from servobus.scheduler import Request


class Withdrawn(PermissionError):
    """A command withdrawn before it was sent: its client no longer holds the motor (a
    PermissionError to the client; none to a client that left)."""

    def __init__(self, message: str, client_left: bool) -> None:
        super().__init__(message)
        self.client_left = client_left


def withdraw(served: Served, mid: int, why: str, client_left: bool = False) -> int:
    """Withdraw the commands for motor ``mid`` still queued on ``served``'s Bus (their callers get
    :class:`Withdrawn`, saying ``why``; ``client_left``: nobody to answer); how many."""
    safe = served.safe_commands[mid]

    def spare(request: Request) -> bool:
        return bool(type(request.command).READ) or request.command in safe

    error = Withdrawn(
        f"motor {mid} on {served.name} was released ({why}): this command was withdrawn before it was sent",
        client_left,
    )
    withdrawn = served.bus.engine.withdraw(served.motors[mid], error, spare)
    served.counts["withdrawn"] += len(withdrawn)
    return len(withdrawn)

"""Who may command which motor on a bridge (:class:`Clients`).

A commanding client declares a liveliness token named by its public id, and its messages carry a
secret id whose hash is that public id (:func:`servobus.remote.wire.public_id`): seeing who holds a
motor (a token's key, ``owners`` in the metrics) does not let another client speak in its name.
The first live client to command a motor holds it until it leaves, makes the motor safe itself, or
lets its set-points go stale; another client's commands for it are refused unless takeover is allowed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols import Command
from servobus.remote import wire

if TYPE_CHECKING:
    from servobus.remote._served import Served

_CACHED = 4096  # secret -> public ids kept


class Clients:
    """The live clients of a bridge and the rule of who holds a motor."""

    def __init__(self, allow_takeover: bool) -> None:
        self.allow_takeover = allow_takeover
        self.live: set[str] = set()  # public ids of the clients whose token is alive
        self._public: dict[str, str] = {}  # secret id -> public id
        self._admitted: dict[bytes, str] = {}  # the same, by the raw bytes (read on Zenoh's threads)

    def public(self, secret: str) -> str:
        """The public id of the client whose messages carry ``secret``."""
        found = self._public.get(secret)
        if found is None:
            if len(self._public) >= _CACHED:
                self._public.clear()
            found = self._public[secret] = wire.public_id(secret)
        return found

    def admits(self, secret: bytes) -> bool:
        """(Any thread) whether the client whose messages carry ``secret`` (its raw bytes) has a live
        token: the bridge hands its set-points to the loop in slots of its own only then."""
        found = self._admitted.get(secret)
        if found is None:
            if len(self._admitted) >= _CACHED:
                self._admitted.clear()
            found = self._admitted[secret] = wire.public_id(secret.hex())
        return found in self.live

    def holder(self, served: Served, mid: int, client: str) -> str | None:
        """The live client other than ``client`` that holds motor ``mid``; None: free to command."""
        owner = served.owners.get(mid)
        if owner is None or owner == client or owner not in self.live or self.allow_takeover:
            return None
        return owner

    def command(self, served: Served, mid: int, secret: str, command: Command) -> None:
        """Let the client with ``secret`` send ``command`` to motor ``mid`` as a request: it holds the
        motor after a command that is not a read. A command that makes the motor safe ends the
        motor's set-point now and, once the motor acknowledged it, its holder (:func:`safe_done`).

        Raises:
            PermissionError: the client has no live token, or another live client holds the motor.
        """
        client = self.public(secret)
        if client not in self.live:
            raise PermissionError("this client has no liveliness token: it may only read")
        holder = self.holder(served, mid, client)
        if holder is not None:
            raise PermissionError(f"motor {mid} on {served.name} is held by another client ({holder})")
        if command in served.safe_commands[mid]:
            served.held.pop(mid, None)  # (the tick must not send the set-point over the stop)
            served.stale_since.pop(mid, None)
        if not type(command).READ:
            served.owners[mid] = client


def safe_done(served: Served, mid: int, secret: str, acknowledged: bool, now: float) -> None:
    """After a request of motor ``mid``'s safe command: acknowledged, the client made the motor safe
    itself and no longer holds it (so its leaving does not undo that, as after ``servobus off``);
    not acknowledged, the motor is stale from ``now`` (the loop's clock) and gets the bridge's own
    stop, repeated until acknowledged, after ``stop_after_s``."""
    if acknowledged:
        if served.owners.get(mid) == wire.public_id(secret):
            served.release(mid)
    else:
        served.stale_since[mid] = now

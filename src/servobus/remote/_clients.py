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
from servobus.remote._withdraw import withdraw

if TYPE_CHECKING:
    from servobus.remote._served import Served

_CACHED = 4096  # secret -> public ids kept


class Clients:
    """The live clients of a bridge and the rule of who holds a motor."""

    def __init__(self, allow_takeover: bool) -> None:
        self.allow_takeover = allow_takeover
        self.live: set[str] = set()  # public ids of the clients whose token is alive
        # (client, bus, motor): motors stopped because the client's set-points went stale, which its
        # requests (some sent before the stop, still on their way) do not take back (:meth:`command`)
        self.revoked: set[tuple[str, str, int]] = set()
        self._public: dict[str, str] = {}  # secret id -> public id

    def public(self, secret: str) -> str:
        """The public id of the client whose messages carry ``secret``."""
        found = self._public.get(secret)
        if found is None:
            if len(self._public) >= _CACHED:
                self._public.clear()
            found = self._public[secret] = wire.public_id(secret)
        return found

    def admits(self, secret: bytes) -> bool:
        """Whether the client whose messages carry ``secret`` (its raw bytes) has a live token: the
        bridge keeps its set-points in slots of its own only then."""
        return self.public(secret.hex()) in self.live

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
            PermissionError: the client has no live token, another live client holds the motor, or
                the bridge stopped the motor for the client's stale set-points (:meth:`revoke`).
        """
        client = self.public(secret)
        if client not in self.live:
            raise PermissionError("this client has no liveliness token: it may only read")
        holder = self.holder(served, mid, client)
        if holder is not None:
            # (named as the metrics name it: its token's key would let the asker keep that token alive)
            shown = wire.shown_id(holder)
            raise PermissionError(f"motor {mid} on {served.name} is held by another client ({shown})")
        safe = command in served.safe_commands[mid]
        if not safe and not type(command).READ and (client, served.name, mid) in self.revoked:
            raise PermissionError(
                f"motor {mid} on {served.name} was stopped because this client's set-points went stale: "
                "a fresh set-point or a stop request of it takes the motor back"
            )
        if safe:
            served.held.pop(mid, None)  # (the tick must not send the set-point over the stop)
            served.stale_since.pop(mid, None)
        elif not type(command).READ:
            served.commanded[mid] += 1
        if not type(command).READ:
            self.take(served, mid, client)

    def take(self, served: Served, mid: int, client: str) -> None:
        """``client`` holds motor ``mid`` now; another client that held it (a takeover) loses its
        set-point and its commands still queued on the Bus (:func:`withdraw`)."""
        previous = served.owners.get(mid)
        if previous is not None and previous != client:
            withdraw(served, mid, "taken over by another client")
            held = served.held.get(mid)
            if held is not None and held.client == previous:
                del served.held[mid]
            served.stale_since.pop(mid, None)
        # (a motor that changed hands frees every client's revocation of it, not only the taker's)
        self.revoked = {entry for entry in self.revoked if entry[1:] != (served.name, mid)}
        served.owners[mid] = client

    def revoke(self, served: Served, mid: int) -> None:
        """Motor ``mid`` is stopped for its holder's stale set-points: that client's commanding
        requests for it are refused until it sends a fresh set-point or a stop request for it (its
        requests sent before the stop would otherwise take the motor back after it)."""
        owner = served.owners.get(mid)
        if owner is not None and owner in self.live:
            self.revoked.add((owner, served.name, mid))

    def left(self, client: str) -> None:
        """``client``'s token went: it holds nothing and may command nothing."""
        self.live.discard(client)
        self.revoked = {entry for entry in self.revoked if entry[0] != client}


def safe_done(served: Served, mid: int, secret: str, acknowledged: bool, now: float, commanded: int) -> None:
    """After a request of motor ``mid``'s safe command: acknowledged, the client made the motor safe
    itself and no longer holds it (so its leaving does not undo that, as after ``servobus off``),
    unless a command was taken for the motor since (``served.commanded[mid]`` is no longer
    ``commanded``, its count when the safe command was taken): the motor moves again, and its
    holder's leaving must stop it; not acknowledged, the motor is stale from ``now`` (the loop's
    clock) and gets the bridge's own stop, repeated until acknowledged, after ``stop_after_s``."""
    if acknowledged:
        if served.commanded[mid] == commanded and served.owners.get(mid) == wire.public_id(secret):
            served.release(mid)
    else:
        served.stale_since[mid] = now

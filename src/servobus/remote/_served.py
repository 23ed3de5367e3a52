"""One bus as a bridge serves it: its motors and their codecs' safe commands, the set-point each
motor holds, which client holds each motor, the counters and the figures the bridge reports."""

from __future__ import annotations

import dataclasses
import enum
import logging
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from servobus._version import __version__
from servobus.bus import Bus, Motor
from servobus.limits import safe_commands
from servobus.protocols import Command, Reply
from servobus.remote import wire
from servobus.remote.keys import check_name
from servobus.scheduler import Traffic

logger = logging.getLogger("servobus.remote.bridge")

_LATENCY_KEPT = 20_000  # set-point -> wire samples kept for the percentiles
REFRESH_S = 1.0  # a motor's state is published again after this long without a change

#: the bridge's counters of each bus, and what each counts
COUNTS = {
    "setpoints": "set-points taken (well-formed, fresh, from the motor's holder)",
    "applied": "set-points that went out at least once",
    "overwritten": (
        "set-point messages a newer one of the same client (of any client without a token) replaced "
        "before the bridge took them"
    ),
    "stale": "set-points that arrived past their deadline",
    "expired": "set-points that went stale while held (not renewed in time)",
    "reordered": "set-points older than the one held from the same client",
    "refused": "commands from a client without a token, or for a motor another live client holds",
    "malformed": "messages that did not parse, or were not a command the motor's codec takes",
    "limited": "commands beyond the motor's host-side limits (servobus.limits), refused",
    "oversized": "messages longer than their key allows (remote/_limits.py), dropped before decoding",
    "shed": "queries dropped on arrival: their client's or their kind's queue was full",
    "requests": "commands through request",
    "reads": "commands through read",
    "stops": "safe stops sent because a client left or its set-points went stale",
    "withdrawn": "queued commands of a client that lost the motor, withdrawn (not to follow its stop)",
    "states": "states published",
}


@dataclass(slots=True)
class Held:
    """A motor's latest set-point: who sent it, until when it may be applied, whether it went out."""

    client: str
    seq: int
    command: Command
    sent_unix_ns: int
    expires: float  # the loop's clock
    applied: bool = False


class Served:
    """One bus as the bridge serves it."""

    def __init__(self, name: str, bus: Bus, motors: Sequence[Motor]) -> None:
        self.name = check_name("bus", name)
        self.bus = bus
        self.motors: dict[int, Motor] = {}
        for motor in motors:
            if motor.motor_id in self.motors:
                raise ValueError(f"bus {name}: two motors with id {motor.motor_id} (keys name motors by id)")
            self.motors[motor.motor_id] = motor
        self.schemas = {mid: wire.Schema.of(m.codec.family) for mid, m in self.motors.items()}
        #: the commands with which a client makes a motor safe itself (then it no longer holds it)
        self.safe_commands = {mid: safe_commands(m.codec) for mid, m in self.motors.items()}
        #: what a motor gets when its client leaves: the Bus's safe kind, "stop" where the Bus has none
        self.stop_commands = {mid: _stop_command(m, bus.safe or "stop") for mid, m in self.motors.items()}
        self.held: dict[int, Held] = {}
        self.stale_since: dict[int, float] = {}  # motor -> when its set-point expired (loop clock)
        self.owners: dict[int, str] = {}  # motor -> the public id of the client that holds it
        #: motor -> how many commands (set-points, requests that are not reads) were taken for it: a
        #: client's stop releases the motor only if none came after it (:func:`_clients.safe_done`)
        self.commanded: dict[int, int] = dict.fromkeys(self.motors, 0)
        self.dirty: set[int] = set()
        self.published: dict[int, float] = {}
        self.publishers: dict[int, Any] = {}
        self.to_wire_ns: deque[int] = deque(maxlen=_LATENCY_KEPT)
        self.counts = dict.fromkeys(COUNTS, 0)

    def changed(self, motor: Motor, traffic: Traffic, reply: Reply) -> None:
        """(The Bus's subscriber) the motor's state is to be published, if it is one served here."""
        if self.motors.get(motor.motor_id) is motor:
            self.dirty.add(motor.motor_id)

    def publish(self, mid: int, now: float) -> None:
        """Publish motor ``mid``'s state now (``now``: the loop's clock)."""
        motor = self.motors[mid]
        fault: enum.Flag | enum.IntEnum | None = motor.fault.flags if motor.fault is not None else None
        if fault is None and motor.fault is not None and isinstance(motor.fault.code, enum.IntEnum):
            fault = motor.fault.code  # (a family that reports one code: Damiao's ERR)
        state = wire.State(mid, time.time_ns(), motor.online is not False, motor.state, fault)
        try:
            self.publishers[mid].put(wire.encode_state(self.schemas[mid], state))
        except wire.WireError as exc:
            logger.debug("state of motor %s not encodable: %s", mid, exc)
            return
        self.counts["states"] += 1
        self.dirty.discard(mid)
        self.published[mid] = now

    def publish_due(self, now: float, period: float) -> None:
        """Publish the state of each motor that changed and was last published ``period`` ago, and
        again every ``REFRESH_S`` of each one that has a state (a client that joins late sees it)."""
        for mid in list(self.dirty):
            if now - self.published.get(mid, -period) >= period:
                self.publish(mid, now)
        for mid, at in list(self.published.items()):
            if now - at >= REFRESH_S:
                self.publish(mid, now)

    def release(self, mid: int) -> None:
        """Motor ``mid`` has no set-point and no holder any more."""
        self.held.pop(mid, None)
        self.stale_since.pop(mid, None)
        self.owners.pop(mid, None)

    def info(self, node: str, limits: dict[str, Any]) -> dict[str, Any]:
        return {
            "node": node,
            "bus": self.name,
            "servobus": __version__,
            "wire": wire.VERSION,
            **limits,
            "safe": self.bus.safe,
            "motors": [
                {
                    "id": mid,
                    "family": m.codec.family,
                    "revision": m.codec.revision.name,
                    "link": m.codec.link,
                    "schema": self.schemas[mid].digest,
                }
                for mid, m in sorted(self.motors.items())
            ],
        }

    def metrics(self) -> dict[str, Any]:
        samples = sorted(self.to_wire_ns)

        def pct(q: float) -> float | None:
            return samples[min(len(samples) - 1, int(q * len(samples)))] / 1e6 if samples else None

        return {
            "bus": dataclasses.asdict(self.bus.metrics()),
            "bridge": dict(self.counts),
            "setpoint_to_wire_ms": {"p50": pct(0.5), "p99": pct(0.99), "n": len(samples)},
            "owners": {str(mid): wire.shown_id(owner) for mid, owner in sorted(self.owners.items())},
        }


def _stop_command(motor: Motor, kind: str) -> Command | None:
    """``motor``'s safe command of ``kind``, its "stop" where it has none of that kind, else None."""
    for wanted in dict.fromkeys((kind, "stop")):
        try:
            return motor.codec.safe_command(wanted)
        except ValueError:
            continue
    logger.warning("%r has no %r nor 'stop' safe command: a client that leaves cannot stop it", motor, kind)
    return None

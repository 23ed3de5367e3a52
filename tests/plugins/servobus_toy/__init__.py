"""A small invented protocol family, packaged apart from servobus and registered by entry point.

It is the example of the family contract (``servobus.protocols.Family``): a package that declares its
commands once (:mod:`.messages`), binds one motor's codec on Frames (:mod:`.codec`), simulates its
motors (:mod:`.device`), has its typed motor methods generated from the declarations (:mod:`._motor`),
says what the command line sends (:mod:`.cli`, imported only by the CLI) and exposes one ``FAMILY``.
It has no ``dbc`` part: its DBC is derived from the declarations. Its distribution registers it::

    [servobus.families]
    toy = servobus_toy:FAMILY

after which ``Bus.motor("toy", 1)``, ``servobus decode --family toy`` and the other family-driven
parts of servobus use it without a line of servobus changed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols import Family
from servobus_toy.codec import COMMANDS, LINKS, MOTOR_IDS, bind, broadcast, decode_reply, decode_request
from servobus_toy.messages import (
    ReadState,
    Restart,
    Revision,
    SetSpeed,
    SpeedLimitEcho,
    StateReply,
    Stop,
    ToyFaults,
    WriteSpeedLimit,
)

__all__ = [
    "FAMILY",
    "ReadState",
    "Restart",
    "Revision",
    "SetSpeed",
    "SpeedLimitEcho",
    "StateReply",
    "Stop",
    "ToyFaults",
    "WriteSpeedLimit",
]

if TYPE_CHECKING:
    from servobus_toy._motor import Motor


def _motor() -> type[Motor]:
    """The typed motor class, generated from the declarations by ``servobus.protocols._calls.render``
    (imported only when a Bus asks: it imports the Bus)."""
    from servobus_toy._motor import Motor

    return Motor


FAMILY: Family[Motor] = Family(
    name="toy",
    description="an invented servo protocol: the example of a family packaged apart from servobus",
    revisions=tuple(Revision),
    default_revision=Revision.V1,
    decode_request=decode_request,
    decode_reply=decode_reply,
    links=LINKS,
    bind=bind,
    broadcast=broadcast,
    commands=COMMANDS,
    motor_ids=MOTOR_IDS,
    motor=_motor,
    parts={"cli": "servobus_toy.cli:CLI", "sim": "servobus_toy.sim:SIM"},
)

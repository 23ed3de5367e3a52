"""A small invented protocol family, packaged apart from servobus and registered by entry point.

It is the example of the family contract (``servobus.protocols.Family``): a package that declares its
commands once (:mod:`.messages`), binds one motor's codec on Frames (:mod:`.codec`), simulates its
motors (:mod:`.device`, and :mod:`.sim`, the simulator's part), has its typed motor methods generated
from the declarations (:mod:`._motor`), says what the command line sends (:mod:`.cli`) and exposes one
``FAMILY``. It has no ``dbc`` part: its DBC is derived from the declarations. Its distribution registers it::

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
    # the typed motor (._motor: Motor) and the parts (.sim: SIM, .cli: CLI) are found here by name,
    # each imported only when asked for
    package=__name__,
)

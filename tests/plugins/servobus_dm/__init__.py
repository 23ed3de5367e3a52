"""Damiao DM-J motors in MIT mode over classic CAN: a servobus family written outside servobus.

A package of its own (``tests/plugins``: servobus's proof that a family from outside is a
first-class one), registered by its distribution's entry point::

    [servobus.families]
    dm = servobus_dm:FAMILY

Its frames are bit-packed and scaled by the motor's model (:mod:`.models`), declared as bit fields
(:mod:`.messages`, on :mod:`servobus.protocols.bits`) with no ``encode``/``decode`` written by hand;
:mod:`.codec` binds one motor, :mod:`.device` and :mod:`.sim` simulate it, :mod:`.cli` and
:mod:`.dbc` are its command-line and DBC parts, :mod:`._motor` its typed methods (generated).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.authoring import Family
from servobus_dm.codec import COMMANDS, LINKS, MOTOR_IDS, bind, broadcast, decode_reply, decode_request
from servobus_dm.messages import (
    ClearError,
    Disable,
    DmState,
    Enable,
    Feedback,
    MitControl,
    RefreshState,
    Revision,
    SaveZero,
)
from servobus_dm.models import DEFAULT_MODEL, MODELS, DmModel

__all__ = [
    "DEFAULT_MODEL",
    "FAMILY",
    "MODELS",
    "ClearError",
    "Disable",
    "DmModel",
    "DmState",
    "Enable",
    "Feedback",
    "MitControl",
    "RefreshState",
    "Revision",
    "SaveZero",
]

if TYPE_CHECKING:
    from servobus_dm._motor import Motor

FAMILY: Family[Motor] = Family(
    name="dm",
    description="Damiao DM-J motors in MIT mode over classic CAN (a family from outside servobus)",
    revisions=tuple(Revision),
    default_revision=Revision.V1,
    decode_request=decode_request,
    decode_reply=decode_reply,
    links=LINKS,
    bind=bind,
    broadcast=broadcast,
    commands=COMMANDS,
    motor_ids=MOTOR_IDS,
    package=__name__,  # ._motor, .sim, .cli and .dbc found by name
)

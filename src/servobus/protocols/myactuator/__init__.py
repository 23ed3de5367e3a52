"""MyActuator V3-driver protocol, revisions V4.3 and V4.4: sans-IO codec (myactuator-v4.md).

Modules, one job each:

* :mod:`.revision`: ``Revision`` and the rule choosing it from the 0xB2 version date.
* :mod:`.ids`: CAN identifiers (0x140/0x240/0x280/0x300/0x400/0x500) and match keys.
* :mod:`.enums`: indexes, modes, error flags, the fault table.
* :mod:`.commands`, :mod:`.commands_control`: one class per 8-byte request.
* :mod:`.motion`: CAN motion (MIT) mode, with per-revision ranges.
* :mod:`.replies`: one class per reply layout, and ``Echo``.
* :mod:`.codec`: decoder tables, ``decode_request``/``decode_reply``, revision availability.
* :mod:`.rs485`: the ``3E`` RS485 frame; :mod:`.rs485_motion`: the ``FE EE`` RS485 motion frame (V4.4).

Usage::

    from servobus.protocols import myactuator as ma

    command = ma.AbsolutePositionControl(angle_deg=360, max_speed_dps=500)
    data = ma.encode_request(command, revision=ma.Revision.V4_4)  # A4 00 F4 01 A0 8C 00 00
    reply = ma.decode_reply(0x241, bytes.fromhex("A4 32 64 00 F4 01 2D 00"))  # StatusReply(...)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols._family import Family, SerialLine, command_classes
from servobus.protocols.myactuator import bound as _bound
from servobus.protocols.myactuator import commands, commands_control, enums, motion, replies, revision
from servobus.protocols.myactuator.codec import decode_reply, decode_request

# Each module's __all__ is the package's: a class is exported where it is written, not listed again.
from servobus.protocols.myactuator.commands import *  # noqa: F403
from servobus.protocols.myactuator.commands_control import *  # noqa: F403
from servobus.protocols.myactuator.enums import *  # noqa: F403
from servobus.protocols.myactuator.ids import MOTOR_IDS as _MOTOR_IDS
from servobus.protocols.myactuator.ids import IdKind
from servobus.protocols.myactuator.motion import *  # noqa: F403
from servobus.protocols.myactuator.replies import *  # noqa: F403
from servobus.protocols.myactuator.revision import *  # noqa: F403
from servobus.protocols.myactuator.rs485_motion import Crc32Rule, Rs485MotionCommand, Rs485MotionReply

__all__ = [
    "FAMILY",
    "Crc32Rule",
    "IdKind",
    "Rs485MotionCommand",
    "Rs485MotionReply",
    "decode_reply",
    "decode_request",
]
__all__ += commands.__all__
__all__ += commands_control.__all__
__all__ += enums.__all__
__all__ += motion.__all__
__all__ += replies.__all__
__all__ += revision.__all__

if TYPE_CHECKING:  # the typed motor class; imported when a Bus asks (it imports the Bus)
    from servobus.protocols.myactuator._motor import Motor


# A declaration: related arguments share a line.
# fmt: off
FAMILY: Family[Motor] = Family(
    name="myactuator", package=__name__,  # the typed Motor (_motor.py) and the sim, cli, dbc parts are there
    description="MyActuator RMD-X and similar on V3 drivers, protocol V4.3/V4.4 (CAN, RS485, motion mode)",
    revisions=_bound.REVISIONS, default_revision=_bound.REVISIONS[0],
    decode_request=decode_request, decode_reply=decode_reply,
    links=_bound.LINKS, bind=_bound.bind, broadcast=_bound.broadcast,
    commands=command_classes(globals().values()), motor_ids=_MOTOR_IDS,
    serial=(  # 8N1 at the rates the manuals list, none named the default (myactuator-v4.md §1.2)
        SerialLine(
            name=_bound.Rs485Framing.name,
            framing=_bound.Rs485Framing,
            bauds=(115_200, 500_000, 1_000_000, 1_500_000, 2_500_000),
            aliases=("myactuator",),
        ),
    ),
)
# fmt: on

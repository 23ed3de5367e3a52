"""LK-TECH (LingKong) MS/MF/MH/MG CAN protocol V2.36 and the RMD-S/RMD-F V2.35 variant, sans-IO.

Typed commands and replies in physical units <-> 8-byte CAN payloads (spec ``lk-v2.md``; manuals
[001] = V2.36, [003] = V2.35). Modules: ``model`` (revision, motor type, encoder width), ``ids``
(identifiers, match keys, the V2.35 echo rule), ``commands`` / ``commands_control`` (requests),
``replies`` / ``replies_position`` (replies), ``params`` (parameter addressing) with
``params_v236`` / ``params_v235`` (parameter messages), ``states`` (named state bytes), ``codec``
(tables and entry points).

Parameters. ``LkModel(revision=V2_36, motor_type=MG, encoder_bits=14)`` bundles what layouts and units
depend on; ``decode_request`` / ``decode_reply`` / ``encode_request`` take ``revision=`` and/or
``model=``. A message whose bytes depend on motor type or encoder width carries it as a field, so
``encode()`` needs nothing else (``TorqueControl(motor_type=MotorType.MF, current_a=1.5)``). A layout
that differs between revisions is two classes (``SpeedControl`` / ``SpeedControlV235``).

Resolutions of the spec's open points (spec §10, §8.2):

* Torque current: MF 33/4096 A, MG 66/4096 A per count on both revisions ([003]'s "±32 A" for MG
  is read as a rounding). MH has no stated scale: its values stay raw (``iq_counts``). MS reports
  power (``power_counts``, unitless) in status-2 replies and has no torque loop.
* Power: the 0xA0 reply's DATA[2..3] is the output power on every motor type (§4.9, A20), so it is
  ``power_counts`` there even for MF/MG/MH. Power is kept as the raw int16 without a range check on
  both revisions (A24: the manuals state -1000..1000 and -850..850, and motors report beyond them).
* 0xA8 maxSpeed: 1 dps/LSB (text of both manuals, A2/A6); worked examples W5/W6 label the same bytes
  0.01 dps/LSB — bytes agree, only the reading differs.
* 0x9B on V2.35: a reply whose DATA[0] is 0x9A is accepted (A4; ``ids.request_keys``).
* 0x92: 56-bit two's complement (A7). 0x44 V2.36 reply DATA[7]: NULL (A14).
* 0x33 (V2.35) and the 0x280 frame: layouts inferred by the spec (``codec.INFERRED_LAYOUTS``).
* 18-bit encoders: counts 0..65535, angle assumes the top 16 bits are sent (inferred).
* NULL bytes are ignored on decode, written as 0x00 on encode.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols._family import Family, command_classes
from servobus.protocols.lk import bound as _bound
from servobus.protocols.lk import commands as _commands
from servobus.protocols.lk import commands_control as _commands_control
from servobus.protocols.lk import params_v235 as _params_v235
from servobus.protocols.lk import params_v236 as _params_v236
from servobus.protocols.lk import replies as _replies
from servobus.protocols.lk import replies_position as _replies_position
from servobus.protocols.lk import states as _states
from servobus.protocols.lk._base import LkCommand, LkReply
from servobus.protocols.lk.codec import decode_reply, decode_request
from servobus.protocols.lk.commands import *  # noqa: F403 - the commands, exported by their module's __all__
from servobus.protocols.lk.commands_control import *  # noqa: F403
from servobus.protocols.lk.ids import MOTOR_IDS as _MOTOR_IDS
from servobus.protocols.lk.model import DEFAULT_MODEL, IQ_AMPS_PER_COUNT, LkModel, MotorType, Revision
from servobus.protocols.lk.params import (
    BusType,
    CanBaud,
    ControlParam,
    ParamId,
    ParamValue,
    PidGains,
    Rs485Baud,
    SettingParam,
)
from servobus.protocols.lk.params_v235 import *  # noqa: F403
from servobus.protocols.lk.params_v236 import *  # noqa: F403
from servobus.protocols.lk.replies import *  # noqa: F403
from servobus.protocols.lk.replies_position import *  # noqa: F403
from servobus.protocols.lk.states import *  # noqa: F403

# What this package adds to the message modules' classes (appended at the end of the module).
__all__ = [
    "DEFAULT_MODEL",
    "FAMILY",
    "IQ_AMPS_PER_COUNT",
    "BusType",
    "CanBaud",
    "ControlParam",
    "LkCommand",
    "LkModel",
    "LkReply",
    "MotorType",
    "ParamId",
    "ParamValue",
    "PidGains",
    "Revision",
    "Rs485Baud",
    "SettingParam",
    "decode_reply",
    "decode_request",
]
if TYPE_CHECKING:  # the typed motor class; imported when a Bus asks (it imports the Bus)
    from servobus.protocols.lk._motor import Motor


# A declaration: related arguments share a line.
# fmt: off
FAMILY: Family[Motor] = Family(
    name="lk", package=__name__,  # the typed Motor (_motor.py) and the sim, cli, dbc parts are there
    description="LK-TECH MS/MF/MH/MG CAN V2.36 and RMD-S/RMD-F V2.35 (0x140+ID -> 0x180+ID / 0x140+ID)",
    revisions=_bound.REVISIONS, default_revision=_bound.REVISIONS[0],
    decode_request=decode_request, decode_reply=decode_reply,
    links=_bound.LINKS, bind=_bound.bind, broadcast=_bound.broadcast,
    commands=command_classes(globals().values()), motor_ids=_MOTOR_IDS,
)
# fmt: on

# The message classes: each module's own __all__ (a new class is exported where it is written).
__all__ += _commands.__all__
__all__ += _commands_control.__all__
__all__ += _params_v235.__all__
__all__ += _params_v236.__all__
__all__ += _replies.__all__
__all__ += _replies_position.__all__
__all__ += _states.__all__

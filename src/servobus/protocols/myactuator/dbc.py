"""The MyActuator DBC part (``FAMILY.part("dbc")``): what its classes' declarations do not say.

* **Standard frames** (0x140 + ID requests, 0x240 + ID replies, the 0x280 broadcast): multiplexed on
  DATA[0]; each layout is its class's ``FIELDS`` (:func:`servobus.protocols.dbc.keyed_layouts`): the family's
  commands of the revision by ``CODE``, their declared replies (``reply_types()``) by theirs, the R2
  status layout under each command's byte, and the frames the motor sends of itself (``EVENTS``:
  0xF1). A command answered by ``Echo`` (its request's bytes) is its own fields, named ``command.<field>``.
* **Motion mode** (0x400/0x500 + ID): the C core's ``MIT_COMMAND``/``MIT_REPLY`` packers with the
  revision's :class:`~servobus.protocols.myactuator.MotionScales` (option ``max_torque_nm`` for V4.4's
  model-specific torque range), bit positions from :func:`servobus.protocols.dbc.packed_signals`.
"""

from __future__ import annotations

import dataclasses
from typing import cast

from servobus.protocols.dbc import (
    DbcFamily,
    DbcOption,
    DbcQuery,
    Described,
    Keyed,
    Layout,
    MessageSpec,
    keyed_layouts,
    muxed,
    packed_signals,
    reply_keys,
    request_keys,
)
from servobus.protocols.myactuator import (
    EVENTS,
    FAMILY,
    Echo,
    MotionCommand,
    MotionReply,
    MotionScales,
    Rs485MotionCommand,
)
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    motion_reply_id,
    motion_request_id,
    reply_id,
    request_id,
)
from servobus.protocols.myactuator.motion import command_packer, reply_packer
from servobus.protocols.myactuator.revision import Revision

__all__ = ["DBC"]


def _describe(query: DbcQuery) -> Described:
    rev = cast(Revision, query.revision if query.revision is not None else FAMILY.default_revision)
    scales = MotionScales.for_revision(rev, max_torque_nm=query.options.get("max_torque_nm"))
    left_out: list[str] = []
    requests = keyed_layouts(request_keys(FAMILY.commands, rev), "request", left_out)
    events = [Keyed(event.CODE, event, event.__name__) for event in EVENTS if event.CODE is not None]
    replies = keyed_layouts([*reply_keys(FAMILY.commands, rev, echo=Echo), *events], "reply", left_out)
    if rev in Rs485MotionCommand.REVISIONS:
        serial = [Rs485MotionCommand.__name__, *(r.__name__ for r in Rs485MotionCommand.reply_types())]
        left_out.append(f"RS485 MIT frames ({', '.join(serial)}): serial frames, not CAN")
    command = Layout(None, "", packed_signals(command_packer(scales), MotionCommand), message="MotionCommand")
    reply = Layout(None, "", packed_signals(reply_packer(scales), MotionReply), message="MotionReply")
    ranges = (
        f"p ±{scales.p_max_rad} rad, v ±{scales.v_max_rad_s} rad/s, kp 0..{scales.kp_max}, "
        f"kd 0..{scales.kd_max}, t ±{scales.t_max_nm} Nm"
    )
    messages = []
    for motor_id in query.ids:
        motor = f"motor_{motor_id}"
        # DATA[0] of a motion reply is the motor's id, the one of its identifier (checked on decode).
        own = tuple(
            dataclasses.replace(s, minimum=motor_id, maximum=motor_id) if s.field == "motor_id" else s
            for s in reply.signals
        )
        for ident, name, kind, root, sender, comment in (
            (request_id(motor_id), "request", "request", muxed(requests), "host", "requests"),
            (reply_id(motor_id), "reply", "reply", muxed(replies), motor, "replies"),
            (motion_request_id(motor_id), "motion_command", "request", command, "host", "motion commands"),
            (
                motion_reply_id(motor_id),
                "motion_reply",
                "reply",
                dataclasses.replace(reply, signals=own),
                motor,
                "motion replies",
            ),
        ):
            text = f"MyActuator {rev.name} {comment} of motor {motor_id}"
            text += f" ({ranges})" if name.startswith("motion") else ", multiplexed on DATA[0]"
            messages.append(
                MessageSpec(
                    ident, f"myactuator_{name}_{motor_id}", 8, kind, root, (sender,), text, motor_id=motor_id
                )
            )
    messages.append(
        MessageSpec(
            BROADCAST_ID,
            "myactuator_broadcast",
            8,
            "request",
            muxed(requests),
            ("host",),
            f"MyActuator {rev.name} multi-motor requests (every motor replies on 0x240 + ID)",
        )
    )
    return Described(revision=rev, messages=tuple(messages), left_out=tuple(left_out))


DBC = DbcFamily(
    summary=(
        "per motor its requests (0x140+ID) and replies (0x240+ID), multiplexed on DATA[0], and its "
        "motion-mode command (0x400+ID) and reply (0x500+ID); the 0x280 broadcast"
    ),
    options=(
        DbcOption(
            name="max_torque_nm",
            help="V4.4: the motor's max torque, the motion-mode torque range [the revision's]",
            parse=float,
        ),
    ),
    describe=_describe,
)

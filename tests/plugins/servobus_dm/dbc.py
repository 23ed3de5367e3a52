"""The DM-J family's DBC part (``FAMILY.part("dbc")``): its frames are bit fields, not byte layouts.

Per motor: the MIT set-point on the motor's id and its feedback on id + 0x10; once: the refresh on
0x7FF. The signals are the frame classes' declared bit fields (:func:`bit_signals` of their
``FIELDS``), scaled over the ranges of the motor model (option ``model``, a name of
``servobus_dm.MODELS``; default DM4310).
"""

from __future__ import annotations

from servobus.authoring import (
    DbcFamily,
    DbcLayout,
    DbcOption,
    DbcQuery,
    Described,
    MessageSpec,
    bit_signals,
)
from servobus_dm.codec import FEEDBACK_OFFSET, REFRESH_ID, request_id
from servobus_dm.messages import Feedback, MitControl, RefreshState, Revision
from servobus_dm.models import find_model

__all__ = ["DBC"]


def _describe(query: DbcQuery) -> Described:
    model = find_model(query.options.get("model"))
    for motor_id in query.ids:
        request_id(motor_id)  # ValueError outside 1..15
    rev = query.revision if query.revision is not None else Revision.V1
    messages: list[MessageSpec] = []
    what = f"dm {model.name} (±{model.p_max} rad, ±{model.v_max} rad/s, ±{model.t_max} N.m)"
    for motor_id in query.ids:
        messages.append(
            MessageSpec(
                motor_id,
                f"dm_mit_{motor_id}",
                8,
                "request",
                DbcLayout(None, "", bit_signals(MitControl, model), message="MitControl"),
                ("host",),
                f"{what} MIT set-point to motor {motor_id}",
                motor_id=motor_id,
            )
        )
        messages.append(
            MessageSpec(
                motor_id + FEEDBACK_OFFSET,
                f"dm_feedback_{motor_id}",
                8,
                "reply",
                DbcLayout(None, "", bit_signals(Feedback, model), message="Feedback"),
                (f"motor_{motor_id}",),
                f"{what} feedback of motor {motor_id}",
                motor_id=motor_id,
            )
        )
    messages.append(
        MessageSpec(
            REFRESH_ID,
            "dm_refresh",
            8,
            "request",
            DbcLayout(
                None, "", bit_signals(RefreshState, model), constants=((2, 0xCC),), message="RefreshState"
            ),
            ("host",),
            "dm state refresh: DATA[0] names the motor that answers with its feedback",
        )
    )
    left_out = (
        "special commands FF x7 + FB..FE (Enable, Disable, SaveZero, ClearError): told apart from a MIT "
        "set-point by their whole payload, not a multiplexer value; the DBC reads them as set-points",
    )
    return Described(revision=rev, messages=tuple(messages), left_out=left_out)


DBC = DbcFamily(
    summary="per motor its MIT set-point (on the motor id) and feedback (id + 0x10), and the refresh (0x7FF)",
    options=(DbcOption(name="model", help="the motor model, a name of servobus_dm.MODELS [DM4310]"),),
    describe=_describe,
)

"""The LK DBC part (``FAMILY.part("dbc")``): what its classes' declarations do not say.

V2.36 and V2.35, per motor its requests (0x140 + ID) and replies (0x180 + ID; V2.35 replies share
0x140 + ID, so that DBC holds the replies unless the requests are asked for), multiplexed on DATA[0];
parameter frames are multiplexed again on their parameter byte (V2.36 settings: a group byte, then the
parameter); V2.35's 0x280 multi-motor torque frame. Options: ``model`` (an ``LkModel`` or a motor type
MS, MF, MH, MG; default MG) and ``encoder_bits`` (14, 15, 16, 18; default 14).

A class's fields are its ``FIELDS`` where it declares them; for the others :func:`lk_fields` states
them: the field objects of ``protocols/lk`` (``SPEED``, ``TEMPERATURE``, the ``IqSlot`` of the motor
type, the parameter ``*_LAYOUTS``) at the offsets their classes write in ``encode``/``decode``.
``tests/test_dbc_export.py`` decodes frames of every LK class both ways and compares every field.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, cast

from servobus.dbc import (
    DbcFamily,
    DbcOption,
    DbcQuery,
    Described,
    EnumByte,
    FlagsByte,
    Layout,
    MessageSpec,
    Mux,
    ResultByte,
    SignalSpec,
    le_signal,
    muxed,
    signal_spec,
)
from servobus.protocols._fields import IntField
from servobus.protocols.lk import commands as cmd
from servobus.protocols.lk import commands_control as ctl
from servobus.protocols.lk import params as lkp
from servobus.protocols.lk import params_v235 as p235
from servobus.protocols.lk import params_v236 as p236
from servobus.protocols.lk import replies as rep
from servobus.protocols.lk import replies_position as rpos
from servobus.protocols.lk import states
from servobus.protocols.lk.codec import REPLY_CLASSES, REQUESTS, resolve_model
from servobus.protocols.lk.ids import MULTI_MOTOR_ID, reply_id, request_id
from servobus.protocols.lk.model import LkModel, MotorType, Revision, encoder_max_count
from servobus.protocols.lk.params import SETTING_LAYOUTS, SettingParam

__all__ = ["DBC", "lk_fields"]


def _iq(slot: Any, motor_type: Any, limits: tuple[int, int] | None = None) -> Any:
    """The field an LK ``IqSlot`` is for ``motor_type``: amperes (MF, MG) or raw counts under the slot's
    name for the type, within ``limits`` (default: the slot's); None if the type does not carry it."""
    lo, hi = limits if limits is not None else slot.limits
    amps = slot.field(motor_type, (lo, hi))
    if amps is not None:
        return amps
    name = slot.counts_names.get(motor_type)
    return None if name is None else IntField(name, size=2, signed=True, lo=lo, hi=hi)


def _items(field: Any, count: int) -> list[Any]:
    """``field`` as the items of a tuple value: ``currents_a[0]``, ``currents_a[1]``..."""
    return [dataclasses.replace(field, name=f"{field.name}[{i}]") for i in range(count)]


def _param_layouts(params: type[enum.IntEnum], layouts: Mapping[Any, Any] | None) -> tuple[Layout, ...]:
    """One layout per parameter of ``params`` (the value signals of its ``ValueLayout``)."""
    return tuple(
        Layout(int(p), p.name, _value_signals(layouts[p]) if layouts else (), implies=(("param", p.name),))
        for p in params
    )


def _value_signals(layout: Any) -> tuple[SignalSpec, ...]:
    """The signals of an LK parameter ``ValueLayout`` (``params.py``): PID gains, an integer, a choice."""
    if isinstance(layout, lkp._Pid):
        return tuple(
            le_signal(f"value.{gain}", offset, 2, minimum=0, maximum=layout.hi)
            for gain, offset in (("kp", 2), ("ki", 4), ("kd", 6))
        )
    if isinstance(layout, lkp._Int):
        field = IntField("value", size=layout.size, signed=layout.signed, lo=layout.lo, hi=layout.hi)
        spec = signal_spec(layout.offset, field)
    elif isinstance(layout, lkp._Choice):
        spec = signal_spec(layout.offset, EnumByte("value", layout.enum_cls))
    else:  # pragma: no cover - a new ValueLayout kind: describe it here
        raise TypeError(f"no signal for the LK parameter layout {layout!r}")
    assert spec is not None
    return (spec,)


def _setting_mux(with_values: bool) -> Mux:
    """V2.36 setting parameters: DATA[1] is a group (0x05: single values, addressed by DATA[2]; 0xA0,
    0xA4, 0xA8: PID groups, values from DATA[2]) (spec §6.2, ``params.decode_setting_address``)."""
    singles = [p for p in SettingParam if p >> 8 == 0x05]
    single_layouts = tuple(
        Layout(
            p & 0xFF,
            p.name,
            _value_signals(SETTING_LAYOUTS[p]) if with_values else (),
            implies=(("param", p.name),),
        )
        for p in singles
    )
    groups = [
        Layout(
            0x05,
            "SINGLE_VALUE",
            mux=Mux(le_signal("param", 2, 1, choices=_choices(single_layouts)), single_layouts),
        )
    ]
    for p in SettingParam:
        if p >> 8 != 0x05:
            signals = _value_signals(SETTING_LAYOUTS[p]) if with_values else ()
            groups.append(Layout(p >> 8, p.name, signals, implies=(("param", p.name),)))
    layouts = tuple(groups)
    return Mux(le_signal("param_group", 1, 1, choices=_choices(layouts)), layouts)


def _param_mux(params: type[enum.IntEnum], layouts: Mapping[Any, Any] | None) -> Mux:
    """A parameter byte at DATA[1] multiplexing each parameter's value layout."""
    subs = _param_layouts(params, layouts)
    return Mux(le_signal("param", 1, 1, choices=_choices(subs)), subs)


def _choices(layouts: Iterable[Layout]) -> tuple[tuple[int, str], ...]:
    return tuple((layout.code, layout.name) for layout in layouts if layout.code is not None)


def lk_fields(cls: type, code: int | None, model: Any) -> tuple[tuple[Any, ...], Mux | None, str | None]:
    """Where an LK message class puts its fields, for ``model``: ``(offset, field object)`` pairs, a
    parameter multiplexer under DATA[0] (or None), and why the class cannot be described (or None).

    The offsets are those the classes' ``encode``/``decode`` write (spec §4, §6, §8); the field objects
    are the LK modules' own, so scales and ranges are the codec's.
    """
    motor_type = model.motor_type

    def encoder(name: str) -> IntField:
        return IntField(name, size=2, hi=encoder_max_count(model.encoder_bits))

    def iq(slot: Any, limits: tuple[int, int] | None = None) -> Any:
        field = _iq(slot, motor_type, limits)
        return (
            _NotCarried(f"{slot.amps_name}: {motor_type.name} motors do not carry it")
            if field is None
            else field
        )

    def items(field: Any, count: int) -> list[Any]:
        return [field] * count if isinstance(field, _NotCarried) else _items(field, count)

    direction = EnumByte("direction", states.SpinDirection)
    # The status-2 shape's DATA[2..3] depends on the command byte too: what it is (0xA0's power on every
    # motor type, ``replies.status2_slot``) and its range (``replies.torque_range``).
    status2_iq = rep.torque_range(model.revision, motor_type, code) if code is not None else None
    status2_slot = rep.status2_slot(code) if code is not None else rep.REPLY_IQ
    table: dict[type, tuple[Any, ...] | Mux] = {
        rep.Status2Reply: (
            (1, rep.TEMPERATURE),
            (2, iq(status2_slot, status2_iq)),
            (4, rep.REPLY_SPEED),
            (6, encoder("encoder_counts")),
        ),
        cmd.BrakeControl: ((1, EnumByte("action", states.BrakeAction)),),
        cmd.WriteEncoderOffset: ((cmd.ENCODER_OFFSET_AT, encoder("offset_counts")),),
        cmd.WriteAcceleration: ((4, cmd.ACCELERATION),),
        ctl.OpenLoopControl: ((4, ctl.POWER),),
        ctl.TorqueControl: ((4, iq(ctl.TORQUE)),),
        ctl.SpeedControl: ((2, iq(ctl.TORQUE_LIMIT)), (4, ctl.SPEED)),
        ctl.SpeedControlV235: ((4, ctl.SPEED),),
        ctl.MultiTurnPosition: ((4, ctl.ANGLE),),
        ctl.MultiTurnPositionSpeed: ((2, ctl.MAX_SPEED), (4, ctl.ANGLE)),
        ctl.SingleTurnPosition: ((1, direction), (4, ctl.SINGLE_TURN)),
        ctl.SingleTurnPositionV235: ((1, direction), (4, ctl.SINGLE_TURN_V235)),
        ctl.SingleTurnPositionSpeed: ((1, direction), (2, ctl.MAX_SPEED), (4, ctl.SINGLE_TURN)),
        ctl.SingleTurnPositionSpeedV235: ((1, direction), (2, ctl.MAX_SPEED), (4, ctl.SINGLE_TURN_V235)),
        ctl.IncrementalPosition: ((4, ctl.INCREMENT),),
        ctl.IncrementalPositionSpeed: ((2, ctl.MAX_SPEED), (4, ctl.INCREMENT)),
        ctl.MultiMotorTorque: tuple(zip((0, 2, 4, 6), items(iq(ctl.MULTI_TORQUE), 4), strict=True)),
        p236.ReadControlParam: ((1, EnumByte("param", lkp.ControlParam)),),
        p236.WriteControlParam: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
        p236.ControlParamReply: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
        p236.ReadSetting: _setting_mux(with_values=False),
        p236.WriteSetting: _setting_mux(with_values=True),
        p236.SettingReply: _setting_mux(with_values=True),
        p236.SaveSettingsReply: ((2, ResultByte("result", lkp.SAVE_RESULT)),),
        p235.ReadParam: ((1, EnumByte("param", lkp.ParamId)),),
        p235.WriteParamRam: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.WriteParamRom: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.ParamReply: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.ParamWriteReply: (
            (1, EnumByte("param", lkp.ParamId)),
            (2, ResultByte("result", lkp.WRITE_RESULT_V235)),
        ),
        rep.Status1Reply: (
            (1, rep.TEMPERATURE),
            (2, rep.VOLTAGE),
            (4, rep.BUS_CURRENT),
            (6, EnumByte("motor_state", states.MotorState)),
            (7, FlagsByte("error_state", states.ErrorState)),
        ),
        rep.Status1ReplyV235: (
            (1, rep.TEMPERATURE),
            (3, rep.VOLTAGE_V235),
            (7, FlagsByte("error_state", states.ErrorStateV235)),
        ),
        rep.Status3Reply: ((1, rep.TEMPERATURE), *zip((2, 4, 6), items(iq(rep.PHASE), 3), strict=True)),
        rep.Status3ReplyV235: tuple(zip((2, 4, 6), _items(rep.PHASE_V235, 3), strict=True)),
        rep.BrakeReply: ((1, EnumByte("state", states.BrakeState)),),
        rpos.EncoderReply: (
            (2, encoder("encoder_counts")),
            (4, encoder("raw_counts")),
            (6, encoder("offset_counts")),
        ),
        rpos.CalibrationReply: (
            (1, rpos.ALIGN_VALUE),
            (5, rpos.ALIGN_RATIO),
            (7, FlagsByte("align_state", states.AlignState)),
        ),
        rpos.EncoderOffsetReply: ((6, encoder("offset_counts")),),
        rpos.MultiTurnAngleReply: ((1, rpos.MULTI_TURN),),
        rpos.SingleTurnAngleReply: ((4, rpos.CIRCLE),),
        rpos.SingleTurnAngleReplyV235: ((6, rpos.CIRCLE_V235),),
        rpos.AccelerationReply: ((4, rpos.ACCELERATION),),
    }
    entry = table.get(cls, ())
    if isinstance(entry, Mux):
        return (), entry, None
    missing = next((f for _, f in entry if isinstance(f, _NotCarried)), None)
    if missing is not None:
        return (), None, missing.why
    return entry, None, None


@dataclass(frozen=True, slots=True)
class _NotCarried:
    """A field the motor type does not carry (MS has no torque loop): the class is left out."""

    why: str


#: Fixed bytes of LK layouts (spec §4.29): 0x44 ``05 FA`` (request) and ``05 flag`` (reply).
LK_CONSTANTS: Mapping[str, tuple[tuple[int, int], ...]] = {
    "SaveSettings": ((1, 0x05), (2, 0xFA)),
    "SaveSettingsReply": ((1, 0x05),),
}


def _lk_layout(cls: type, code: int, model: Any, what: str, left_out: list[str]) -> Layout | None:
    fields, mux, why = lk_fields(cls, code, model)
    name = cls.__name__
    if why is not None:
        left_out.append(f"{what} 0x{code:02X} ({name}): {why}")
        return None
    signals = []
    for offset, field in fields:
        spec = signal_spec(offset, field)
        assert spec is not None  # LK has no text fields
        signals.append(spec)
    implies = (("command", code),) if "command" in {f.name for f in dataclasses.fields(cls)} else ()
    return Layout(code, name, tuple(signals), LK_CONSTANTS.get(name, ()), mux, message=name, implies=implies)


def _describe(query: DbcQuery) -> Described:
    ids, direction = query.ids, query.direction
    model, encoder_bits = query.options.get("model"), query.options.get("encoder_bits")
    rev = cast(Revision | None, query.revision)
    if isinstance(model, str):
        try:
            motor_type = MotorType[model.upper()]
        except KeyError:
            raise ValueError(f"lk has no motor type {model!r} (known: MS, MF, MH, MG)") from None
        model = LkModel(
            revision=rev or Revision.V2_36, motor_type=motor_type, encoder_bits=encoder_bits or 14
        )
    elif model is None:
        model = LkModel(revision=rev or Revision.V2_36, encoder_bits=encoder_bits or 14)
    elif encoder_bits is not None and encoder_bits != model.encoder_bits:
        raise ValueError(f"encoder_bits={encoder_bits} contradicts model.encoder_bits={model.encoder_bits}")
    model = resolve_model(rev, model)
    rev = model.revision
    left_out: list[str] = []
    requests = tuple(
        layout
        for code, cls in sorted(REQUESTS[rev].items())
        if (layout := _lk_layout(cls, code, model, "request", left_out)) is not None
    )
    replies = tuple(
        layout
        for code, cls in sorted(REPLY_CLASSES[rev].items())
        if (layout := _lk_layout(cls, code, model, "reply", left_out)) is not None
    )
    what = f"LK {rev.name} ({model.motor_type.name}, {model.encoder_bits}-bit encoder)"
    # V2.35 replies come on the request's identifier (spec §1.1): one DBC holds one of the two.
    shared = rev is Revision.V2_35 and direction is None
    if shared:
        left_out.append(
            "requests on 0x140+ID: V2.35 motors reply on the request's identifier and a DBC has one message "
            "per identifier, so 0x140+ID describes the replies (a request frame there decodes as a reply); "
            "--direction request gives the requests' DBC"
        )
    messages = []
    for motor_id in ids:
        motor = f"motor_{motor_id}"
        if not shared:
            messages.append(
                MessageSpec(
                    request_id(motor_id),
                    f"lk_request_{motor_id}",
                    8,
                    "request",
                    muxed(requests),
                    ("host",),
                    f"{what} requests to motor {motor_id}, multiplexed on DATA[0]",
                    motor_id=motor_id,
                )
            )
        messages.append(
            MessageSpec(
                reply_id(motor_id, rev),
                f"lk_reply_{motor_id}",
                8,
                "reply",
                muxed(replies),
                (motor,),
                f"{what} replies of motor {motor_id}, multiplexed on DATA[0]",
                motor_id=motor_id,
            )
        )
    if rev in ctl.MultiMotorTorque.REVISIONS:
        fields, _, why = lk_fields(ctl.MultiMotorTorque, None, model)
        if why is not None:
            left_out.append(f"request id 0x280 (MultiMotorTorque): {why}")
        else:
            signals = tuple(s for offset, f in fields if (s := signal_spec(offset, f)) is not None)
            messages.append(
                MessageSpec(
                    MULTI_MOTOR_ID,
                    "lk_multi_motor",
                    8,
                    "request",
                    Layout(None, "", signals, message="MultiMotorTorque"),
                    ("host",),
                    f"{what} torque set-points of motors 1..4 (layout inferred, spec §5); each replies "
                    "on 0x140+ID with a 0xA1 status-2 reply",
                )
            )
    return Described(revision=rev, messages=tuple(messages), left_out=tuple(left_out))


DBC = DbcFamily(
    summary=(
        "per motor its requests (0x140+ID) and replies (0x180+ID; V2.35 replies share 0x140+ID, so that "
        "DBC holds the replies unless --direction request), parameter frames multiplexed again on their "
        "parameter byte; V2.35's 0x280"
    ),
    options=(
        DbcOption(name="model", help="the motor type MS, MF, MH or MG (or an LkModel) [MG]"),
        DbcOption(name="encoder_bits", help="the encoder width, 14, 15, 16 or 18 [14]", parse=int),
    ),
    describe=_describe,
)

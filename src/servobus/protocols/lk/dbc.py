"""The LK DBC part (``FAMILY.part("dbc")``): what its classes' declarations do not say.

V2.36 and V2.35, per motor its requests (0x140 + ID) and replies (0x180 + ID; V2.35 replies share
0x140 + ID, so that DBC holds the replies unless the requests are asked for), multiplexed on DATA[0];
parameter frames are multiplexed again on their parameter byte (V2.36 settings: a group byte, then the
parameter); V2.35's 0x280 multi-motor torque frame. Options: ``model`` (an ``LkModel`` or a motor type
MS, MF, MH, MG; default MG) and ``encoder_bits`` (14, 15, 16, 18; default 14).

The DATA[0] values are the family's commands and their declared replies (``request_keys``,
``reply_keys``); a class's fields are its declarations (``FIELDS`` and the model-dependent
``MODEL_FIELDS``) read for the motor type and encoder width (:func:`lk_fields`); only the parameter
frames, whose value sits where their key says, are stated here (``params.py``'s ``*_LAYOUTS``).
``tests/test_dbc_export.py`` decodes frames of every LK class both ways and compares every field.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable, Iterable, Mapping
from typing import Any, cast

from servobus.protocols._fields import IntField
from servobus.protocols.dbc import (
    DbcFamily,
    DbcOption,
    DbcQuery,
    Described,
    EnumByte,
    FlagsByte,
    Keyed,
    Layout,
    MessageSpec,
    Mux,
    ResultByte,
    SignalSpec,
    le_signal,
    muxed,
    reply_keys,
    request_keys,
    signal_spec,
)
from servobus.protocols.lk import FAMILY
from servobus.protocols.lk import commands_control as ctl
from servobus.protocols.lk import params as lkp
from servobus.protocols.lk import params_v235 as p235
from servobus.protocols.lk import params_v236 as p236
from servobus.protocols.lk import replies as rep
from servobus.protocols.lk._base import (
    CommandField,
    EncoderCountField,
    FlagByteField,
    IqField,
    MemberField,
    TupleField,
)
from servobus.protocols.lk.codec import resolve_model
from servobus.protocols.lk.ids import MULTI_MOTOR_ID, reply_id, request_id
from servobus.protocols.lk.model import LkModel, MotorType, Revision, encoder_max_count
from servobus.protocols.lk.params import SETTING_LAYOUTS, ResultField, SettingParam

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
    if isinstance(layout, lkp.PidLayout):
        return tuple(
            le_signal(f"value.{gain}", offset, 2, minimum=0, maximum=layout.hi)
            for gain, offset in (("kp", 2), ("ki", 4), ("kd", 6))
        )
    if isinstance(layout, lkp.IntLayout):
        field = IntField("value", size=layout.size, signed=layout.signed, lo=layout.lo, hi=layout.hi)
        spec = signal_spec(layout.offset, field)
    elif isinstance(layout, lkp.ChoiceLayout):
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


#: Classes whose payload is not a fixed layout (a parameter frame's value sits where its key says):
#: a parameter multiplexer under DATA[0], or their fields.
_PARAMETERS: Mapping[type, Callable[[], tuple[tuple[int, Any], ...] | Mux]] = {
    p236.ReadControlParam: lambda: ((1, EnumByte("param", lkp.ControlParam)),),
    p236.WriteControlParam: lambda: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
    p236.ControlParamReply: lambda: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
    p236.ReadSetting: lambda: _setting_mux(with_values=False),
    p236.WriteSetting: lambda: _setting_mux(with_values=True),
    p236.SettingReply: lambda: _setting_mux(with_values=True),
    p235.ReadParam: lambda: ((1, EnumByte("param", lkp.ParamId)),),
    p235.WriteParamRam: lambda: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
    p235.WriteParamRom: lambda: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
    p235.ParamReply: lambda: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
}


def lk_fields(cls: type, code: int | None, model: Any) -> tuple[tuple[Any, ...], Mux | None, str | None]:
    """Where an LK message class puts its fields, for ``model``: ``(offset, field object)`` pairs, a
    parameter multiplexer under DATA[0] (or None), and why the class cannot be described (or None).

    A fixed layout's fields are its declarations (``all_fields()``: ``FIELDS`` and ``MODEL_FIELDS``),
    each as the field the motor needs: an encoder count within ``model.encoder_bits``; an iq value
    (``IqField``) in amperes or counts by ``model.motor_type``, the status-2 reply's range by its command
    byte (``replies.torque_range``), a motor type without it leaving the class out; a tuple value as its
    items. The ``command`` byte of a shared reply layout is the multiplexer's (implied). Parameter frames
    are :data:`_PARAMETERS`.
    """
    parameters = _PARAMETERS.get(cls)
    if parameters is not None:
        entry = parameters()
        return ((), entry, None) if isinstance(entry, Mux) else (entry, None, None)
    out: list[tuple[int, Any]] = []
    for offset, field in cls.all_fields():  # type: ignore[attr-defined]
        if isinstance(field, CommandField):
            continue
        if isinstance(field, EncoderCountField):
            out.append((offset, IntField(field.name, size=2, hi=encoder_max_count(model.encoder_bits))))
        elif isinstance(field, IqField):
            slot = field.slot_of(code)
            limits = None
            if cls is rep.Status2Reply and code is not None:
                limits = rep.torque_range(model.revision, model.motor_type, code)
            iq = _iq(slot, model.motor_type, limits)
            if iq is None:
                return (), None, f"{slot.amps_name}: {model.motor_type.name} motors do not carry it"
            items = _items(iq, len(field.labels)) if field.labels else [iq]
            out += [(offset + 2 * i, item) for i, item in enumerate(items)]
        elif isinstance(field, TupleField):
            items = _items(field.item, len(field.labels))
            out += [(offset + i * field.item.size, item) for i, item in enumerate(items)]
        elif isinstance(field, MemberField):
            out.append((offset, EnumByte(field.name, field.members, field.size)))
        elif isinstance(field, FlagByteField):
            out.append((offset, FlagsByte(field.name, field.flags)))
        elif isinstance(field, ResultField):
            out.append((offset, ResultByte(field.name, field.table)))
        else:
            out.append((offset, field))
    return tuple(out), None, None


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
    constants = tuple(getattr(cls, "CONSTANTS", ()))
    return Layout(code, name, tuple(signals), constants, mux, message=name, implies=implies)


def _layouts(keys: list[Keyed], model: Any, what: str, left_out: list[str]) -> tuple[Layout, ...]:
    """The layouts of the classes each DATA[0] value selects (one per value in LK)."""
    out = []
    for key in sorted(keys, key=lambda k: k.code):
        layout = _lk_layout(key.cls, key.code, model, what, left_out)
        if layout is not None:
            out.append(layout)
    return tuple(out)


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
    requests = _layouts(request_keys(FAMILY.commands, rev), model, "request", left_out)
    replies = _layouts(reply_keys(FAMILY.commands, rev), model, "reply", left_out)
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

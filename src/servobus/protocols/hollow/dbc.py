"""The hollow DBC part (``FAMILY.part("dbc")``): its frames are C-core bit layouts, not field tables.

Per motor its requests on the motor id and one reply message on the host id, in one CAN mode (option
``can_mode``: ``normal``, ``extended`` or ``fd``; they share the identifiers): each frame's class
declares its bits and scales (``FIELDS``, ``SIZE``: a :class:`~servobus.protocols.bits.BitLayout`,
as a plug-in's would), read for the motor model by :func:`servobus.protocols.dbc.bit_signals`:
``Setpoint``/``NormalReply`` (normal mode), ``IncrementalSetpoint``/``ExtendedReply`` (extended
mode), ``FdCommand``/``FdReply`` (CAN FD, 16 bytes). The extended-id frames (CAN
mode switch, PI multiplier) are laid out in their classes' code; :func:`hollow_config` states them.
Options: ``model`` (a ``HollowModel`` or a name of ``hollow.MODELS``), ``host_id`` (default 100).
"""

from __future__ import annotations

import functools
from typing import Any

from servobus.protocols import hollow as ho
from servobus.protocols.dbc import (
    DbcFamily,
    DbcOption,
    DbcQuery,
    Described,
    Layout,
    MessageSpec,
    Mux,
    SignalSpec,
    bit_signals,
    enum_choices,
)
from servobus.protocols.hollow import CanMode, PiGain
from servobus.protocols.hollow.ids import check_host_id, check_motor_id

__all__ = ["CAN_MODES", "DBC", "hollow_config"]

CAN_MODES = ("normal", "extended", "fd")
#: The request and the reply on the motor and host ids in each CAN mode: DBC message name and class.
_FRAMES: dict[str, tuple[tuple[str, type[Any]], tuple[str, type[Any]]]] = {
    "normal": (("setpoint", ho.Setpoint), ("reply", ho.NormalReply)),
    "extended": (("increment", ho.IncrementalSetpoint), ("ext_reply", ho.ExtendedReply)),
    "fd": (("fd_command", ho.FdCommand), ("fd_reply", ho.FdReply)),
}


def _serial_only() -> list[str]:
    """The commands no CAN link carries (their ``LINKS``), and their replies: the DBC has none of them."""
    commands = [c for c in ho.FAMILY.commands if not any(link.startswith("can") for link in _links(c))]
    return list(
        dict.fromkeys(c.__name__ for c in (*commands, *(r for c in commands for r in c.reply_types())))
    )


def _links(cls: type) -> tuple[str, ...]:
    links: tuple[str, ...] = getattr(cls, "LINKS", ()) or ho.FAMILY.links
    return links


@functools.cache
def hollow_config() -> Mux:
    """The hollow extended-id frames (§5.1, §6), laid out in ``CanModeSwitch``/``PiMultiplier`` code:
    DATA[1] tells them apart (0: the mode switch, whose D0 bit 1 is the mode; 1..4: the PI gain whose
    multiplier is a big-endian float32 at DATA[2..5]), as ``commands.decode_extended_request`` does."""
    mode = SignalSpec("mode", 1, 1, choices=enum_choices(CanMode))  # D0 bit 1 (§5.1, A4)
    multiplier = SignalSpec("multiplier", 8 * 2 + 7, 32, "big_endian", signed=True, is_float=True, minimum=0)
    layouts = [Layout(0, "CanModeSwitch", (mode,), message="CanModeSwitch")]
    layouts += [
        Layout(
            int(g),
            f"PiMultiplier_{g.name}",
            (multiplier,),
            message="PiMultiplier",
            implies=(("gain", g.name),),
        )
        for g in PiGain
    ]
    return Mux(SignalSpec("gain", 8, 8), tuple(layouts))


def _describe(query: DbcQuery) -> Described:
    ids = query.ids
    model, can_mode, host_id = (query.options.get(k) for k in ("model", "can_mode", "host_id"))
    rev = query.revision if query.revision is not None else ho.FAMILY.default_revision
    if model is None:
        model = ho.DEFAULT_MODEL
    elif isinstance(model, str):
        if model not in ho.MODELS:
            raise ValueError(f"hollow has no model {model!r} (known: {', '.join(ho.MODELS)})")
        model = ho.MODELS[model]
    mode = can_mode or "normal"
    if mode not in CAN_MODES:
        raise ValueError(f"can_mode={mode!r} is not one of {', '.join(CAN_MODES)}")
    host = check_host_id(ho.DEFAULT_HOST_ID if host_id is None else host_id)
    for motor_id in ids:
        check_motor_id(motor_id)
    if host in ids:
        raise ValueError(f"motor id {host} is the host id the replies go to: give another --host-id")
    left_out = [
        f"RS-485 converter frames (transparent, Modbus RTU, configuration: {', '.join(_serial_only())}): "
        "serial frames, not CAN",
    ]
    if mode != "fd":
        left_out.append(
            "special commands FF x7 + F9..FE (Start, Stop, SelectMode, SetZero): told apart from a setpoint "
            "by a 7-byte pattern, not a multiplexer value; the DBC reads them as setpoints"
        )
    if mode == "extended":
        left_out.append(
            "ExtendedReply position_deg as one signal: its 32-bit code is split (low half DATA[1..2], "
            "high half DATA[6..7]), so it is two signals whose values add up to it (position_deg_b0 + "
            "position_deg_b16)"
        )
    # Each frame: its message name, and its class's declared fields and SIZE.
    request, reply = ((name, cls.SIZE, bit_signals(cls, model), cls.__name__) for name, cls in _FRAMES[mode])
    others = [m for m in CAN_MODES if m != mode]
    left_out.append(
        f"the {' and '.join(others)} frames: they use the same identifiers (the motor id for requests, the "
        "host id for replies) and a DBC has one message per identifier; --can-mode gives their DBC"
    )
    what = f"hollow {rev.name} ({model.name} model"
    if mode != "fd":
        what += f": ±{model.position_full_scale_deg} deg, ±{model.speed_full_scale_rad_s} rad/s, "
        what += f"±{model.current_full_scale_a} A)"
    else:
        what += f", {model.pole_pairs} pole pairs)"
    fd = mode == "fd"
    messages = []
    config = Layout(None, "", mux=hollow_config())
    for motor_id in ids:
        name, length, signals, message = request
        messages.append(
            MessageSpec(
                motor_id,
                f"hollow_{name}_{motor_id}",
                length,
                "request",
                Layout(None, "", signals, message=message),
                ("host",),
                f"{what} {mode}-mode {message} to motor {motor_id}",
                fd=fd,
                motor_id=motor_id,
            )
        )
        messages.append(
            MessageSpec(
                motor_id,
                f"hollow_config_{motor_id}",
                8,
                "request",
                config,
                ("host",),
                f"hollow CAN mode switch and PI multiplier frames to motor {motor_id} (extended id), "
                "multiplexed on DATA[1]",
                extended=True,
                motor_id=motor_id,
            )
        )
    name, length, signals, message = reply
    messages.append(
        MessageSpec(
            host,
            f"hollow_{name}",
            length,
            "reply",
            Layout(None, "", signals, message=message),
            tuple(f"motor_{i}" for i in ids),
            f"{what} {mode}-mode replies of every motor, on the host id (the motor id is in the frame)",
            fd=fd,
        )
    )
    return Described(revision=rev, messages=tuple(messages), left_out=tuple(left_out))


DBC = DbcFamily(
    summary=(
        "per motor its requests (on the motor id; can_mode normal, extended or fd: they share the ids) "
        "and the mode-switch/PI frames (extended id), and one reply message on the host id"
    ),
    options=(
        DbcOption(name="model", help="the motor model, a name of hollow.MODELS (default, 3507) [default]"),
        DbcOption(name="can_mode", help="normal, extended or fd: which frames share the ids [normal]"),
        DbcOption(name="host_id", help="the identifier replies go to [100]", parse=int),
    ),
    describe=_describe,
)

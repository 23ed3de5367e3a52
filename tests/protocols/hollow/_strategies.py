"""Hypothesis strategies for the hollow family's typed messages (physical values within range)."""

from __future__ import annotations

from hypothesis import strategies as st

from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    MODEL_3507,
    CanMode,
    CanModeSwitch,
    ControlMode,
    ConverterGain,
    ConverterPdGains,
    ConverterPiMultiplier,
    ExtendedReply,
    FdCommand,
    FdReply,
    HollowModel,
    IncrementalSetpoint,
    NormalReply,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    Start,
    Stop,
)
from servobus.protocols.hollow.commands_fd import fd_position_limits_deg, fd_velocity_limits_rpm
from servobus.protocols.hollow.replies import EXTENDED_POSITION_LIMITS_DEG

# A few models, so scaling is exercised beyond the defaults without building packers per example.
MODELS = [
    DEFAULT_MODEL,
    MODEL_3507,
    HollowModel(
        name="wide", pmax_turns=2.5, speed_full_scale_rad_s=45.0, current_full_scale_a=33.0, pole_pairs=7
    ),
]
models = st.sampled_from(MODELS)


def offset_binary_top(full_scale: float, bits: int) -> float:
    """The value of the last code of an offset-binary field: +full scale is one code past it."""
    half = 1 << (bits - 1)
    return full_scale * (half - 1) / half


def reals(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False)


@st.composite
def setpoint_values(draw: st.DrawFn, model: HollowModel) -> dict[str, object]:
    pos = model.position_full_scale_deg
    spd = model.speed_full_scale_rad_s
    cur = model.current_full_scale_a
    gains = st.integers(0, 0xFFF)
    return {
        "speed_rad_s": draw(reals(-spd, offset_binary_top(spd, 12))),
        "kp": draw(gains),
        "kd": draw(gains),
        "current_a": draw(reals(-cur, offset_binary_top(cur, 12))),
        "position": draw(reals(-pos, offset_binary_top(pos, 16))),
        "model": model,
    }


@st.composite
def setpoints(draw: st.DrawFn) -> Setpoint:
    values = draw(setpoint_values(draw(models)))
    return Setpoint(position_deg=values.pop("position"), **values)  # type: ignore[arg-type]


@st.composite
def incremental_setpoints(draw: st.DrawFn) -> IncrementalSetpoint:
    values = draw(setpoint_values(draw(models)))
    return IncrementalSetpoint(step_deg=values.pop("position"), **values)  # type: ignore[arg-type]


special_commands = st.one_of(
    st.just(Start()),
    st.just(Stop()),
    st.just(SetZero()),
    st.sampled_from(ControlMode).map(lambda mode: SelectMode(mode=mode)),
)
mode_switches = st.sampled_from(CanMode).map(lambda mode: CanModeSwitch(mode=mode))
float32s = st.floats(min_value=0.0, allow_nan=False, allow_infinity=False, width=32)
pi_multipliers = st.builds(PiMultiplier, gain=st.sampled_from(PiGain), multiplier=float32s)


@st.composite
def fd_commands(draw: st.DrawFn) -> FdCommand:
    model = draw(models)
    return FdCommand(
        position_deg=draw(reals(*fd_position_limits_deg())),
        velocity_rpm=draw(reals(*fd_velocity_limits_rpm(model))),
        current_raw=draw(st.integers(-(1 << 15), (1 << 15) - 1)),
        mode=draw(st.sampled_from(ControlMode)),
        run=draw(st.booleans()),
        kp=draw(st.integers(0, 255)),
        kd=draw(st.integers(0, 255)),
        zero=draw(st.booleans()),
        model=model,
    )


@st.composite
def fd_replies(draw: st.DrawFn) -> FdReply:
    model = draw(models)
    return FdReply(
        position_deg=draw(reals(*fd_position_limits_deg())),
        velocity_rpm=draw(reals(*fd_velocity_limits_rpm(model))),
        current_raw=draw(st.integers(-(1 << 15), (1 << 15) - 1)),
        mode=draw(st.sampled_from(ControlMode)),
        running=draw(st.booleans()),
        reserved=draw(st.integers(0, 255)),
        temperature_c=draw(st.integers(-125, 125)),  # manual §VII: -125..125 °C
        slave_id=draw(st.integers(0, 100)),
        model=model,
    )


@st.composite
def normal_replies(draw: st.DrawFn) -> NormalReply:
    model = draw(models)
    pos = model.position_full_scale_deg
    spd = model.speed_full_scale_rad_s
    cur = model.current_full_scale_a
    return NormalReply(
        motor_id=draw(st.integers(0, 100)),
        position_deg=draw(reals(-pos, offset_binary_top(pos, 16))),
        speed_rad_s=draw(reals(-spd, offset_binary_top(spd, 12))),
        current_a=draw(reals(-cur, offset_binary_top(cur, 12))),
        model=model,
    )


@st.composite
def extended_replies(draw: st.DrawFn) -> ExtendedReply:
    model = draw(models)
    spd = model.speed_full_scale_rad_s
    cur = model.current_full_scale_a
    return ExtendedReply(
        motor_id=draw(st.integers(0, 100)),
        position_deg=draw(reals(*EXTENDED_POSITION_LIMITS_DEG)),
        speed_rad_s=draw(reals(-spd, offset_binary_top(spd, 12))),
        current_a=draw(reals(-cur, offset_binary_top(cur, 12))),
        model=model,
    )


converter_configs = st.one_of(
    st.builds(ConverterPdGains, p=st.integers(0, 255), d=st.integers(0, 255), header=st.sampled_from([0, 1])),
    st.builds(
        ConverterPiMultiplier,
        gain=st.sampled_from(ConverterGain),
        multiplier=float32s,
        header=st.sampled_from([0, 1]),
    ),
)

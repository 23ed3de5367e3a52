"""decode_request / decode_reply dispatch by frame kind, the Family, and random bytes (hollow.md §3-§7)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import get_family
from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    FAMILY,
    MODEL_3507,
    CanMode,
    CanModeSwitch,
    ExtendedReply,
    FdCommand,
    FdReply,
    HollowCommand,
    HollowReply,
    IncrementalSetpoint,
    NormalReply,
    PiMultiplier,
    Revision,
    Setpoint,
    SpecialCommand,
    decode_reply,
    decode_request,
)
from servobus.protocols.hollow.codec import (
    decode_reply_frame,
    decode_request_frame,
    reply_frame,
    request_frame,
)

from .._contract import decodes_or_protocol_error
from ._strategies import (
    extended_replies,
    fd_commands,
    fd_replies,
    incremental_setpoints,
    mode_switches,
    normal_replies,
    pi_multipliers,
    setpoints,
    special_commands,
)

can_requests = st.one_of(setpoints(), special_commands, mode_switches, pi_multipliers, fd_commands())
can_replies = st.one_of(normal_replies(), extended_replies(), fd_replies())


def _model_of(message: object) -> object:
    return getattr(message, "model", DEFAULT_MODEL)


@given(can_requests, st.integers(0, 100))
def test_every_request_decodes_from_its_frame(command: HollowCommand, motor_id: int) -> None:
    frame = request_frame(motor_id, command)
    decoded = decode_request_frame(frame, model=_model_of(command))  # type: ignore[arg-type]
    assert type(decoded) is type(command)
    assert decoded.encode() == frame.data
    if isinstance(command, SpecialCommand | CanModeSwitch | PiMultiplier):
        assert decoded == command


@given(incremental_setpoints(), st.integers(0, 100))
def test_setpoints_decode_by_the_motors_can_mode(command: IncrementalSetpoint, motor_id: int) -> None:
    frame = request_frame(motor_id, command)
    decoded = decode_request_frame(frame, model=command.model, can_mode=CanMode.EXTENDED)
    assert isinstance(decoded, IncrementalSetpoint) and decoded.encode() == frame.data
    assert isinstance(decode_request_frame(frame, model=command.model), Setpoint)


@given(can_replies, st.integers(0, 0x7FF))
def test_every_reply_decodes_from_its_frame(reply: HollowReply, host_id: int) -> None:
    frame = reply_frame(host_id, reply)
    decoded = decode_reply_frame(frame, model=_model_of(reply))  # type: ignore[arg-type]
    assert type(decoded) is type(reply) and decoded.encode() == frame.data


def test_reply_kind_follows_the_length() -> None:
    assert isinstance(decode_reply(100, bytes([1, 0x80, 0, 0x80, 0x08, 0])), NormalReply)
    assert isinstance(decode_reply(100, bytes([1, 0, 0, 0x80, 0x08, 0, 0, 0])), ExtendedReply)
    assert isinstance(decode_reply(100, bytes(15) + b"\x01", is_fd=True), FdReply)
    with pytest.raises(ProtocolError, match="expected 6 or 8 data bytes, got 7"):
        decode_reply(100, bytes(7))
    with pytest.raises(ProtocolError, match="CAN FD reply: expected 16 data bytes, got 8"):
        decode_reply(100, bytes(8), is_fd=True)
    with pytest.raises(ProtocolError, match="not a standard identifier"):
        decode_reply(100, bytes(6), is_extended_id=True)


def test_request_kind_follows_the_frame() -> None:
    assert isinstance(decode_request(1, bytes(8)), Setpoint)
    assert isinstance(decode_request(1, bytes(8), can_mode=CanMode.EXTENDED), IncrementalSetpoint)
    assert isinstance(decode_request(1, bytes(8), is_extended_id=True), CanModeSwitch)
    assert isinstance(
        decode_request(1, bytes.fromhex("00 02 3F 80 00 00"), is_extended_id=True), PiMultiplier
    )
    # A17: a PI frame may come as an FD extended frame.
    assert isinstance(
        decode_request(1, bytes.fromhex("00 02 3F 80 00 00 00 00"), is_extended_id=True, is_fd=True),
        PiMultiplier,
    )
    assert isinstance(decode_request(1, bytes(16), is_fd=True), FdCommand)
    with pytest.raises(ProtocolError, match="standard-id request: expected 8 data bytes, got 6"):
        decode_request(1, bytes(6))
    with pytest.raises(ProtocolError, match="CAN FD request: expected 16 data bytes, got 8"):
        decode_request(1, bytes(8), is_fd=True)
    with pytest.raises(ProtocolError, match=r"request id 101 is not a motor id \(0..100\)"):
        decode_request(101, bytes(8))


def test_the_model_scales_decoding() -> None:
    frame = bytes.fromhex("C0 00 C0 01 00 02 0C 00")
    assert decode_request(1, frame).speed_rad_s == 100.0  # type: ignore[attr-defined]
    assert decode_request(1, frame, model=MODEL_3507).speed_rad_s == pytest.approx(58.639 / 2)  # type: ignore[attr-defined]


def test_revision_is_checked() -> None:
    assert FAMILY.revisions == (Revision.HO_SERIES,)
    assert FAMILY.revision("ho_series") is Revision.HO_SERIES
    with pytest.raises(ValueError, match="revision='V4_3' is not one of HO_SERIES"):
        decode_request(1, bytes(8), revision="V4_3")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="revision="):
        decode_reply(100, bytes(6), revision=None)  # type: ignore[arg-type]


def test_the_registry_loads_the_family() -> None:
    family = get_family("hollow")
    assert family is FAMILY and family.name == "hollow"
    assert family.decode_request is decode_request and family.decode_reply is decode_reply


def test_can_mode_must_be_a_can_mode() -> None:
    with pytest.raises(ValueError, match="can_mode='extended' is not a CanMode"):
        decode_request(1, bytes(8), can_mode="extended")  # type: ignore[arg-type]


# ---- random bytes: decoded or ProtocolError, nothing else ----

payloads = st.binary(min_size=0, max_size=16)
ids = st.integers(min_value=-1, max_value=0x1FFFFFFF)


@given(st.one_of(st.integers(0, 100), ids), payloads, st.booleans(), st.booleans(), st.sampled_from(CanMode))
def test_random_requests_decode_or_raise_protocol_error(
    can_id: int, data: bytes, extended: bool, fd: bool, can_mode: CanMode
) -> None:
    decodes_or_protocol_error(
        decode_request, can_id, data, is_extended_id=extended, is_fd=fd, can_mode=can_mode
    )


@given(ids, payloads, st.booleans(), st.booleans())
def test_random_replies_decode_or_raise_protocol_error(
    can_id: int, data: bytes, extended: bool, fd: bool
) -> None:
    decodes_or_protocol_error(decode_reply, can_id, data, is_extended_id=extended, is_fd=fd)


@given(st.integers(0, 100), st.binary(min_size=8, max_size=8), st.sampled_from(CanMode))
def test_random_classic_frames_decode_or_raise(can_id: int, data: bytes, can_mode: CanMode) -> None:
    for extended in (False, True):
        decodes_or_protocol_error(decode_request, can_id, data, is_extended_id=extended, can_mode=can_mode)
    decodes_or_protocol_error(decode_reply, 100, data)
    decodes_or_protocol_error(decode_reply, 100, data[:6])


@given(st.integers(0, 100), st.binary(min_size=16, max_size=16))
def test_random_fd_frames_decode_or_raise(can_id: int, data: bytes) -> None:
    decodes_or_protocol_error(decode_request, can_id, data, is_fd=True)
    decodes_or_protocol_error(decode_reply, 100, data, is_fd=True)
    decodes_or_protocol_error(decode_request_frame, Frame(arbitration_id=can_id, data=data, is_fd=True))

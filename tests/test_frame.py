"""Frame: the checks of its hand-written constructor, and serial-link messages."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import can
import pytest

from servobus import Frame
from servobus.transports.can import message_from_frame


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"arbitration_id": 0x800}, r"0x800 outside the standard range"),
        ({"arbitration_id": -1}, r"outside the standard range"),
        ({"arbitration_id": 0x20000000, "is_extended_id": True}, r"outside the extended range"),
        ({"arbitration_id": 1, "data": bytes(9)}, r"classic CAN data length 9"),
        ({"arbitration_id": 1, "data": bytes(9), "is_fd": True}, r"CAN FD data length 9"),
        ({"arbitration_id": 1, "bitrate_switch": True}, r"bitrate_switch needs is_fd"),
        ({"arbitration_id": 0x100, "is_serial": True}, r"address is one byte"),
        ({"arbitration_id": 1, "data": bytes(256), "is_serial": True}, r"exceeds 255"),
        ({"arbitration_id": 1, "is_serial": True, "is_fd": True}, r"no extended id, FD"),
        ({"arbitration_id": 1, "is_serial": True, "is_extended_id": True}, r"no extended id, FD"),
    ],
)
def test_bad_frames_are_refused(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Frame(**kwargs)  # type: ignore[arg-type]


def test_good_frames() -> None:
    assert Frame(arbitration_id=0x7FF, data=bytearray(8)).data == bytes(8)
    assert Frame(arbitration_id=0x1FFFFFFF, is_extended_id=True).arbitration_id == 0x1FFFFFFF
    assert len(Frame(arbitration_id=1, data=bytes(64), is_fd=True, bitrate_switch=True).data) == 64
    serial = Frame(arbitration_id=0xFF, data=bytes(41), is_serial=True)
    assert repr(serial).startswith("Frame(0x0FF s [")


def test_equality_ignores_time_and_direction_but_not_the_link() -> None:
    a = Frame(arbitration_id=3, data=b"\x01", timestamp=1.0, is_rx=False)
    assert a == Frame(arbitration_id=3, data=b"\x01") and hash(a) == hash(
        Frame(arbitration_id=3, data=b"\x01")
    )
    assert a != Frame(arbitration_id=3, data=b"\x01", is_serial=True)


def test_frozen_and_replace_checks_again() -> None:
    frame = Frame(arbitration_id=3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        frame.data = b"x"  # type: ignore[misc]
    with pytest.raises(ValueError, match="standard range"):
        dataclasses.replace(frame, arbitration_id=0x800)


def test_a_codecs_unchecked_request_frame_is_the_checked_one() -> None:
    from servobus.frame import classic_request

    fast = classic_request(0x141, bytes(range(8)))
    slow = Frame(arbitration_id=0x141, data=bytes(range(8)), is_rx=False)
    assert fast == slow and repr(fast) == repr(slow)
    assert [getattr(fast, f) for f in Frame.__slots__] == [getattr(slow, f) for f in Frame.__slots__]


_MESSAGE_FIELDS = (
    "arbitration_id",
    "is_extended_id",
    "is_fd",
    "bitrate_switch",
    "error_state_indicator",
    "is_remote_frame",
    "is_error_frame",
    "dlc",
    "timestamp",
    "is_rx",
)


@pytest.mark.parametrize(
    "frame",
    [
        Frame(arbitration_id=0x141, data=b"\x9c", timestamp=12.5, is_rx=False),
        Frame(arbitration_id=0x7FF, timestamp=1.0),
        Frame(arbitration_id=0x1ABCDEF0, data=bytes(range(8)), is_extended_id=True, timestamp=3.25),
        Frame(arbitration_id=0x241, data=bytes(range(64)), is_fd=True, bitrate_switch=True, timestamp=4.0),
        Frame(arbitration_id=0x1F, data=bytes(12), is_fd=True, error_state_indicator=True, is_rx=False),
    ],
    ids=["classic-tx", "empty", "extended", "fd-brs", "fd-esi"],
)
def test_a_frame_converts_to_a_python_can_message_and_back_exactly(frame: Frame) -> None:
    message = message_from_frame(frame)
    assert isinstance(message, can.Message)
    expected = {
        "arbitration_id": frame.arbitration_id,
        "is_extended_id": frame.is_extended_id,
        "is_fd": frame.is_fd,
        "bitrate_switch": frame.bitrate_switch,
        "error_state_indicator": frame.error_state_indicator,
        "is_remote_frame": False,
        "is_error_frame": False,
        "dlc": len(frame.data),
        "timestamp": frame.timestamp,
        "is_rx": frame.is_rx,
    }
    assert {name: getattr(message, name) for name in _MESSAGE_FIELDS} == expected
    assert bytes(message.data) == frame.data
    back = Frame.from_message(message)
    assert back == frame
    assert [getattr(back, f) for f in Frame.__slots__] == [getattr(frame, f) for f in Frame.__slots__]
    assert Frame.from_message(message, timestamp=99.0).timestamp == 99.0  # a clock of the caller's


def test_a_python_can_message_converts_with_its_own_flags() -> None:
    message = can.Message(
        timestamp=7.5,
        arbitration_id=0x18FF50E5,
        data=bytes(16),
        is_extended_id=True,
        is_fd=True,
        bitrate_switch=True,
        error_state_indicator=True,
        is_rx=False,
        channel="can0",
    )
    frame = Frame.from_message(message)
    assert (frame.arbitration_id, frame.data, frame.is_extended_id, frame.is_fd) == (
        0x18FF50E5,
        bytes(16),
        True,
        True,
    )
    assert (frame.bitrate_switch, frame.error_state_indicator, frame.timestamp, frame.is_rx) == (
        True,
        True,
        7.5,
        False,
    )
    assert message_from_frame(frame, channel="can0").equals(message)


@pytest.mark.parametrize(
    ("message", "match"),
    [
        (can.Message(arbitration_id=0x141, is_remote_frame=True, dlc=8, is_extended_id=False), "remote"),
        (can.Message(arbitration_id=0x4, is_error_frame=True, data=bytes(8)), "error frame"),
        (can.Message(arbitration_id=0x141, data=b"\x01", dlc=8, is_extended_id=False, check=False), "DLC 8"),
        (can.Message(arbitration_id=0x800, is_extended_id=False, check=False), "standard range"),
    ],
    ids=["remote", "error", "dlc", "id"],
)
def test_a_message_that_is_no_frame_does_not_convert(message: can.Message, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Frame.from_message(message)


def test_a_serial_message_has_no_python_can_form_and_esi_needs_fd() -> None:
    with pytest.raises(ValueError, match="serial-link"):
        message_from_frame(Frame(arbitration_id=1, data=b"\x9c", is_serial=True))
    with pytest.raises(ValueError, match="error_state_indicator needs is_fd"):
        Frame(arbitration_id=1, error_state_indicator=True)


def test_importing_frame_does_not_import_python_can() -> None:
    code = "import sys, servobus.frame; assert 'can' not in sys.modules, 'can imported'; print('ok')"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "ok", done.stderr

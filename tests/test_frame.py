"""Frame: the checks of its hand-written constructor, and serial-link messages."""

from __future__ import annotations

import dataclasses

import pytest

from servobus import Frame


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

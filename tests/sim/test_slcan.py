"""The simulated SLCAN adapter's side of the LAWICEL protocol (servobus.sim.slcan).

python-can's own slcan formatting is the independent implementation these frames are checked
against: what its ``send`` writes, the adapter parses; what the adapter writes, its reader parses.
"""

from __future__ import annotations

from typing import Any

import can
import can.interfaces.slcan
import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.sim.slcan import SlcanAdapter, format_frame, parse_frame


def _read_all(port: Any) -> bytes:
    """What python-can wrote to its loop:// port, every byte of it.

    python-can opens the port with a 1 ms read timeout, and pyserial's loop read checks that
    timeout on the wall clock after each byte: a thread descheduled for a millisecond on a loaded
    machine came back with part of the line (the race). Every byte is already queued when
    ``in_waiting`` counts it (the write is synchronous), so the read is made non-blocking
    (timeout 0): it takes exactly those bytes, with no clock involved."""
    waiting = port.in_waiting
    timeout = port.timeout
    port.timeout = 0
    try:
        return bytes(port.read(waiting))
    finally:
        port.timeout = timeout


def _python_can_slcan() -> can.BusABC:
    """python-can's slcan interface on pyserial's loopback port: what it writes, it reads back."""
    bus = can.Bus(interface="slcan", channel="loop://", sleep_after_open=0)
    port = bus.serialPortOrig  # type: ignore[attr-defined]
    assert _read_all(port) == b"O\r"  # opened the channel
    return bus


frames = st.one_of(
    st.builds(
        lambda i, d, x: Frame(arbitration_id=i, data=d, is_extended_id=x),
        st.integers(0, 0x7FF),
        st.binary(max_size=8),
        st.just(False),
    ),
    st.builds(
        lambda i, d: Frame(arbitration_id=i, data=d, is_extended_id=True),
        st.integers(0, 0x1FFFFFFF),
        st.binary(max_size=8),
    ),
    st.builds(
        lambda i, n, brs, x: Frame(
            arbitration_id=i if x else i & 0x7FF,
            data=bytes(n),
            is_fd=True,
            bitrate_switch=brs,
            is_extended_id=x,
        ),
        st.integers(0, 0x1FFFFFFF),
        st.sampled_from([0, 8, 12, 16, 64]),
        st.booleans(),
        st.booleans(),
    ),
)


@given(frames)
def test_python_can_sends_what_the_adapter_parses(frame: Frame) -> None:
    bus = _python_can_slcan()
    message = can.Message(
        arbitration_id=frame.arbitration_id,
        data=frame.data,
        is_extended_id=frame.is_extended_id,
        is_fd=frame.is_fd,
        bitrate_switch=frame.bitrate_switch,
    )
    bus.send(message)
    port = bus.serialPortOrig  # type: ignore[attr-defined]
    written = _read_all(port)
    bus.shutdown()
    adapter = SlcanAdapter(is_open=True)
    answer, sent = adapter.receive(written)
    assert sent == [frame]
    assert answer in (b"z\r", b"Z\r", b"\r")


@given(frames)
def test_python_can_reads_what_the_adapter_writes(frame: Frame) -> None:
    bus = _python_can_slcan()
    bus.serialPortOrig.write(format_frame(frame))  # type: ignore[attr-defined]
    message = bus.recv(timeout=1.0)
    bus.shutdown()
    assert message is not None
    assert (message.arbitration_id, bytes(message.data), message.is_extended_id, message.is_fd) == (
        frame.arbitration_id,
        frame.data,
        frame.is_extended_id,
        frame.is_fd,
    )
    assert message.bitrate_switch == frame.bitrate_switch
    assert parse_frame(format_frame(frame).decode()[:-1]) == (frame, False)


def test_the_hollow_manuals_setup_and_example_frames() -> None:
    adapter = SlcanAdapter(bitrate=None)
    answer, _ = adapter.receive(b"S8\rY5\rO\r\n")
    assert answer == b"\r\r\r"
    assert (adapter.bitrate, adapter.data_bitrate, adapter.is_open) == (1_000_000, 5_000_000, True)
    # spec hollow.md §8 "Examples for motor id 1"
    answer, sent = adapter.receive(
        b"t0018C000C00100020C00\rT000000018" + b"0" * 16 + b"\rb001A" + b"0" * 32 + b"\r"
    )
    assert answer == b"z\rZ\r\r"
    assert sent == [
        Frame(arbitration_id=1, data=bytes.fromhex("C000C00100020C00")),
        Frame(arbitration_id=1, data=bytes(8), is_extended_id=True),
        Frame(arbitration_id=1, data=bytes(16), is_fd=True, bitrate_switch=True),
    ]
    assert adapter.to_host(Frame(arbitration_id=0x64, data=bytes(6))) == b"t0646000000000000\r"


@pytest.mark.parametrize(
    ("setup", "line"),
    [
        (b"", b"t0018C000C00100020C00\r"),  # closed: no frames
        (b"L\r", b"t0010\r"),  # listen-only: no frames
        (b"O\r", b"S8\r"),  # open: no configuration
        (b"O\r", b"O\r"),  # already open
        (b"", b"S7x\r"),
        (b"", b"Y3\r"),
        (b"O\r", b"t0019" + b"00" * 9 + b"\r"),  # classic DLC 9
        (b"O\r", b"t0012AB\r"),  # DLC says 2 bytes, one given
        (b"O\r", b"t00G1AA\r"),
        (b"O\r", b"t0011\r"),
        (b"O\r", b"r0012AA\r"),
        (b"", b"?\r"),
    ],
)
def test_bad_or_misplaced_commands_answer_bel(setup: bytes, line: bytes) -> None:
    adapter = SlcanAdapter()
    adapter.receive(setup)
    answer, sent = adapter.receive(line)
    assert (answer, sent) == (b"\a", [])
    assert adapter.errors == 1


def test_info_commands_close_and_overlong_lines() -> None:
    adapter = SlcanAdapter(serial_number="AB12")
    assert adapter.receive(b"V\rN\rF\rZ1\r\r")[0] == b"V1013\rNAB12\rF00\r\r\r"
    assert adapter.timestamps
    adapter.receive(b"O\r")
    assert adapter.receive(b"C\r")[0] == b"\r" and not adapter.is_open
    assert adapter.to_host(Frame(arbitration_id=1)) == b""
    answer, _ = adapter.receive(b"t" + b"0" * 300 + b"\r")
    assert answer == b"\a" and adapter.discarded > 0
    assert adapter.receive(b"sABCD\r")[0] == b"\r" and adapter.bitrate is None


def test_the_hollow_vectors_for_the_usb_adapter_are_each_answered_ok() -> None:
    from _spec import hexbytes, load_vectors

    adapter_vectors = [v for v in load_vectors("hollow") if v["transport"] == "slcan-ascii"]
    assert [v["id"] for v in adapter_vectors] == ["H23", "H24", "H25"]
    adapter = SlcanAdapter(bitrate=None)
    for vector in adapter_vectors:  # in the manual's order: S8, Y5, then O
        assert adapter.receive(hexbytes(vector["data"]))[0] == b"\r", vector["id"]
    assert (adapter.bitrate, adapter.data_bitrate, adapter.is_open) == (1_000_000, 5_000_000, True)

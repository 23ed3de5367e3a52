"""CanTransport's own rules: python-can configuration, filters, error frames, ENOBUFS, gaps, load.

Traffic goes through python-can's ``virtual`` interface to a plain python-can peer; the ENOBUFS
and send-failure policies use a python-can bus whose ``send`` fails on cue.
"""

from __future__ import annotations

import errno
import itertools
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import anyio
import can
import pytest

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.transports import (
    BusOff,
    CanErrorClass,
    CanTransport,
    ErrorFrame,
    TransportEvent,
    TransportState,
)
from servobus.transports.can import frame_from_message, message_from_frame

from ._anyio_help import within

pytestmark = pytest.mark.anyio


@pytest.fixture
def peer(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


def _recv_all(bus: can.BusABC, n: int, timeout: float = 2.0) -> list[can.Message]:
    got = []
    while len(got) < n and (message := bus.recv(timeout)) is not None:
        got.append(message)
    return got


@pytest.fixture
def clean_config(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """No python-can configuration anywhere: an empty home and no CAN_* variables."""
    monkeypatch.setenv("HOME", str(tmp_path))
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)


def test_frames_convert_to_and_from_python_can_messages() -> None:
    frame = Frame(arbitration_id=0x1ABCDEF0, data=bytes(range(12)), is_extended_id=True, is_fd=True)
    message = message_from_frame(frame)
    assert (message.arbitration_id, bytes(message.data), message.is_extended_id, message.is_fd) == (
        0x1ABCDEF0,
        bytes(range(12)),
        True,
        True,
    )
    back = frame_from_message(message, 12.5)
    assert back == frame and back.timestamp == 12.5
    message.is_rx = False
    assert frame_from_message(message, 0.0).is_rx is False  # our own echo stays marked


@pytest.mark.usefixtures("clean_config")
async def test_the_adapter_comes_from_python_cans_environment_configuration(
    monkeypatch: pytest.MonkeyPatch, channel: str, peer: can.BusABC
) -> None:
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    monkeypatch.setenv("CAN_CHANNEL", channel)
    monkeypatch.setenv("CAN_BITRATE", "500000")
    async with CanTransport() as transport:
        assert transport.config["interface"] == "virtual" and transport.bitrate == 500_000
        transport.send(Frame(arbitration_id=0x141, data=b"\x9c"))
        (message,) = await anyio.to_thread.run_sync(_recv_all, peer, 1)
        assert message.arbitration_id == 0x141
        assert transport.stats().bus_load_pct is not None


@pytest.mark.usefixtures("clean_config")
async def test_a_canrc_file_is_read_and_arguments_win_over_it(tmp_path: Path, channel: str) -> None:
    (tmp_path / ".canrc").write_text(
        f"[default]\ninterface = virtual\nchannel = {channel}\nbitrate = 250000\n"
    )
    assert CanTransport().config["bitrate"] == 250_000
    assert CanTransport(bitrate=1_000_000).bitrate == 1_000_000
    assert "bitrate" not in CanTransport("virtual", channel, ignore_config=True).config


@pytest.mark.usefixtures("clean_config")
def test_no_interface_anywhere_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="CAN interface"):
        CanTransport()
    with pytest.raises(ValueError, match="enobufs"):
        CanTransport("virtual", "x", enobufs="block", ignore_config=True)  # type: ignore[arg-type]


async def test_fd_frames_need_an_fd_bus(channel: str) -> None:
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        with pytest.raises(ValueError, match="fd=True"):
            transport.send(Frame(arbitration_id=0x1, data=bytes(16), is_fd=True))


async def test_serial_messages_never_go_to_a_can_adapter(channel: str) -> None:
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        with pytest.raises(ValueError, match="serial-link message"):
            transport.send(Frame(arbitration_id=0x1, data=bytes(8), is_serial=True))


async def test_receive_ids_filter_what_arrives(channel: str, peer: can.BusABC) -> None:
    async with CanTransport("virtual", channel, ignore_config=True, receive_ids=[0x241, 0x242]) as transport:
        for can_id in (0x240, 0x241, 0x243, 0x242):
            peer.send(can.Message(arbitration_id=can_id, data=b"\x01", is_extended_id=False))
        got = [await within(1.0, transport.receive()) for _ in range(2)]
        assert [f.arbitration_id for f in got] == [0x241, 0x242]
        transport.set_receive_ids(None)
        peer.send(can.Message(arbitration_id=0x243, data=b"\x02", is_extended_id=False))
        assert (await within(1.0, transport.receive())).arbitration_id == 0x243
        with pytest.raises(ValueError, match="outside"):
            transport.set_receive_ids([0x800])


async def test_error_frames_and_bus_off_become_events_and_remote_frames_are_dropped(
    channel: str, peer: can.BusABC
) -> None:
    events: list[TransportEvent] = []
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        transport.add_listener(events.append)
        peer.send(
            can.Message(is_error_frame=True, arbitration_id=0x004, data=bytes([0, 0x10, 0, 0, 0, 0, 0, 0]))
        )
        peer.send(can.Message(is_error_frame=True, arbitration_id=0x040, data=bytes(8)))
        peer.send(can.Message(is_remote_frame=True, arbitration_id=0x141, dlc=8, is_extended_id=False))
        peer.send(can.Message(arbitration_id=0x241, data=b"\x01", is_extended_id=False))
        frame = await within(1.0, transport.receive())
        assert frame.arbitration_id == 0x241
        stats = transport.stats()
    errors = [e for e in events if isinstance(e, ErrorFrame)]
    assert [e.classes for e in errors] == [CanErrorClass.CONTROLLER, CanErrorClass.BUS_OFF]
    assert errors[0].data[1] == 0x10
    assert sum(isinstance(e, BusOff) for e in events) == 1
    assert (stats.error_frames, stats.bus_off, stats.ignored, stats.frames_in) == (2, 1, 1, 1)


async def test_min_gap_spaces_the_frames_on_the_wire(channel: str, peer: can.BusABC) -> None:
    async with CanTransport("virtual", channel, ignore_config=True, min_gap_s=0.01) as transport:
        for i in range(5):
            transport.send(Frame(arbitration_id=0x141, data=bytes([i])))
        await transport.drain()
    times = [m.timestamp for m in await anyio.to_thread.run_sync(_recv_all, peer, 5)]
    assert min(b - a for a, b in itertools.pairwise(times)) >= 0.009


async def test_bus_load_counts_frames_both_ways_at_the_configured_bit_rate(
    channel: str, peer: can.BusABC
) -> None:
    async with CanTransport("virtual", channel, ignore_config=True, bitrate=1_000_000) as transport:
        for _ in range(100):
            transport.send(Frame(arbitration_id=0x141, data=bytes(8)))
        await transport.drain()
        for _ in range(100):
            peer.send(can.Message(arbitration_id=0x241, data=bytes(8), is_extended_id=False))
        for _ in range(100):
            await within(1.0, transport.receive())
        load = transport.stats().bus_load_pct
    # 200 unstuffed 8-byte standard frames of 111 bits at 1 Mbit/s within the last second.
    assert load == pytest.approx(100 * 200 * 111e-6, rel=1e-6)
    async with CanTransport("virtual", channel, ignore_config=True) as unknown:
        assert unknown.stats().bus_load_pct is None


class _FlakyBus(can.BusABC):
    """A python-can bus whose sends fail as the test says; receives nothing."""

    sent: ClassVar[list[can.Message]] = []
    failures: ClassVar[list[can.CanError]] = []

    def __init__(self, channel: Any = None, **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.failures:
            raise self.failures.pop(0)
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        time.sleep(timeout or 0)
        return None, False


@pytest.fixture
def flaky(monkeypatch: pytest.MonkeyPatch) -> type[_FlakyBus]:
    _FlakyBus.sent = []
    _FlakyBus.failures = []
    monkeypatch.setattr(can, "Bus", lambda **config: _FlakyBus(**config))
    return _FlakyBus


def _enobufs() -> can.CanOperationError:
    return can.CanOperationError("Failed to transmit: [Errno 105] No buffer space available", errno.ENOBUFS)


async def test_enobufs_wait_policy_retries_until_the_adapter_takes_the_frame(flaky: type[_FlakyBus]) -> None:
    flaky.failures = [_enobufs(), _enobufs(), can.CanOperationError("Transmit buffer full")]
    async with CanTransport(
        "flaky", "x", ignore_config=True, enobufs="wait", enobufs_timeout_s=0.5
    ) as transport:
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
        await transport.drain()
        stats = transport.stats()
    assert [bytes(m.data) for m in flaky.sent] == [b"\x01"]
    assert (stats.enobufs_waits, stats.enobufs_dropped, stats.frames_out) == (3, 0, 1)


async def test_enobufs_drop_policy_and_wait_timeout_drop_and_count(flaky: type[_FlakyBus]) -> None:
    flaky.failures = [_enobufs()]
    async with CanTransport("flaky", "x", ignore_config=True, enobufs="drop") as transport:
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
        transport.send(Frame(arbitration_id=0x141, data=b"\x02"))
        await transport.drain()
        assert transport.stats().enobufs_dropped == 1
    flaky.failures = [_enobufs() for _ in range(10_000)]
    async with CanTransport(
        "flaky", "x", ignore_config=True, enobufs="wait", enobufs_timeout_s=0.01
    ) as transport:
        transport.send(Frame(arbitration_id=0x141, data=b"\x03"))
        await transport.drain()
        stats = transport.stats()
    assert [bytes(m.data) for m in flaky.sent] == [b"\x02"]
    assert stats.enobufs_dropped == 1 and stats.enobufs_waits > 1


async def test_any_other_send_failure_is_a_loss_and_the_bus_is_reopened(flaky: type[_FlakyBus]) -> None:
    flaky.failures = [
        # (ENETDOWN is bus-off, a state of the bus: tests/transports/test_send_errors.py)
        can.CanOperationError("Failed to transmit: [Errno 19] No such device", errno.ENODEV)
    ]
    async with CanTransport("flaky", "x", ignore_config=True, reopen_backoff_s=(0.01, 0.01)) as transport:
        states: list[TransportState] = []
        transport.add_listener(lambda e: states.append(e.state) if hasattr(e, "state") else None)
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
        await anyio.sleep(0.1)  # the writer thread fails, the loss is reported, a reopen follows
        await transport.wait_open(timeout=2.0)
        transport.send(Frame(arbitration_id=0x141, data=b"\x02"))
        await transport.drain()
        stats = transport.stats()
    assert states[:2] == [TransportState.LOST, TransportState.OPEN]
    assert (stats.losses, stats.reopens) == (1, 1)
    assert [bytes(m.data) for m in flaky.sent] == [b"\x02"]


# ---- what python-can's readers and adapters get wrong, handled here (issue 14) ----


def test_a_message_whose_dlc_disagrees_with_its_data_does_not_convert() -> None:
    message = can.Message(arbitration_id=0x123, data=b"\x11\x22\x33", check=False)
    message.dlc = 8  # what python-can's slcan reader builds from "t1238112233\r"
    with pytest.raises(ValueError, match="DLC 8 but 3 data bytes"):
        frame_from_message(message, 0.0)


async def test_virtual_sends_are_written_from_send_itself_and_reported(
    channel: str, peer: can.BusABC
) -> None:
    reports: list[tuple[Frame, float | None, str | None]] = []
    async with CanTransport("virtual", channel, ignore_config=True) as transport:
        transport.set_send_reporter(lambda frame, at, why: reports.append((frame, at, why)))
        frame = Frame(arbitration_id=0x141, data=b"\x9c" + bytes(7))
        transport.send(frame)  # no await between: written before send() returned
        assert [(f, why) for f, _, why in reports] == [(frame, None)]
        assert transport.stats().frames_out == 1 and transport.stats().queue_depth == 0
    (message,) = _recv_all(peer, 1)
    assert bytes(message.data) == frame.data


def _stalled() -> can.CanOperationError:
    import serial

    error = can.CanOperationError("could not send message")
    error.__cause__ = serial.SerialTimeoutException("Write timeout")
    return error


async def test_a_stalled_adapter_is_backpressure_not_a_lost_device(flaky: type[_FlakyBus]) -> None:
    flaky.failures = [_stalled(), _stalled()]
    async with CanTransport(
        "flaky", "x", ignore_config=True, enobufs="wait", enobufs_timeout_s=0.5
    ) as transport:
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
        await transport.drain()
        stats = transport.stats()
        assert transport.is_open
    assert [bytes(m.data) for m in flaky.sent] == [b"\x01"]
    assert (stats.losses, stats.enobufs_waits, stats.frames_out) == (0, 2, 1)


class _ParseErrorBus(_FlakyBus):
    """Receives what the test queues: a Message, or an exception python-can's reader would raise."""

    incoming: ClassVar[list[can.Message | BaseException]] = []

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self.incoming:
            time.sleep(timeout or 0)
            return None, False
        item = self.incoming.pop(0)
        if isinstance(item, BaseException):
            raise item
        return item, False


async def test_frames_python_can_cannot_parse_are_counted_and_reading_goes_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    good = can.Message(arbitration_id=0x241, data=b"\x9c" + bytes(7), is_extended_id=False)
    short = can.Message(arbitration_id=0x242, data=b"\x01", is_extended_id=False, check=False)
    short.dlc = 8
    _ParseErrorBus.incoming = [
        IndexError("string index out of range"),
        good,
        ValueError("non-hex"),
        short,
        good,
    ]
    monkeypatch.setattr(can, "Bus", lambda **config: _ParseErrorBus(**config))
    async with CanTransport("parse", "x", ignore_config=True) as transport:
        frames = [await within(2.0, transport.receive()) for _ in range(2)]
        stats = transport.stats()
        assert transport.is_open
    assert [f.arbitration_id for f in frames] == [0x241, 0x241]
    assert (stats.bad_frames, stats.losses) == (3, 0)


async def test_a_malformed_slcan_line_on_a_real_pty_is_one_bad_frame_not_a_lost_adapter() -> None:
    import os

    master, slave = os.openpty()
    try:
        async with CanTransport(
            "slcan", os.ttyname(slave), bitrate=1_000_000, ignore_config=True, sleep_after_open=0
        ) as transport:
            await anyio.sleep(0.05)
            os.read(master, 1024)  # the open sequence python-can wrote
            os.write(master, b"t12\r" + b"t12311\r" + b"t2418" + b"9C" + b"00" * 7 + b"\r")
            frame = await within(2.0, transport.receive())
            assert frame == Frame(arbitration_id=0x241, data=b"\x9c" + bytes(7))
            # A peer that never ends its line (written from a thread: the pty holds only a few KiB).
            await anyio.to_thread.run_sync(os.write, master, b"x" * 100_000)
            await anyio.sleep(0.2)
            stats = transport.stats()
            assert transport.is_open
            assert len(transport.bus._buffer) <= 200  # type: ignore[union-attr]
        assert stats.bad_frames >= 3 and stats.losses == 0 and stats.discarded_bytes > 90_000
    finally:
        os.close(master)
        os.close(slave)


async def test_the_virtual_fast_send_hands_every_listener_its_own_message(channel: str) -> None:
    first = can.Bus(interface="virtual", channel=channel)
    second = can.Bus(interface="virtual", channel=channel)
    try:
        async with CanTransport("virtual", channel, ignore_config=True) as transport:
            transport.send(Frame(arbitration_id=0x141, data=b"\x01\x02"))
            a, b = first.recv(1.0), second.recv(1.0)
            assert a is not None and b is not None and a is not b and a.data is not b.data
            for message in (a, b):
                assert (message.arbitration_id, bytes(message.data), message.is_rx) == (
                    0x141,
                    b"\x01\x02",
                    True,
                )
                assert message.channel == channel and message.timestamp > 0
    finally:
        first.shutdown()
        second.shutdown()


async def test_a_full_virtual_listener_queue_is_a_failed_send_not_a_blocked_loop(channel: str) -> None:
    peer = can.Bus(interface="virtual", channel=channel, rx_queue_size=1)
    try:
        async with CanTransport("virtual", channel, ignore_config=True, reopen=False) as transport:
            transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
            with pytest.raises(TransportError, match=r"device lost \(Could not send"):
                transport.send(Frame(arbitration_id=0x141, data=b"\x02"))
    finally:
        peer.shutdown()

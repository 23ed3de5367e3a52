"""SlcanTransport (the native SLCAN link) through real ptys: the simulator's SLCAN adapter with
simulated motors, and a raw pty whose far end injects what a broken adapter might send.

Regression tests of issue 14 for the native transport: a malformed line leaves it OPEN with the bad
frame counted; 1 MiB without CR costs bounded memory and well under 100 ms of loop time; a DLC that
disagrees with the data is counted and dropped; a stalled adapter is backpressure (nothing written
late, no spinning), not a lost device. Unplug, reopen and the rest of the transport contract run
over this transport in test_contract.py (the ``native-slcan`` path).
"""

from __future__ import annotations

import contextlib
import os
import time
import tty
from collections.abc import AsyncIterator

import anyio
import pytest

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.ids import reply_id, request_id
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_slcan
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter
from servobus.transports import SlcanTransport, TransportState, create_transport
from servobus.transports.slcan import encode_line

from ._anyio_help import serving

pytestmark = pytest.mark.anyio

GOOD = b"t2418" + b"9C" + b"00" * 7 + b"\r"


class RawAdapter:
    """The far end of a raw pty: answers the open sequence (or not), then injects bytes at will and
    reads (or stops reading) what the host writes."""

    def __init__(self, answer: bytes = b"\r", refuse: bytes = b"") -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.commands: list[bytes] = []
        self._answer = answer
        self._refuse = refuse
        self._buf = b""

    async def answer_open(self) -> None:
        """Answer each command line until O (or L) has been answered; read nothing after it."""
        while True:
            await anyio.wait_readable(self.master)
            self._buf += os.read(self.master, 4096)
            while b"\r" in self._buf:
                line, self._buf = self._buf.split(b"\r", 1)
                self.commands.append(line)
                if self._answer:
                    os.write(self.master, b"\a" if line == self._refuse else self._answer)
                if line in (b"O", b"L"):
                    return

    def inject(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.master, view) :]
            except BlockingIOError:
                time.sleep(0.0005)  # the host has not read yet

    def read_all(self) -> bytes:
        out = b""
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(self.master, 65536):
                out += chunk
        return out

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


@contextlib.asynccontextmanager
async def raw_open(**options: object) -> AsyncIterator[tuple[SlcanTransport, RawAdapter]]:
    adapter = RawAdapter()
    transport = SlcanTransport(adapter.path, reopen=False, **options)  # type: ignore[arg-type]
    try:
        async with anyio.create_task_group() as answering:
            answering.start_soon(adapter.answer_open)
            await transport.open()  # answered up to O before it returns
            assert adapter.commands == [b"C", b"S8", b"O"]
            try:
                yield transport, adapter
            finally:
                await transport.close()
                answering.cancel_scope.cancel()
    finally:
        adapter.close()


async def receive_n(transport: SlcanTransport, n: int, timeout: float = 2.0) -> list[Frame]:
    frames: list[Frame] = []
    with anyio.fail_after(timeout):
        while len(frames) < n:
            frames += await transport.receive_batch()
    return frames


# ---- with simulated motors ----


async def test_round_trips_with_thirty_two_simulated_motors(tmp_path: object) -> None:
    network = SimCanNetwork([MyActuatorMotor(i) for i in range(1, 33)])
    port = PtyPort()
    async with (
        serving(serve_slcan(network, port)),
        create_transport("slcan", port.path, bitrate=1_000_000) as transport,
    ):
        assert isinstance(transport, SlcanTransport)
        for _ in range(3):  # three control ticks: 32 requests, 32 replies each
            for motor_id in range(1, 33):
                transport.send(Frame(arbitration_id=request_id(motor_id), data=ma.ReadStatus2().encode()))
            replies = await receive_n(transport, 32)
            assert sorted(f.arbitration_id for f in replies) == [reply_id(i) for i in range(1, 33)]
            for frame in replies:
                reply = ma.decode_reply(frame.arbitration_id, frame.data)
                assert isinstance(reply, ma.StatusReply) and reply.temperature_c > 0
        stats = transport.stats()
        assert (stats.frames_out, stats.frames_in, stats.bad_frames, stats.discarded_bytes) == (
            96,
            96,
            0,
            0,
        )
        assert stats.bus_load_pct is not None and stats.bus_load_pct > 0
        counters = transport.line_counters()
        assert counters["acks"] == 96 and counters["bells"] == 0  # every line acknowledged, none refused
    port.close()


async def test_can_fd_frames_go_out_and_come_back(tmp_path: object) -> None:
    from sim._standins import Responder

    port = PtyPort()
    adapter = SlcanAdapter()
    async with (
        serving(serve_slcan(SimCanNetwork([Responder(1)]), port, adapter)),
        SlcanTransport(port.path, bitrate=1_000_000, data_bitrate=5_000_000) as transport,
    ):
        assert adapter.data_bitrate == 5_000_000
        frame = Frame(arbitration_id=0x141, data=bytes(range(48)), is_fd=True, bitrate_switch=True)
        transport.send(frame)
        (reply,) = await receive_n(transport, 1)
        assert reply == Frame(arbitration_id=0x241, data=bytes(range(48)), is_fd=True)
    port.close()


def test_lines_are_lawicel() -> None:
    assert encode_line(Frame(arbitration_id=0x141, data=b"\x9c\x01")) == b"t14129C01\r"
    assert encode_line(Frame(arbitration_id=0x1ABCDEF, is_extended_id=True)) == b"T01ABCDEF0\r"
    fd = Frame(arbitration_id=0x7FF, data=bytes(12), is_fd=True, bitrate_switch=True)
    assert encode_line(fd) == b"b7FF9" + b"00" * 12 + b"\r"
    assert encode_line(Frame(arbitration_id=1, data=bytes(64), is_fd=True, is_extended_id=True)).startswith(
        b"D00000001F"
    )


def test_arguments_are_checked_in_one_line() -> None:
    with pytest.raises(ValueError, match=r"^bitrate=750000 is not an SLCAN rate \(one of \[10000, "):
        SlcanTransport("/dev/null", bitrate=750_000)
    with pytest.raises(ValueError, match="data_bitrate=3000000"):
        SlcanTransport("/dev/null", data_bitrate=3_000_000)
    with pytest.raises(ValueError, match="min_gap_s"):
        SlcanTransport("/dev/null", min_gap_s=-1)
    transport = SlcanTransport("/dev/null")
    with pytest.raises(ValueError, match="CAN FD frame"):
        transport.send(Frame(arbitration_id=1, is_fd=True))
    with pytest.raises(ValueError, match="serial-link message"):
        transport.send(Frame(arbitration_id=1, is_serial=True))


# ---- what a broken adapter sends ----


async def test_a_malformed_line_is_one_bad_frame_and_the_transport_stays_open() -> None:
    """Issue 14: ``t12\\r`` made CanTransport declare python-can's slcan adapter lost."""
    async with raw_open() as (transport, adapter):
        adapter.inject(b"t12\r" + b"t12311\r" + b"zz\r" + b"t8000\r" + GOOD)
        (frame,) = await receive_n(transport, 1)
        assert frame == Frame(arbitration_id=0x241, data=bytes.fromhex("9C") + bytes(7))
        stats = transport.stats()
        assert stats.state is TransportState.OPEN
        assert (stats.bad_frames, stats.losses, stats.frames_in) == (4, 0, 1)
        transport.send(Frame(arbitration_id=0x141, data=b"\x01"))
        await transport.drain()
        await anyio.sleep(0.01)
        assert adapter.read_all() == b"t141101\r"


async def test_a_dlc_that_disagrees_with_the_data_is_counted_and_dropped() -> None:
    """Issue 14: python-can delivered ``t1238112233`` as a frame of the wrong length."""
    async with raw_open() as (transport, adapter):
        adapter.inject(
            b"t1238112233\r" + b"t1232AABBCC\r" + b"t1230AA\r" + b"t1239" + b"00" * 9 + b"\r" + GOOD
        )
        frames = await receive_n(transport, 1)
        await anyio.sleep(0.02)
        assert frames == [Frame(arbitration_id=0x241, data=bytes.fromhex("9C") + bytes(7))]
        assert transport.stats().bad_frames == 4 and transport.state is TransportState.OPEN


async def test_one_mebibyte_without_cr_costs_bounded_memory_and_little_loop_time() -> None:
    """Issue 14: python-can's line buffer grew without bound and held the loop for over a minute."""
    async with raw_open() as (transport, adapter):
        feed_s: list[float] = []
        pending: list[int] = []
        on_bytes = transport._on_bytes

        def timed(data: bytes, generation: int) -> None:
            started = time.perf_counter()
            on_bytes(data, generation)
            feed_s.append(time.perf_counter() - started)
            pending.append(transport.line_counters()["pending"])

        transport._on_bytes = timed  # type: ignore[method-assign]
        blob = b"t" + b"0123456789ABCDEF" * (1 << 16)
        async with anyio.create_task_group() as writer:
            writer.start_soon(anyio.to_thread.run_sync, adapter.inject, blob + b"\r" + GOOD)
            (frame,) = await receive_n(transport, 1, timeout=10.0)
        assert frame.arbitration_id == 0x241
        assert sum(len(b) for b in [blob]) >= 1 << 20
        assert sum(feed_s) < 0.1, f"{sum(feed_s) * 1000:.1f} ms of loop time for 1 MiB"
        assert max(pending) <= 138  # never more than the longest valid line held
        counters = transport.line_counters()
        assert (counters["overlong"], counters["discarded_bytes"]) == (1, len(blob) + 1)
        stats = transport.stats()
        assert (stats.state, stats.bad_frames, stats.losses) == (TransportState.OPEN, 1, 0)


async def test_remote_frames_replies_and_bells_are_counted_not_delivered() -> None:
    async with raw_open() as (transport, adapter):
        adapter.inject(b"r1230\rR000001230\r\az\rZ\r\r" + GOOD)
        await receive_n(transport, 1)
        await anyio.sleep(0.02)
        counters = transport.line_counters()
        assert (counters["remote"], counters["bells"], counters["acks"]) == (2, 1, 2)
        stats = transport.stats()
        assert (stats.ignored, stats.bad_frames, stats.frames_in) == (2, 0, 1)


# ---- a stalled adapter: backpressure, freshness, no spinning ----


async def test_a_stalled_adapter_is_backpressure_and_nothing_is_written_late() -> None:
    """The far end stops reading: the kernel fills, the writer waits without spinning, frames that
    wait longer than stale_after_s are dropped (counted and reported), the transport stays OPEN, and
    what finally reaches the adapter is exactly what was counted as sent, whole lines only."""
    async with raw_open(stale_after_s=0.2, queue_size=4096) as (transport, adapter):
        reports: list[tuple[int, float | None, str | None]] = []
        transport.set_send_reporter(lambda frame, at, why: reports.append((frame.data[0], at, why)))
        sent_ids = 0

        def send_some(n: int) -> None:
            nonlocal sent_ids
            for _ in range(n):
                transport.send(Frame(arbitration_id=0x141, data=sent_ids.to_bytes(4, "big")))
                sent_ids += 1

        send_some(2000)  # ~30 KB of lines: more than a pty takes
        await anyio.sleep(0.05)
        stats = transport.stats()
        assert 0 < stats.frames_out < 2000 and stats.queue_depth + stats.frames_out <= 2000
        cpu = time.process_time()
        await anyio.sleep(0.5)  # stalled for longer than stale_after_s
        assert time.process_time() - cpu < 0.15, "the writer spins while the adapter is stalled"
        assert transport.state is TransportState.OPEN
        written_before = transport.stats().frames_out
        received = adapter.read_all()  # the adapter wakes up
        for _ in range(50):
            await anyio.sleep(0.01)
            received += adapter.read_all()
        stats = transport.stats()
        assert stats.stale > 0 and stats.losses == 0
        assert stats.frames_out + stats.stale == 2000 and stats.queue_depth == 0
        lines = received.split(b"\r")
        assert lines[-1] == b""  # whole lines only
        assert len(lines) - 1 == stats.frames_out
        assert stats.frames_out - written_before <= 1  # at most the line cut mid-way went out later
        assert sum(1 for _, at, why in reports if why == "stale") == stats.stale
        assert sum(1 for _, at, _ in reports if at is not None) == stats.frames_out


# ---- opening ----


async def test_an_adapter_that_refuses_the_bit_rate_fails_the_open() -> None:
    adapter = RawAdapter(refuse=b"S8")
    try:
        async with anyio.create_task_group() as answering:
            answering.start_soon(adapter.answer_open)
            transport = SlcanTransport(adapter.path, reopen=False)
            with pytest.raises(TransportError, match=r"refused 'S8' \(BEL\)"):
                await transport.open()
            assert transport.state is TransportState.CLOSED
            answering.cancel_scope.cancel()
    finally:
        adapter.close()


async def test_a_port_that_answers_nothing_fails_the_open_within_the_timeout() -> None:
    adapter = RawAdapter(answer=b"")
    try:
        transport = SlcanTransport(adapter.path, reopen=False, open_timeout_s=0.1)
        started = time.monotonic()
        with pytest.raises(TransportError, match="no answer to 'C'"):
            await transport.open()
        assert time.monotonic() - started < 1.0
    finally:
        adapter.close()


async def test_a_missing_port_is_a_transport_error() -> None:
    with pytest.raises(TransportError, match="cannot open"):
        await SlcanTransport("/dev/nonexistent-slcan", reopen=False).open()

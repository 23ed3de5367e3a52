"""One contract over every path: SLCAN on a pty (python-can's and native), RS485 on a pty, CAN FD on
the virtual bus, and the in-process simulated bus; and the link's side of the FrameLink contract
(servobus.transports.contract) over every in-process link type, on asyncio and on trio.

The path tests run over each path of tests/transports/_paths.py, on asyncio and on trio in real
time (real I/O: ptys, python-can's virtual bus); the unplug and reopen tests over the pty paths,
where a device can really vanish. The link tests (below the paths) run every in-process link:
SimTransport in both clock lanes, a SimTransport subclass that sends a copy of each frame, the
recording tap around a SimTransport, and LinkBase links (one of them copying too), in virtual time.
The Bus's side (its time-outs with a copying link) is tests/transports/test_contract_bus.py.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from collections.abc import Callable
from pathlib import Path

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.tools.recording import TapLink
from servobus.transports import SimTransport, TransportState, TransportStats
from servobus.transports.base import Transport as LinkBase
from servobus.transports.contract import FrameLink, LineRules
from sim._standins import Responder

from ._anyio_help import within
from ._paths import PATHS, LinePath, open_path

PTY_PATHS = ("slcan", "rs485", "native-slcan")
SHORT_SOAK = 2_000
LONG_SOAK = 100_000


async def soak(path: LinePath, n: int, *, window: int = 32) -> None:
    """Send ``n`` numbered requests (``window`` in flight) and check every reply, in order, once.

    Checks order and uniqueness frame by frame (a reply's number must be the next expected one),
    completeness by count, and content by a CRC-32 over every payload on both sides.
    """
    transport = path.transport
    sent_crc = received_crc = 0
    sent = received = 0
    while received < n:
        while sent < n and sent - received < window and transport.queue_room:
            path.request(sent)
            sent += 1
        for reply in await within(5.0, transport.receive_batch()):
            data = path.reply_payload(reply)
            assert path.seq_of(data) == received, f"reply {path.seq_of(data)} where {received} was due"
            received_crc = zlib.crc32(data, received_crc)
            received += 1
    for data in path.peer_seen():
        sent_crc = zlib.crc32(data, sent_crc)
    assert len(path.peer_seen()) == n
    assert received_crc == sent_crc
    stats = transport.stats()
    assert (stats.frames_out, stats.frames_in) == (n, n)
    assert (stats.stale, stats.purged, stats.rx_overflow, stats.queue_full) == (0, 0, 0, 0)
    assert (stats.discarded_bytes, stats.crc_errors) == (0, 0)


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PATHS)
async def test_requests_are_answered_through_the_real_path(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path) as path:
        path.request(7)
        reply = await within(2.0, path.transport.receive())
        assert path.seq_of(path.reply_payload(reply)) == 7
        assert abs(reply.timestamp - anyio.current_time()) < 1.0  # the loop's clock
        stats = path.transport.stats()
        assert stats.state is TransportState.OPEN
        assert stats.frames_in == stats.frames_out == 1 and stats.bytes_in > 0
        assert stats.bytes_out == stats.bytes_in


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PATHS)
async def test_no_frame_lost_duplicated_or_reordered_short(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path) as path:
        await soak(path, SHORT_SOAK)


@pytest.mark.slow
@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PATHS)
async def test_no_frame_lost_duplicated_or_reordered_over_100k_frames(name: str, tmp_path: Path) -> None:
    async with open_path(name, tmp_path, queue_size=1024) as path:
        started = time.perf_counter()
        await soak(path, LONG_SOAK)
        print(f"{name}: {LONG_SOAK} round trips in {time.perf_counter() - started:.1f} s")


async def _stall_writer(path: LinePath) -> None:
    """Leave frames queued, unanswered, so a drain() stays pending (no device has id 9).

    RS485 holds the line for each frame's reply; the slcan paths are opened with a long gap.
    """
    for seq in range(3):
        if path.name == "rs485":
            frame = Frame(arbitration_id=9, data=bytes([seq, 0, 0, 0, 0, 0, 0, 0]), is_serial=True)
            path.transport.send(frame, reply_timeout_s=5.0)
        else:
            path.transport.send(Frame(arbitration_id=0x149, data=bytes([seq])))


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PTY_PATHS)
async def test_unplug_fails_every_pending_waiter_within_100_ms(name: str, tmp_path: Path) -> None:
    # slcan (both): keep frames queued for a while
    options = {"min_gap_s": 0.5} if name in ("slcan", "native-slcan") else {}
    async with open_path(name, tmp_path, reopen=False, **options) as path:
        transport = path.transport
        await _stall_writer(path)
        calls = [transport.receive] * 3 + [transport.receive_batch, transport.drain]
        results: list[object] = [None] * len(calls)
        ended = [False] * len(calls)

        async def wait(i: int) -> None:
            try:
                results[i] = await calls[i]()
            except Exception as exc:
                results[i] = exc
            ended[i] = True

        async with anyio.create_task_group() as waiters:
            for i in range(len(calls)):
                waiters.start_soon(wait, i)
            await anyio.sleep(0.05)
            assert not any(ended)
            assert path.unplug is not None
            unplugged = time.monotonic()
            path.unplug()
            with anyio.fail_after(1.0):
                while not all(ended):
                    await anyio.sleep(0.001)
            elapsed = time.monotonic() - unplugged
        assert all(isinstance(r, TransportError) for r in results), results
        assert elapsed < 0.1, f"waiters failed {elapsed * 1000:.1f} ms after the unplug"
        assert all(isinstance(r, BaseException) and r.__cause__ is not None for r in results)  # I/O error
        assert transport.state is TransportState.LOST
        with pytest.raises(TransportError, match="device lost"):
            path.request(99)
        await anyio.sleep(0.05)  # a batch already in the CAN writer thread reports back
        stats = transport.stats()
        assert (stats.losses, stats.purged, stats.queue_depth) == (1, 3 - stats.frames_out, 0)


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PTY_PATHS)
async def test_the_transport_reopens_when_the_device_returns_and_replays_nothing(
    name: str, tmp_path: Path
) -> None:
    async with open_path(name, tmp_path, reopen_backoff_s=(0.02, 0.1)) as path:
        transport = path.transport
        path.request(1)
        await within(2.0, transport.receive())
        await _stall_writer(path)
        assert path.unplug is not None and path.replug is not None
        path.unplug()
        with pytest.raises(TransportError):
            await within(1.0, transport.receive())
        await anyio.sleep(0.3)  # several reopen attempts fail while the device is away
        assert transport.state is TransportState.LOST
        await path.replug()
        await transport.wait_open(timeout=5.0)
        path.request(2)
        reply = await within(2.0, transport.receive())
        assert path.seq_of(path.reply_payload(reply)) == 2
        # The new device saw only what was sent after it came back: nothing queued before the loss.
        assert [path.seq_of(p) for p in path.peer_seen()] == [2]
        stats = transport.stats()
        assert (stats.losses, stats.reopens, stats.state) == (1, 1, TransportState.OPEN)


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", BACKENDS)  # (real time: real I/O)
@pytest.mark.parametrize("name", PATHS)
async def test_close_ends_async_iteration_and_pending_receivers_fail(name: str, tmp_path: Path) -> None:
    got: list[list[object]] = []
    # (the iterating task's group is entered before the link's: anyio nests task groups)
    async with anyio.create_task_group() as group, open_path(name, tmp_path) as path:
        transport = path.transport
        path.request(1)

        async def iterate() -> None:
            got.append([frame async for frame in transport])

        group.start_soon(iterate)
        await anyio.sleep(0.2)
        await transport.close()
        with anyio.fail_after(1.0):
            while not got:
                await anyio.sleep(0.001)
        assert len(got[0]) == 1
        with pytest.raises(TransportError, match="closed"):
            await transport.receive()
        assert transport.state is TransportState.CLOSED


# ================================================================ the link's side of the contract


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


class TaskClockSim(SimTransport):
    task_clock = True


class CopyingSim(SimTransport):
    """Sends a copy of every frame (as a link that re-encodes would): reports must echo the handle."""

    def send(self, frame: Frame, handle: object = None) -> None:
        super().send(dataclasses.replace(frame), frame if handle is None else handle)


class EchoLink(LinkBase):
    """A LinkBase link: each frame takes ``WIRE_S`` on the wire (a task of the link's own), then is
    reported sent and answered on ``id + 0x100``; frames still on the wire at close are reported
    purged."""

    name = "echo"
    rules = LineRules(bitrate=1_000_000, stale_after_s=0.5)
    WIRE_S = 0.001

    def send(self, frame: Frame, handle: object = None) -> None:
        if not self.is_open:
            raise TransportError(f"{self.name}: not open")
        self._tasks.start_soon(self._wire, self._outgoing(frame), self._handle(frame, handle))

    def _outgoing(self, frame: Frame) -> Frame:
        return frame

    async def _wire(self, frame: Frame, handle: object) -> None:
        try:
            await anyio.sleep(self.WIRE_S)
        except anyio.get_cancelled_exc_class():
            self._dropped("purged", [handle])
            raise
        self._sent(handle, self._now(), frame)
        reply = Frame(arbitration_id=frame.arbitration_id + 0x100, data=frame.data, timestamp=self._now())
        self._deliver([reply])


class CopyingEchoLink(EchoLink):
    def _outgoing(self, frame: Frame) -> Frame:
        return dataclasses.replace(frame)


def _tapped_sim() -> FrameLink:
    return TapLink(SimTransport(devices=[Responder(1)]), lambda *_: None, anyio.current_time)


#: every in-process link type, built fresh (a simulated responder on 0x141 answers on 0x241)
LINKS: dict[str, Callable[[], FrameLink]] = {
    "sim": lambda: SimTransport(devices=[Responder(1)]),
    "sim-task-clock": lambda: TaskClockSim(devices=[Responder(1)]),
    "sim-copying": lambda: CopyingSim(devices=[Responder(1)]),
    "tap-sim": _tapped_sim,
    "linkbase": EchoLink,
    "linkbase-copying": CopyingEchoLink,
}


@dataclasses.dataclass(eq=False)
class Handle:
    """A sender's handle (the Bus passes its Request): compared by identity."""

    n: int


class Reports:
    """What a link reported, by handle identity."""

    def __init__(self) -> None:
        self.calls: list[tuple[object, float | None, str | None]] = []

    def __call__(self, handle: object, sent_at: float | None, reason: str | None) -> None:
        self.calls.append((handle, sent_at, reason))

    def of(self, handle: object) -> list[tuple[float | None, str | None]]:
        return [(at, why) for h, at, why in self.calls if h is handle]


def _request(n: int) -> Frame:
    return Frame(arbitration_id=0x141, data=bytes([n, 0, 0, 0, 0, 0, 0, 0]))


@pytest.mark.anyio
@pytest.mark.parametrize("kind", LINKS)
async def test_every_link_declares_its_rules_and_counts(kind: str) -> None:
    link = LINKS[kind]()
    assert isinstance(link, FrameLink)
    assert isinstance(link.rules, LineRules)
    assert isinstance(link.stats(), TransportStats)
    assert not link.is_open
    async with link:
        assert link.is_open
        link.send(_request(1))
        with anyio.fail_after(1.0):
            while link.stats().frames_out < 1:
                await anyio.sleep(0.0005)
    stats = link.stats()
    assert stats.frames_out == 1 and stats.state is TransportState.CLOSED
    assert not link.is_open


@pytest.mark.anyio
@pytest.mark.parametrize("kind", LINKS)
async def test_every_accepted_frame_is_reported_once_with_the_handle_it_was_given(kind: str) -> None:
    link = LINKS[kind]()
    reports = Reports()
    received: list[Frame] = []
    link.set_send_reporter(reports)
    link.set_consumer(received.extend)
    handles = [Handle(n) for n in range(5)]
    frames = [_request(n) for n in range(6)]
    async with link:
        for frame, handle in zip(frames, handles, strict=False):
            sent_from = anyio.current_time()
            link.send(frame, handle)
        link.send(frames[5])  # no handle: the frame is the handle
        with anyio.fail_after(1.0):
            while len(received) < 6:
                await anyio.sleep(0.0005)
    for handle in handles:
        [(sent_at, reason)] = reports.of(handle)  # once, with this very object
        assert reason is None and sent_at is not None and sent_at >= sent_from
    [(sent_at, reason)] = reports.of(frames[5])
    assert reason is None
    assert len(reports.calls) == 6
    assert sorted(f.data[0] for f in received) == list(range(6))


@pytest.mark.anyio
@pytest.mark.parametrize("kind", ["linkbase", "linkbase-copying"])
async def test_frames_that_never_leave_are_reported_with_the_reason(kind: str) -> None:
    link = LINKS[kind]()
    reports = Reports()
    link.set_send_reporter(reports)
    handles = [Handle(n) for n in range(3)]
    async with link:
        for n, handle in enumerate(handles):
            link.send(_request(n), handle)
        # closed before they left: each is reported once, as purged
    assert [reports.of(h) for h in handles] == [[(None, "purged")]] * 3
    assert link.stats().purged == 3 and link.stats().frames_out == 0


@pytest.mark.anyio
@pytest.mark.parametrize("kind", ["sim", "sim-copying", "tap-sim"])
async def test_a_lost_sim_link_refuses_sends_and_reports_nothing_it_did_not_accept(kind: str) -> None:
    link = LINKS[kind]()
    reports = Reports()
    link.set_send_reporter(reports)
    async with link:
        sim = link._inner if isinstance(link, TapLink) else link
        assert isinstance(sim, SimTransport)
        sim.unplug()
        with pytest.raises(TransportError, match="lost"):
            link.send(_request(1), Handle(1))
    assert reports.calls == []


@pytest.mark.anyio
@pytest.mark.parametrize("kind", LINKS)
async def test_open_and_close_belong_to_one_task_and_nothing_runs_after_close(kind: str) -> None:
    link = LINKS[kind]()
    before = len(anyio.get_running_tasks())
    refused: list[RuntimeError] = []

    async def close_elsewhere() -> None:
        try:
            await link.close()
        except RuntimeError as exc:
            refused.append(exc)

    await link.open()
    link.send(_request(1))
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(close_elsewhere)
    assert refused and "task that opened it" in str(refused[0])
    assert link.is_open
    await link.close()
    assert len(anyio.get_running_tasks()) == before
    await link.close()  # twice is harmless


@pytest.mark.anyio
async def test_a_failing_consumer_or_reporter_is_logged_and_the_link_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The owner's callbacks run inside the link's own code (here, a task of the link): their error
    is logged and reaches neither that task nor the next frame."""
    calls: list[str] = []

    def consumer(frames: list[Frame]) -> None:
        calls.append("frames")
        raise ValueError("the consumer's bug")

    def reporter(handle: object, sent_at: float | None, reason: str | None) -> None:
        calls.append("report")
        raise KeyError("the reporter's bug")

    async with EchoLink() as link:
        link.set_consumer(consumer)
        link.set_send_reporter(reporter)
        for n in range(2):
            link.send(Frame(arbitration_id=0x141, data=bytes([n])))
            await anyio.sleep(0.01)
        assert link.is_open
    assert calls == ["report", "frames"] * 2
    assert "the consumer's bug" in caplog.text and "the reporter's bug" in caplog.text

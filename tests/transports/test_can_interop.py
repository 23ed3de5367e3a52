"""CanTransport beside an application that owns python-can already: its open bus, its Notifier.

Real python-can ``virtual`` buses throughout; the motors are the simulator served on a python-can
bus of the same channel (``servobus.sim.attach.serve_python_can``).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import AsyncIterator, Iterator

import anyio
import can
import pytest
from can.interfaces.virtual import VirtualBus

from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_python_can
from servobus.sim.network import SimCanNetwork
from servobus.transports import CanTransport, TransportState

from ._anyio_help import needs_bus_on, serving, within

pytestmark = pytest.mark.anyio


@pytest.fixture
def app_bus(channel: str) -> Iterator[can.BusABC]:
    """The application's own bus: servobus must leave it open."""
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


@pytest.fixture
def peer(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


class _Collect(can.Listener):
    """An application listener: what the application's notifier hands it."""

    def __init__(self) -> None:
        self.ids: list[int] = []
        self.got = threading.Event()

    def on_message_received(self, msg: can.Message) -> None:
        self.ids.append(msg.arbitration_id)
        self.got.set()


async def _until(predicate: object, timeout: float = 2.0) -> None:
    with anyio.fail_after(timeout):
        while not predicate():  # type: ignore[operator]
            await anyio.sleep(0.005)


async def test_an_open_application_bus_is_used_and_left_open(app_bus: can.BusABC, peer: can.BusABC) -> None:
    transport = CanTransport(app_bus)
    assert transport.name == f"can:virtual:{app_bus.channel_info}"
    async with transport:
        transport.send(Frame(arbitration_id=0x141, data=b"\x9c"))
        sent = await anyio.to_thread.run_sync(peer.recv, 2.0)
        assert sent is not None and (sent.arbitration_id, bytes(sent.data)) == (0x141, b"\x9c")
        peer.send(can.Message(arbitration_id=0x241, data=b"\x01", is_extended_id=False))
        assert await within(2.0, transport.receive()) == Frame(arbitration_id=0x241, data=b"\x01")
    assert transport.state is TransportState.CLOSED
    app_bus.send(can.Message(arbitration_id=0x7, data=b"", is_extended_id=False))  # still open: no raise
    assert peer.recv(2.0) is not None


async def test_beside_the_applications_notifier_both_get_every_frame(
    app_bus: can.BusABC, peer: can.BusABC
) -> None:
    mine = _Collect()
    notifier = can.Notifier(app_bus, [mine], timeout=0.01)
    try:
        async with CanTransport(app_bus, notifier=notifier) as transport:
            for ident in (0x241, 0x242):
                peer.send(can.Message(arbitration_id=ident, data=b"\x00", is_extended_id=False))
            got = [await within(2.0, transport.receive()) for _ in range(2)]
            assert [f.arbitration_id for f in got] == [0x241, 0x242]
            await _until(lambda: len(mine.ids) == 2)
        assert notifier.listeners == [mine]  # servobus took itself off, the notifier reads on
        mine.got.clear()
        peer.send(can.Message(arbitration_id=0x243, data=b"", is_extended_id=False))
        assert await anyio.to_thread.run_sync(mine.got.wait, 2.0) and mine.ids[-1] == 0x243
    finally:
        notifier.stop()


async def test_a_bus_with_a_running_notifier_is_joined_not_read_a_second_time(
    app_bus: can.BusABC, peer: can.BusABC
) -> None:
    mine = _Collect()
    notifier = can.Notifier(app_bus, [mine], timeout=0.01)
    try:
        async with CanTransport(app_bus) as transport:
            assert len(notifier.listeners) == 2  # it joined the notifier: no reader of its own
            for i in range(20):
                peer.send(can.Message(arbitration_id=0x241, data=bytes([i]), is_extended_id=False))
            got = [await within(2.0, transport.receive()) for _ in range(20)]
            assert [f.data[0] for f in got] == list(range(20))  # none lost to a competing recv()
            await _until(lambda: len(mine.ids) == 20)
    finally:
        notifier.stop()


async def test_receive_ids_on_an_application_bus_filter_here_and_leave_its_filters(
    app_bus: can.BusABC, peer: can.BusABC
) -> None:
    app_bus.set_filters([{"can_id": 0x200, "can_mask": 0x700, "extended": False}])
    before = app_bus.filters
    async with CanTransport(app_bus, receive_ids=[0x241]) as transport:
        transport.set_receive_ids([0x241, 0x243])
        assert app_bus.filters == before
        for ident in (0x242, 0x241, 0x244, 0x243):
            peer.send(can.Message(arbitration_id=ident, data=b"", is_extended_id=False))
        got = [await within(2.0, transport.receive()) for _ in range(2)]
        assert [f.arbitration_id for f in got] == [0x241, 0x243]
    assert app_bus.filters == before


def test_an_open_bus_takes_no_python_can_configuration(app_bus: can.BusABC) -> None:
    with pytest.raises(ValueError, match="takes no channel"):
        CanTransport(app_bus, "other")
    with pytest.raises(TypeError, match=r"interface name or a can\.BusABC"):
        CanTransport(42)  # type: ignore[arg-type]


@contextlib.asynccontextmanager
async def _motors_on(channel: str, *ids: int) -> AsyncIterator[None]:
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        async with serving(serve_python_can(SimCanNetwork([MyActuatorMotor(i) for i in ids]), bus)):
            yield
    finally:
        bus.shutdown()


async def test_a_servobus_bus_runs_on_the_applications_bus_and_notifier(
    channel: str, app_bus: can.BusABC
) -> None:
    needs_bus_on()
    mine = _Collect()
    notifier = can.Notifier(app_bus, [mine], timeout=0.01)
    try:
        async with _motors_on(channel, 1, 2), Bus(CanTransport(app_bus, notifier=notifier)) as bus:
            one, two = bus.motor("myactuator", 1), bus.motor("myactuator", 2)
            assert isinstance(await one.read_status2(timeout_s=1.0), ma.StatusReply)
            replies = await bus.cycle([(one, ma.ReadStatus1()), (two, ma.ReadStatus1())], timeout_s=1.0)
            assert all(isinstance(r, ma.Status1Reply) for r in replies)
        assert {0x241, 0x242} <= set(mine.ids)  # the application heard the replies too
        app_bus.send(can.Message(arbitration_id=0x7, data=b"", is_extended_id=False))  # still open
    finally:
        notifier.stop()


class _Vanishing(VirtualBus):
    """A python-can bus whose device goes away on cue (recv raises an OS error, as socketcan does)."""

    gone = False

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.gone:
            raise can.CanOperationError("device gone") from OSError(19, "No such device")
        return super().recv(timeout)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
async def test_a_device_lost_under_the_applications_notifier_is_a_loss_and_the_notifier_decides(
    channel: str,
) -> None:
    bus = _Vanishing(channel=channel)
    notifier = can.Notifier(bus, [], timeout=0.01)
    try:
        async with CanTransport(bus, notifier=notifier) as transport:
            bus.gone = True
            await _until(lambda: transport.state is TransportState.LOST)
            await _until(lambda: notifier.exception is not None)  # not handled by servobus: it stops
    finally:
        notifier.stop()
        bus.shutdown()

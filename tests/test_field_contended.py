"""A second controller on the bus (issue [field], case 3): another host sends its own requests to
our motors at 500 Hz, the motors answer it on the identifier and DATA[0] they answer us on. Its
replies must never be taken as ours: the two hosts command different speeds (ours +100 dps, the
other -50 dps) and a device model that puts the set-point of the request it answers into its reply
tells which request a reply is for. On the project's simulator in virtual time, plus the scheduler's
rules without I/O and one run through python-can's ``virtual`` bus.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import anyio
import pytest

from _setpoint_motor import SetpointMotor
from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.scheduler import Received, Scheduler, Traffic
from servobus.sim import virtual
from servobus.sim.otherhost import OtherHost
from servobus.transports.sim import SimTransport

OURS_DPS, THEIRS_DPS = 100.0, -50.0
MOTORS = (1, 2, 3)


async def _cycles_per_s(bus: Bus, batch: list[Any], hz: float, seconds: float) -> float:
    """Cycle ``batch`` at ``hz`` for ``seconds``; the cycles a second it kept."""
    start = anyio.current_time()
    ticks = 0
    async for _ in bus.ticks(hz, spin_s=0.0):
        if anyio.current_time() - start >= seconds:
            break
        await bus.cycle(batch)
        ticks += 1
    return ticks / (anyio.current_time() - start)


def _watch_whose(bus: Bus, checked: list[int]) -> None:
    """From now on count the status replies ``bus`` takes as answers to its requests: ``checked[0]``
    all, ``[1]`` those carrying the other host's set-point, ``[2]`` of these the ones not marked as
    of unknown order (``request.crossed``)."""
    receive = bus.scheduler.receive

    def watch(frame: Frame, now: float) -> Received:
        got = receive(frame, now)
        if got.request is not None and isinstance(got.reply, ma.StatusReply):
            checked[0] += 1
            if got.reply.speed_dps != OURS_DPS:
                checked[1] += 1
                if not got.request.crossed:
                    checked[2] += 1
        return got

    bus.scheduler.receive = watch  # type: ignore[method-assign]


def _run(
    *, other: bool, hz: float = 200.0, seconds: float = 2.0, seed: int = 1, backend: str = "asyncio"
) -> tuple[float, int, int, Any]:
    """Our loop of SpeedControl(+100) at ``hz`` on three motors, with (or without) another host
    commanding -50 dps at 500 Hz: (ticks per second, replies taken, of which another host's, bus)."""
    devices: list[Any] = [SetpointMotor(i) for i in MOTORS]
    if other:
        codecs = [ma.FAMILY.bind(i) for i in MOTORS]
        devices.append(
            OtherHost.commanding(codecs, ma.SpeedControl(speed_dps=THEIRS_DPS), rate_hz=500, seed=seed)
        )
    checked = [0, 0, 0]

    async def main() -> tuple[float, Any]:
        async with Bus(SimTransport(devices=devices), safe=None) as bus:
            _watch_whose(bus, checked)
            batch = [(bus.motor("myactuator", i), ma.SpeedControl(speed_dps=OURS_DPS)) for i in MOTORS]
            return await _cycles_per_s(bus, batch, hz, seconds), bus

    rate, bus = virtual.run(main(), backend=backend)
    return rate, checked[0], checked[1], bus


@pytest.mark.parametrize(("seed", "backend"), [(1, "asyncio"), (2, "asyncio"), (3, "trio")])
def test_a_second_controller_s_replies_are_never_taken_as_ours(
    seed: int, backend: str, caplog: pytest.LogCaptureFixture
) -> None:
    clean_rate, _, _, _ = _run(other=False, backend=backend)
    with caplog.at_level("WARNING", logger="servobus.bus"):
        rate, taken, wrong, bus = _run(other=True, seed=seed, backend=backend)
    assert wrong == 0, f"{wrong} of {taken} replies taken were the other host's"
    assert taken >= 0.9 * 2.0 * 200 * len(MOTORS), taken
    assert rate >= 0.95 * clean_rate, (rate, clean_rate)
    for i in MOTORS:
        metrics = bus.motor("myactuator", i).metrics()
        assert metrics.contended > 0 and metrics.foreign_requests >= metrics.contended, metrics
    warnings = [r.getMessage() for r in caplog.records if "another host" in r.getMessage()]
    assert len(warnings) == len(MOTORS), warnings  # once per motor
    assert "0x141" in " ".join(warnings) and "per second" in warnings[0]


# ---- the rules, without I/O (servobus.scheduler._hosts) ----

STATUS_A2 = bytes.fromhex("A2 32 64 00 F4 01 2D 00")


def _theirs(motor: int, t: float, dps: float = THEIRS_DPS) -> Frame:
    """Another host's 0xA2 request to ``motor``, as our adapter receives it."""
    frame = ma.FAMILY.bind(motor).encode(ma.SpeedControl(speed_dps=dps))
    return Frame(arbitration_id=frame.arbitration_id, data=frame.data, timestamp=t)


def _reply(motor: int, t: float) -> Frame:
    return Frame(arbitration_id=0x240 + motor, data=STATUS_A2, timestamp=t)


def _ours(scheduler: Scheduler, codec: Any, at: float) -> Any:
    request = scheduler.request(codec, ma.SpeedControl(speed_dps=OURS_DPS), timeout_s=0.01)
    scheduler.submit(request, at)
    (sent,), _ = scheduler.poll(at)
    scheduler.sent(sent, at)
    return request


def test_a_request_of_another_host_before_ours_gets_the_first_reply() -> None:
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    assert scheduler.receive(_theirs(1, 0.0010), 0.0010).traffic is Traffic.OTHER_HOST
    ours = _ours(scheduler, codec, 0.0012)  # (handed over after theirs ended: theirs is answered first)
    first = scheduler.receive(_reply(1, 0.0015), 0.0015)
    assert first.traffic is Traffic.CONTENDED and first.request is None and ours.state.value == "sent"
    assert isinstance(first.reply, ma.StatusReply)  # (the motor's state, for subscribers)
    second = scheduler.receive(_reply(1, 0.0018), 0.0018)
    assert second.request is ours
    counts = scheduler.motor_counts[id(codec)]
    assert counts["contended"] == 1 and counts["foreign_requests"] == 1 and scheduler.counts["foreign"] == 0


def test_a_request_of_another_host_after_ours_leaves_ours_the_first_reply() -> None:
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    ours = _ours(scheduler, codec, 0.0010)
    scheduler.receive(_theirs(1, 0.0013), 0.0013)  # ended well after ours was handed over
    assert scheduler.receive(_reply(1, 0.0014), 0.0014).request is ours
    assert scheduler.receive(_reply(1, 0.0017), 0.0017).traffic is Traffic.CONTENDED
    # ... and while theirs is still owed its reply, our next request's reply is not taken for it
    scheduler.receive(_theirs(1, 0.0020), 0.0020)
    later = _ours(scheduler, codec, 0.0021)
    assert scheduler.receive(_reply(1, 0.0023), 0.0023).traffic is Traffic.CONTENDED
    assert scheduler.receive(_reply(1, 0.0026), 0.0026).request is later


def test_a_request_of_another_host_that_is_never_answered_stops_counting() -> None:
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    scheduler.receive(_theirs(1, 0.0010), 0.0010)
    ours = _ours(scheduler, codec, 0.5)  # (its reply was due long ago: lost, or not to be)
    assert scheduler.receive(_reply(1, 0.5005), 0.5005).request is ours


@pytest.mark.parametrize("is_rx", [False, True], ids=["looped back as sent", "echoed as received"])
def test_our_own_frame_looped_back_is_not_another_host_s(is_rx: bool) -> None:
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    ours = _ours(scheduler, codec, 0.0010)
    own = ours.frame
    back = Frame(arbitration_id=own.arbitration_id, data=own.data, timestamp=0.0011, is_rx=is_rx)
    assert scheduler.receive(back, 0.0011).traffic is Traffic.FOREIGN  # (ours: no placeholder)
    assert scheduler.receive(_reply(1, 0.0014), 0.0014).request is ours
    assert scheduler.motor_counts[id(codec)]["foreign_requests"] == 0


def test_another_host_is_warned_of_once_per_motor_with_its_identifier_and_rate(
    caplog: pytest.LogCaptureFixture,
) -> None:
    codecs = [ma.FAMILY.bind(1), ma.FAMILY.bind(2)]
    scheduler = Scheduler(codecs)
    with caplog.at_level("WARNING", logger="servobus.bus"):
        for n in range(40):
            for motor in (1, 2):
                scheduler.receive(_theirs(motor, n * 0.002), n * 0.002)
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 2 and "0x141" in warnings[0] and "0x142" in warnings[1]
    assert "about 500 per second" in warnings[0]


def test_each_family_tells_another_host_s_request_by_its_identifier() -> None:
    v236, v235 = lk.FAMILY.bind(1), lk.FAMILY.bind(1, revision="V2_35")
    read = lk.ReadStatus2()
    request = v236.encode(read)
    received = Frame(arbitration_id=request.arbitration_id, data=request.data)
    assert v236.request_key(received) == v236.reply_key(read)
    assert v236.request_key(request) is None  # (our own, sent: is_rx False)
    assert v235.request_key(received) is None  # V2.35 replies on the request's id: not to be told apart
    hollow = ho.FAMILY.bind(20)
    frame = hollow.encode(ho.Setpoint(position_deg=1.0, speed_rad_s=0.0, kp=5, kd=1, current_a=0.0))
    assert hollow.request_key(dataclasses.replace(frame, is_rx=True)) == hollow.reply_key(ho.Stop())
    myactuator = ma.FAMILY.bind(3)
    write = ma.WriteEncoderZero(offset_counts=-1)  # an echo reply: keyed with the value written
    sent = myactuator.encode(write)
    assert myactuator.request_key(dataclasses.replace(sent, is_rx=True)) == myactuator.reply_key(write)
    assert myactuator.request_key(_theirs(4, 0.0)) is None  # another motor's


@pytest.mark.parametrize("family", ["lk", "hollow"])
def test_lk_and_hollow_requests_of_another_host_take_their_place_too(family: str) -> None:
    from servobus.protocols.hollow.sim.device import HollowMotor
    from servobus.protocols.lk.sim.device import LkMotor

    if family == "lk":
        codec, device, command = lk.FAMILY.bind(1), LkMotor(1), lk.ReadStatus2()
    else:
        codec, device = ho.FAMILY.bind(20), HollowMotor(20)
        command = ho.Setpoint(position_deg=1.0, speed_rad_s=0.0, kp=5, kd=1, current_a=0.0)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    request = codec.encode(command)
    theirs = Frame(
        arbitration_id=request.arbitration_id,
        data=request.data,
        is_extended_id=request.is_extended_id,
        timestamp=0.001,
    )
    (emission,) = device.receive(theirs, 0.001)
    reply = emission.frame
    assert scheduler.receive(theirs, 0.001).traffic is Traffic.OTHER_HOST
    ours = scheduler.request(codec, command, timeout_s=0.01)
    scheduler.submit(ours, 0.0012)
    (out,), _ = scheduler.poll(0.0012)
    scheduler.sent(out, 0.0012)
    assert (
        scheduler.receive(dataclasses.replace(reply, timestamp=0.0015), 0.0015).traffic is Traffic.CONTENDED
    )
    assert scheduler.receive(dataclasses.replace(reply, timestamp=0.0018), 0.0018).request is ours


def test_our_own_frame_looped_back_orders_ours_against_another_host_s_exactly() -> None:
    """Ours was handed over at 1.0 ms but waited for the wire until 1.6 ms (SocketCAN's loop-back
    says when it left); theirs ended at 1.3 ms: theirs reached the motor first."""
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001)
    ours = _ours(scheduler, codec, 0.0010)
    scheduler.receive(_theirs(1, 0.0013), 0.0013)
    own = ours.frame
    back = Frame(arbitration_id=own.arbitration_id, data=own.data, timestamp=0.0016, is_rx=False)
    assert scheduler.receive(back, 0.0016).traffic is Traffic.FOREIGN
    assert ours.on_wire_at == 0.0016
    assert scheduler.receive(_reply(1, 0.0017), 0.0017).traffic is Traffic.CONTENDED
    assert scheduler.receive(_reply(1, 0.0020), 0.0020).request is ours


# ---- real transport paths: python-can's ``virtual`` bus and the SLCAN adapter on a pty ----
#
# Here our request and another host's cross with the adapters' latencies in between (a reader
# thread, the simulator's own hand-overs, a serial line): milliseconds, not one frame's time. What
# cannot be ordered is answered with the later of the two replies and counted ``ambiguous``
# (servobus.scheduler._hosts); what can be ordered must be right.


def _run_real(
    path: str, *, other: bool, hz: float = 200.0, seconds: float = 1.5
) -> tuple[float, int, int, int, Any]:
    """Our 200 Hz loop of SpeedControl(+100) on three motors through ``path`` ("virtual": CanTransport
    on python-can's virtual bus; "slcan": the native SLCAN transport on a pty), in real time, with
    (or without) another host at 500 Hz: (ticks per second, replies taken, of which another host's,
    of those not marked as of unknown order, metrics)."""
    import time as _time

    import can

    from servobus.sim.attach import serve_python_can, serve_slcan
    from servobus.sim.network import SimCanNetwork
    from servobus.sim.pty import PtyPort
    from servobus.transports import CanTransport, SlcanTransport

    devices: list[Any] = [SetpointMotor(i) for i in MOTORS]
    if other:
        codecs = [ma.FAMILY.bind(i) for i in MOTORS]
        devices.append(
            OtherHost.commanding(codecs, ma.SpeedControl(speed_dps=THEIRS_DPS), rate_hz=500, seed=1)
        )
    network = SimCanNetwork(devices)
    checked = [0, 0, 0]

    async def main() -> tuple[float, Any]:
        port: PtyPort | None = None
        sim_side: can.BusABC | None = None
        transport: Any
        if path == "virtual":
            channel = f"contended-{_time.monotonic_ns()}"
            sim_side = can.Bus(interface="virtual", channel=channel)
            serve = serve_python_can(network, sim_side)
            transport = CanTransport("virtual", channel, ignore_config=True)
        else:
            port = PtyPort()
            serve = serve_slcan(network, port)
            transport = SlcanTransport(port.path, bitrate=1_000_000)
        try:
            with anyio.fail_after(seconds + 10):
                async with anyio.create_task_group() as group:
                    group.start_soon(lambda: serve)
                    async with Bus(transport, safe=None) as bus:
                        motors = [bus.motor("myactuator", i) for i in MOTORS]
                        batch = [(m, ma.SpeedControl(speed_dps=OURS_DPS)) for m in motors]
                        await bus.cycle(batch, timeout_s=0.5)  # (the first exchange through a fresh adapter)
                        # Another host's requests received before the motors were added are not
                        # known (counted foreign): their replies may still come now.
                        await anyio.sleep(0.05)
                        _watch_whose(bus, checked)
                        rate = await _cycles_per_s(bus, batch, hz, seconds)
                    group.cancel_scope.cancel()
        finally:
            if port is not None:
                port.close()
            if sim_side is not None:
                sim_side.shutdown()
        return rate, bus

    rate, bus = anyio.run(main)
    return rate, checked[0], checked[1], checked[2], bus


@pytest.mark.parametrize("path", ["virtual", "slcan"])
def test_on_a_real_transport_path_no_reply_of_another_host_is_taken_as_ours_unmarked(path: str) -> None:
    """Real time, about 4 s. Every reply taken as ours that was the other host's is one whose order
    could not be known, and counted ``ambiguous``; the loop keeps its rate. At 100 Hz: ours waits
    for the later of two replies when they crossed, about a millisecond more, which a 200 Hz tick
    on this path (replies 1-5 ms through the reader thread or the pty) does not always have."""
    clean_rate, clean_taken, _, _, _ = _run_real(path, other=False, hz=100)
    rate, taken, wrong, unmarked, bus = _run_real(path, other=True, hz=100)
    metrics = bus.metrics()
    print(
        f"\n{path}: clean {clean_rate:.1f}/s, {clean_taken} replies; with another host {rate:.1f}/s, "
        f"{taken} replies taken, {wrong} the other host's ({unmarked} unmarked), "
        f"ambiguous {metrics.ambiguous}, contended {metrics.contended}, timeouts {metrics.timeouts}"
    )
    assert unmarked == 0, f"{unmarked} of {taken} replies taken were the other host's, not marked: {metrics}"
    assert wrong <= metrics.ambiguous, metrics
    # (real time on a shared machine: typically 96-100 % of clean, 79 % seen under load;
    # the 95 % bound is held in virtual time, by the simulator's test above. This catches a
    # collapse: ours starved of replies by other hosts' requests, as a chain of them could)
    assert rate >= 0.5 * clean_rate, (rate, clean_rate)
    assert taken >= 0.5 * clean_taken, (taken, clean_taken, metrics)
    assert metrics.contended > 0


def test_through_an_adapter_a_crossing_of_unknown_order_gives_ours_the_later_reply_counted() -> None:
    """Times off by an adapter's latency (``exact_order`` False): another host's request stamped
    after ours was handed over may have reached the motor before or after it."""
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler([codec], min_reply_s=0.0001, exact_order=False)
    counts = scheduler.motor_counts[id(codec)]
    # stamped before ours was handed over: first for sure, nothing ambiguous
    scheduler.receive(_theirs(1, 0.0010), 0.0010)
    ours = _ours(scheduler, codec, 0.0012)
    assert scheduler.receive(_reply(1, 0.0030), 0.0030).traffic is Traffic.CONTENDED
    assert scheduler.receive(_reply(1, 0.0031), 0.0031).request is ours and not ours.crossed
    assert counts["ambiguous"] == 0
    # stamped after ours was handed over (well after, by the times: they say nothing here)
    later = _ours(scheduler, codec, 0.0100)
    scheduler.receive(_theirs(1, 0.0105), 0.0105)
    scheduler.receive(_theirs(1, 0.0106), 0.0106)  # (a second one: after ours)
    assert scheduler.receive(_reply(1, 0.0107), 0.0107).traffic is Traffic.CONTENDED
    assert scheduler.receive(_reply(1, 0.0108), 0.0108).request is later and later.crossed
    assert scheduler.receive(_reply(1, 0.0109), 0.0109).traffic is Traffic.CONTENDED
    assert counts["ambiguous"] == 1 and counts["contended"] == 3
    # a reply received before their request answers ours, by order alone
    last = _ours(scheduler, codec, 0.0200)
    assert scheduler.receive(_reply(1, 0.0210), 0.0210).request is last and not last.crossed
    assert scheduler.receive(_theirs(1, 0.0205), 0.0211).traffic is Traffic.OTHER_HOST
    assert scheduler.receive(_reply(1, 0.0212), 0.0212).traffic is Traffic.CONTENDED


def test_a_reply_later_than_another_host_s_was_expected_is_counted_ambiguous() -> None:
    """Another host's request whose reply is overdue (a stalled host, a slow adapter) may still be
    answered: our request handed over meanwhile that takes the next reply is counted ambiguous."""
    codec = ma.FAMILY.bind(1)
    scheduler = Scheduler(
        [codec], min_reply_s=0.0001, exact_order=False, initial_timeout_s=0.002, min_timeout_s=0.001
    )
    scheduler.receive(_theirs(1, 0.0010), 0.0010)  # (its reply expected within twice 2 ms)
    ours = _ours(scheduler, codec, 0.0012)
    assert scheduler.receive(_reply(1, 0.0080), 0.0080).request is ours and ours.crossed
    assert scheduler.motor_counts[id(codec)]["ambiguous"] == 1

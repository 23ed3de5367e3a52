"""Devices on the simulated CAN bus in virtual time (servobus.sim.network).

The devices here are minimal stand-ins (tests/sim/_standins.py) so the network's own rules are
tested apart from any protocol; the family device models have their own tests on this network.
"""

from __future__ import annotations

import math

import pytest

from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel
from servobus.sim.faults import FaultInjector, FaultPlan
from servobus.sim.network import SimCanNetwork
from servobus.timing import CLASSIC_8_BYTE_STANDARD_BITS

from ._standins import TURNAROUND_S, Responder, Streamer


def _request(motor_id: int) -> Frame:
    return Frame(arbitration_id=0x140 + motor_id, data=bytes([0x9C, motor_id, 0, 0, 0, 0, 0, 0]))


def test_thirty_two_request_reply_pairs_fit_the_bit_count_bound_plus_turnaround() -> None:
    network = SimCanNetwork([Responder(i) for i in range(1, 33)])
    for i in range(1, 33):
        network.send(_request(i), 0.0)
    received = network.run_until_idle()
    assert sorted(f.arbitration_id for _, f in received) == [0x240 + i for i in range(1, 33)]
    lo, hi = CLASSIC_8_BYTE_STANDARD_BITS
    assert 64 * lo / 1e6 <= network.bus.busy_s <= 64 * hi / 1e6
    # The host's 32 requests leave back to back; each reply waits for its turnaround, then the wire.
    last_end = received[-1][0]
    assert network.bus.busy_s <= last_end <= network.bus.busy_s + TURNAROUND_S


def test_replies_ready_together_leave_in_identifier_order() -> None:
    devices = [Responder(i) for i in (9, 2, 30, 5)]
    network = SimCanNetwork(devices)
    for device in devices:  # requests queued in this order by the host...
        network.send(_request(device.motor_id), 0.0)
    received = network.run_until_idle()
    # ...and leave back to back (0x14x beats every 0x24x reply); a reply is ready 100 µs after its
    # request, shorter than one frame, so the replies contend once the requests are out and leave
    # by identifier, not in the order their requests went.
    assert [f.arbitration_id - 0x240 for _, f in received] == [2, 5, 9, 30]


def test_every_device_sees_every_frame_but_its_own() -> None:
    a, b = Responder(1), Responder(2)
    network = SimCanNetwork([a, b])
    network.send(_request(1), 0.0)
    network.run_until_idle()
    assert [f.arbitration_id for _, f in a.seen] == [0x141]  # not its own reply 0x241
    assert [f.arbitration_id for _, f in b.seen] == [0x141, 0x241]


def test_spontaneous_frames_follow_the_device_deadline() -> None:
    network = SimCanNetwork([Streamer(period_s=0.010)])
    received = network.advance(0.0505)
    assert len(received) == 6  # t = 0, 10, ..., 50 ms
    assert received[1][0] == pytest.approx(0.010 + received[0][0])


def test_faults_towards_the_host_are_seeded() -> None:
    def run(seed: int) -> list[tuple[float, Frame]]:
        network = SimCanNetwork(
            [Responder(i) for i in range(1, 33)],
            to_host=FaultInjector(FaultPlan(drop=0.2, delay=0.2, duplicate=0.1), seed),
        )
        for i in range(1, 33):
            network.send(_request(i), 0.0)
        return network.run_until_idle()

    first = run(4)
    assert first == run(4)
    assert len(first) != 32 or first != run(5)


def test_slower_bit_rate_stretches_the_same_traffic() -> None:
    fast = SimCanNetwork([Responder(1)])
    slow = SimCanNetwork([Responder(1)], bus=CanBusModel(bitrate=500_000))
    for network in (fast, slow):
        network.send(_request(1), 0.0)
    (t_fast, _), (t_slow, _) = fast.run_until_idle()[0], slow.run_until_idle()[0]
    assert t_slow - TURNAROUND_S == pytest.approx(2 * (t_fast - TURNAROUND_S))


def test_names_are_unique() -> None:
    with pytest.raises(ValueError, match="already on this bus"):
        SimCanNetwork([Responder(1), Responder(1)])


def test_a_zero_latency_bus_leaves_only_the_turnaround() -> None:
    network = SimCanNetwork([Responder(i) for i in (3, 1, 2)], bus=CanBusModel(bitrate=math.inf))
    for motor_id in (3, 1, 2):
        network.send(_request(motor_id), 0.0)
    received = network.run_until_idle()
    assert [(t, f.arbitration_id) for t, f in received] == [
        (TURNAROUND_S, 0x241),
        (TURNAROUND_S, 0x242),
        (TURNAROUND_S, 0x243),
    ]
    assert network.bus.busy_s == 0.0

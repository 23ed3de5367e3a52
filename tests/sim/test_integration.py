"""The simulator end to end with real device models: the [sim] issue's bus-level promises.

* python-can's own ``slcan`` interface, over a pty, exchanges frames with 32 simulated motors;
* in virtual time, 32 request/reply pairs of 8-byte frames occupy 7.10..8.64 ms of a 1 Mbit/s bus
  (111..135 bits a frame) plus the modelled turnaround, and contending replies leave by identifier.
"""

from __future__ import annotations

import asyncio
import contextlib

import can
import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.ids import BROADCAST_ID, reply_id, request_id
from servobus.protocols.myactuator.sim.device import DEFAULT_TURNAROUND_S, MyActuatorMotor
from servobus.sim.attach import serve_slcan
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort

READ_STATUS_2 = ma.ReadStatus2().encode()


def _network() -> SimCanNetwork:
    return SimCanNetwork([MyActuatorMotor(i) for i in range(1, 33)])


def test_thirty_two_pairs_take_the_bit_count_bound_plus_turnaround_in_virtual_time() -> None:
    network = _network()
    for motor_id in range(1, 33):
        network.send(Frame(arbitration_id=request_id(motor_id), data=READ_STATUS_2), 0.0)
    received = network.run_until_idle()
    assert sorted(f.arbitration_id for _, f in received) == [reply_id(i) for i in range(1, 33)]
    assert all(isinstance(ma.decode_reply(f.arbitration_id, f.data), ma.StatusReply) for _, f in received)
    assert 7.10e-3 <= network.bus.busy_s <= 8.64e-3
    # the wire never idles longer than one turnaround: the last reply ends by busy time + turnaround
    assert network.bus.busy_s <= received[-1][0] <= network.bus.busy_s + DEFAULT_TURNAROUND_S


def test_replies_ready_together_leave_in_identifier_order() -> None:
    network = _network()
    network.send(Frame(arbitration_id=BROADCAST_ID, data=READ_STATUS_2), 0.0)  # one frame, 32 replies
    received = network.run_until_idle()
    ids = [f.arbitration_id for _, f in received]
    assert ids == sorted(ids) and len(ids) == 32


@pytest.mark.asyncio
async def test_python_can_slcan_exchanges_frames_with_thirty_two_simulated_motors() -> None:
    network = _network()
    port = PtyPort()
    serving = asyncio.ensure_future(serve_slcan(network, port))
    bus = can.Bus(interface="slcan", channel=port.path, bitrate=1_000_000, sleep_after_open=0)

    def exchange() -> list[can.Message]:
        for motor_id in range(1, 33):
            bus.send(
                can.Message(arbitration_id=request_id(motor_id), data=READ_STATUS_2, is_extended_id=False)
            )
        replies = []
        while len(replies) < 32 and (message := bus.recv(timeout=2.0)) is not None:
            replies.append(message)
        return replies

    try:
        replies = await asyncio.to_thread(exchange)
    finally:
        bus.shutdown()
        serving.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await serving
        port.close()
    assert sorted(m.arbitration_id for m in replies) == [reply_id(i) for i in range(1, 33)]
    for message in replies:
        reply = ma.decode_reply(message.arbitration_id, bytes(message.data))
        assert isinstance(reply, ma.StatusReply) and reply.temperature_c > 0

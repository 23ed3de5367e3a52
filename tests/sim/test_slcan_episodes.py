"""The simulated SLCAN adapter's controller episodes (issue [field], case 4): a frame it cannot
transmit (transmit FIFO full, or bus-off) is answered BEL, as LAWICEL's adapters do, and never
reaches the bus; ``F`` says why; while bus-off nothing is received. Sans-IO, then on the pty under the
native SlcanTransport: refused frames are counted (bells), the adapter is no lost device, and the
motors answer again after the episode.
"""

from __future__ import annotations

import collections

import anyio
import pytest

from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_slcan
from servobus.sim.episodes import ControllerEpisodes, Episode
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.sim.slcan import SlcanAdapter
from servobus.transports import SlcanTransport

LINE = b"t1418" + b"9C" + b"00" * 7 + b"\r"


def _adapter() -> SlcanAdapter:
    episodes = ControllerEpisodes(
        [
            Episode(kind="queue_full", start_s=1.0, duration_s=1.0),
            Episode(kind="bus_off", start_s=3.0, duration_s=1.0),
        ]
    )
    adapter = SlcanAdapter(episodes=episodes)
    assert adapter.receive(b"S8\rO\r", 0.0) == (b"\r\r", [])
    return adapter


def test_a_frame_the_controller_cannot_send_is_answered_bel_and_status_says_why() -> None:
    adapter = _adapter()
    frame = Frame(arbitration_id=0x141, data=bytes([0x9C]) + bytes(7))
    answers = []
    for now_s in (0.5, 1.5, 2.5, 3.5, 4.5):
        answer, frames = adapter.receive(LINE + b"F\r", now_s)
        answers.append((answer, frames, adapter.to_host(frame, now_s)))
    line = b"t1418" + b"9C" + b"00" * 7 + b"\r"
    assert answers == [
        (b"z\rF00\r", [frame], line),
        (b"\aF02\r", [], line),  # transmit FIFO full: not sent, still receiving
        (b"z\rF00\r", [frame], line),
        (b"\aFA4\r", [], b""),  # bus-off: not sent, nothing received
        (b"z\rF00\r", [frame], line),
    ]
    assert (adapter.refused, adapter.errors) == (2, 2)


@pytest.mark.anyio
async def test_on_the_pty_refused_frames_are_counted_and_the_motors_answer_after_the_episode() -> None:
    ids = range(1, 5)
    episodes = ControllerEpisodes([Episode(kind="queue_full", start_s=0.5, duration_s=0.5)])
    adapter = SlcanAdapter(episodes=episodes)
    port = PtyPort()
    transport = SlcanTransport(port.path, bitrate=1_000_000)
    ticks: list[tuple[float, list[object]]] = []
    try:
        with anyio.fail_after(20):
            async with anyio.create_task_group() as group:
                group.start_soon(serve_slcan, SimCanNetwork([MyActuatorMotor(i) for i in ids]), port, adapter)
                async with Bus(transport, safe=None, probe_interval_s=0.05) as bus:
                    batch = [(bus.motor("myactuator", i), ma.ReadStatus2()) for i in ids]
                    start = anyio.current_time()
                    async for _ in bus.ticks(100.0, spin_s=0.0):
                        now = anyio.current_time() - start
                        if now >= 2.0:
                            break
                        ticks.append((now, list(await bus.cycle(batch))))
                    stats, bells = transport.stats(), transport.line_counters()["bells"]
                group.cancel_scope.cancel()
    finally:
        port.close()
    assert adapter.refused > 0 and bells == adapter.refused  # each refused frame counted on the host
    assert stats.losses == stats.reopens == 0  # a BEL is no lost adapter
    # Its requests are not failed fast (a BEL names no frame: the C de-framer counts it), they time
    # out and the watchdog skips and probes the motors; after the episode they answer again (in real
    # time on a shared machine a reply misses its floor now and then: most, not all).
    after = [r for at, results in ticks if at >= 1.6 for r in results]
    kinds = collections.Counter(type(r).__name__ for r in after)
    assert kinds["StatusReply"] >= 0.5 * len(after), kinds

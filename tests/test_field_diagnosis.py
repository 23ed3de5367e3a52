"""[field] case 7: "no reply" says what the bus saw instead. A request that times out carries a
diagnosis (``MotorTimeout.diagnosis``, also the end of its message): frames of another family on the
motor's ids, frames on other ids (and whose motors would send them), or no frame at all. On the
project's simulator in virtual time, on asyncio and on trio; :class:`~servobus.diagnosis.Seen` and
the wording without a Bus.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import anyio
import pytest

from _backends import BACKENDS
from servobus.bus import Bus
from servobus.errors import MotorTimeout
from servobus.frame import Frame
from servobus.protocols import Command, get_family, lk
from servobus.protocols import myactuator as ma
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.attach import serve_slcan
from servobus.sim.device import Emission
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort
from servobus.transports import SlcanTransport
from servobus.transports.sim import SimTransport
from transports._anyio_help import serving

#: what a silent line is told (servobus.diagnosis.NOTHING_AT_ALL; said here too, so that this module
#: runs against a servobus without it, and fails there by its assertions)
NOTHING_AT_ALL = "no frame at all: check bitrate, wiring and termination, or another program on the port"


@dataclass
class OtherHost:
    """A second controller on the bus: reads the status of ``ids`` every ``period_s`` (MyActuator's
    0x9C on 0x140+ID), so their replies are on the bus though this Bus asks them nothing."""

    ids: Sequence[int]
    period_s: float = 0.01
    name: str = "other host"
    _next_s: float = 0.0
    sent: list[Frame] = field(default_factory=list)

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        return []

    def poll(self, now_s: float) -> list[Emission]:
        if now_s < self._next_s:
            return []
        self._next_s = now_s + self.period_s
        return [
            Emission(now_s, Frame(arbitration_id=0x140 + i, data=bytes([0x9C, 0, 0, 0, 0, 0, 0, 0])))
            for i in self.ids
        ]

    def next_deadline_s(self) -> float | None:
        return self._next_s


def _timeout(
    devices: list[Any], family: str, motor_id: int, command: Command, backend: str = "asyncio"
) -> MotorTimeout:
    """The MotorTimeout of one request to ``family``'s motor ``motor_id`` on a bus of ``devices``."""

    async def main() -> MotorTimeout:
        async with Bus(SimTransport(devices=devices), safe=None) as bus:
            motor = bus.motor(family, motor_id)
            await motor.request(command, timeout_s=0.05)  # (the line warms: frames come meanwhile)
            raise AssertionError("answered")

    try:
        virtual.run(main(), backend=backend)
    except MotorTimeout as exc:
        return exc
    raise AssertionError("no timeout")


@pytest.mark.parametrize("backend", BACKENDS)
def test_lk_motors_read_as_myactuator_are_named_with_the_family_to_use(backend: str) -> None:
    exc = _timeout([LkMotor(1)], "myactuator", 1, ma.ReadStatus2(), backend)
    assert exc.diagnosis == "0x181 answered as lk (V2_36) would: --family lk?"
    assert str(exc).endswith("no reply within 50 ms; 0x181 answered as lk (V2_36) would: --family lk?")


def test_an_old_lk_motor_replies_on_its_request_id_and_is_named_with_its_revision() -> None:
    exc = _timeout(
        [LkMotor(1, model=lk.LkModel(revision=lk.Revision.V2_35))], "myactuator", 1, ma.ReadStatus2()
    )
    assert exc.diagnosis == "0x141 answered as lk (V2_35) would: --family lk --revision V2_35?"


def test_myactuator_motors_read_as_lk_are_named_too() -> None:
    exc = _timeout([MyActuatorMotor(2)], "lk", 2, lk.ReadStatus2())
    assert exc.diagnosis is not None and "0x242 answered as myactuator" in exc.diagnosis
    assert exc.diagnosis.endswith("--family myactuator?")


@pytest.mark.parametrize("backend", BACKENDS)
def test_frames_on_other_ids_name_the_motors_that_send_them(backend: str) -> None:
    """Motors 5-8 answer another host; ours (1) is not there: the ids to try are named."""
    devices = [*(MyActuatorMotor(i) for i in range(5, 9)), OtherHost(range(5, 9))]
    exc = _timeout(devices, "myactuator", 1, ma.ReadStatus2(), backend)
    assert exc.diagnosis is not None
    assert "20 frames on 0x145-0x148: another host's requests to myactuator motors 5-8" in exc.diagnosis
    assert "on 0x245-0x248, as myactuator motors 5-8 would answer: other ids (--ids 5-8)?" in exc.diagnosis


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_silent_line_says_no_frame_at_all(backend: str) -> None:
    exc = _timeout([], "myactuator", 1, ma.ReadStatus2(), backend)
    assert exc.diagnosis == NOTHING_AT_ALL
    assert "check bitrate, wiring and termination, or another program on the port" in str(exc)


def test_a_silent_motor_among_answering_ones_is_told_apart_from_a_silent_line() -> None:
    async def main() -> MotorTimeout:
        async with Bus(SimTransport(devices=[MyActuatorMotor(2)]), safe=None) as bus:
            results = await bus.cycle(
                [(bus.motor("myactuator", i), ma.ReadStatus2()) for i in (1, 2)], timeout_s=0.05
            )
            assert isinstance(results[0], MotorTimeout) and not isinstance(results[1], Exception)
            return results[0]

    exc = virtual.run(main())
    assert exc.diagnosis == "other frames came, none from motor 1: check its id, power and wiring"


def test_seen_keeps_the_ids_seen_last_with_counts() -> None:
    from servobus.diagnosis import Seen

    seen = Seen(limit=3)
    for at, ident in enumerate([0x181, 0x182, 0x181, 0x183, 0x184]):
        seen.note(Frame(arbitration_id=ident, data=b"\x9c"), float(at))
    assert [hex(e.frame.arbitration_id) for e in seen.since(0.0)] == ["0x181", "0x183", "0x184"]  # 0x182 out
    assert [e.count for e in seen.since(0.0)] == [2, 1, 1]
    assert [e.frame.arbitration_id for e in seen.since(3.0)] == [0x183, 0x184]


def test_the_diagnosis_without_a_bus() -> None:
    from servobus.diagnosis import NOTHING_AT_ALL as SAID
    from servobus.diagnosis import Seen, diagnose, explain

    assert SAID == NOTHING_AT_ALL
    codec = get_family("myactuator").bind(1)
    seen = Seen()
    assert diagnose(codec, seen, 0.0, heard=False) == NOTHING_AT_ALL
    request = codec.encode(ma.ReadStatus2())
    seen.note(request, 1.0)  # an adapter that echoes our own frame is no witness
    assert diagnose(codec, seen, 0.0, heard=False, sent=request) == NOTHING_AT_ALL
    seen.note(Frame(arbitration_id=0x7FF, data=b"\x01\x02"), 2.0)
    assert diagnose(codec, seen, 0.0, heard=True, sent=request) == (
        "1 frame on 0x7FF, which no known family's motor sends"
    )
    assert diagnose(codec, seen, 3.0, heard=False) == NOTHING_AT_ALL  # (before the request left)
    assert explain([]) is None


@pytest.mark.anyio
async def test_through_slcan_on_a_pty_the_timeout_names_the_family_that_answered() -> None:
    """The same through a real link: the simulator's SLCAN adapter on a pty, an LK motor behind it,
    asked as a MyActuator motor, in real time."""
    port = PtyPort()
    try:
        with anyio.fail_after(10):
            network = SimCanNetwork([LkMotor(3)])
            transport = SlcanTransport(port.path, bitrate=1_000_000)
            async with serving(serve_slcan(network, port)), Bus(transport, safe=None) as bus:
                with pytest.raises(MotorTimeout) as raised:
                    await bus.motor("myactuator", 3).request(ma.ReadStatus1(), timeout_s=0.3)
    finally:
        port.close()
    assert raised.value.diagnosis == "0x183 answered as lk (V2_36) would: --family lk?"

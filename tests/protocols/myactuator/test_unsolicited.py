"""Frames a motor sends of itself, and the echo after a trip, at the codec and the scheduler (sans-IO).

Every unsolicited frame of every family has a name (issue [field], case 1):

=========== ===================================== ==========================================
family      frame                                 classified / decoded / counted as
=========== ===================================== ==========================================
myactuator  0xF1 on 0x240+ID (0xB3 trip)          REPORT, ``CommunicationTimeoutTripped``,
                                                  ``comm_tripped`` (and ``report``)
myactuator  0x9A on 0x240+ID (0x20 index 3 on)    REPORT, ``Status1Reply``, ``report``
myactuator  streamed command on 0x240+ID (0xB6)   STREAM, the command's reply, ``stream``
lk          none (the manuals: one reply per request)
hollow      none ("a pure slave ... no unsolicited frames", hollow.md)
=========== ===================================== ==========================================
"""

from __future__ import annotations

from typing import Any

import pytest

from servobus import Frame
from servobus.errors import MotorNotExecuted, ProtocolError
from servobus.protocols import FrameKind, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.hollow.sim.device import HollowMotor
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.codec import COMMANDS
from servobus.protocols.myactuator.codec import request_frame as ma_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.scheduler import Request, RequestState, Scheduler, Traffic
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import Off, PositionControl

MA = get_family("myactuator")
TRIP = bytes.fromhex("F1 00 00 00 00 00 00 00")
CONTROL = ma.AbsolutePositionControl(angle_deg=90.0, max_speed_dps=None)


def _frame(data: bytes, motor: int = 1, t: float = 0.0) -> Frame:
    return Frame(arbitration_id=0x240 + motor, data=data, timestamp=t)


# ---- the codec ----


@pytest.mark.parametrize("data", [TRIP, b"\xf1", bytes.fromhex("F1 01 02 03 04 05 06 07")])
def test_a_0xf1_frame_is_a_named_report_not_malformed(data: bytes) -> None:
    codec = MA.bind(1)
    kind, key = codec.classify(_frame(data))
    assert kind is FrameKind.REPORT and key is not None
    event = codec.decode(_frame(data))
    assert isinstance(event, ma.CommunicationTimeoutTripped)
    assert (event.EVENT, event.EVENT_REASON) == ("comm_tripped", "communication watchdog tripped (0xF1)")
    assert ma.decode_reply(0x241, data) == event and event.encode() == TRIP
    assert codec.classify(_frame(data, motor=2))[0] is FrameKind.NOT_OURS


def test_the_other_unsolicited_frames_keep_their_names() -> None:
    codec = MA.bind(1)
    codec.note_sent(ma.FunctionControl(index=ma.FunctionIndex.ERROR_REPORTING, value=1))
    codec.note_sent(
        ma.ActiveReply(command=ma.StreamableCommand.MULTI_TURN_ANGLE, enabled=True, interval_ms=10)
    )
    status1 = ma.Status1Reply(
        temperature_c=30,
        mos_temperature_c=30,
        voltage_v=24.0,
        brake_released=True,
        errors=ma.ErrorFlags.LOW_VOLTAGE,
    )
    assert codec.classify(_frame(status1.encode()))[0] is FrameKind.REPORT
    assert codec.classify(_frame(ma.MultiTurnAngleReply(angle_deg=1.0).encode()))[0] is FrameKind.STREAM


def test_control_commands_declare_that_their_reply_is_never_their_own_bytes() -> None:
    never = {c.__name__ for c in COMMANDS if c.NEVER_ECHOED}
    assert never == {
        "TorqueControl", "SpeedControl", "AbsolutePositionControl", "SingleTurnPositionControl",
        "IncrementalPositionControl", "ForcePositionControl", "PositionSpeedFeedforward",
        "PositionTorqueFeedforward",
    }  # fmt: skip
    # Not a read (its reply may be all zeros) nor a write answered by its own bytes (0x81, 0xB3, ...)
    assert not any(c.READ or ma.Echo in c.reply_types() for c in COMMANDS if c.NEVER_ECHOED)


def test_may_echo_holds_for_every_command_from_a_0xf1_until_the_motor_speaks_again() -> None:
    codec = MA.bind(1)
    stop = ma.MotorStop()
    assert codec.may_echo(CONTROL) and not codec.may_echo(stop) and not codec.may_echo(ma.ReadStatus2())
    codec.classify(_frame(TRIP))
    assert codec.may_echo(stop) and codec.may_echo(ma.ReadStatus2())
    codec.classify(_frame(TRIP))  # repeated about every second: still tripped
    codec.note_sent(ma.FunctionControl(index=ma.FunctionIndex.ERROR_REPORTING, value=1))
    report = ma.Status1Reply(temperature_c=30, mos_temperature_c=30, voltage_v=24.0, brake_released=False)
    codec.classify(_frame(report.encode()))  # an error report answers nothing: still tripped
    assert codec.may_echo(stop)
    codec.classify(_frame(stop.encode()))  # the echo (or any other frame of the motor)
    assert not codec.may_echo(stop) and codec.may_echo(CONTROL)


def test_the_other_families_declare_no_echo() -> None:
    for family, command in (("lk", lk.ReadStatus1()), ("hollow", ho.Start())):
        motor = 3 if family == "lk" else 20
        assert not get_family(family).bind(motor).may_echo(command)


# ---- the scheduler ----


def _sent(scheduler: Scheduler, command: ma.MyActuatorCommand, at: float) -> Request:
    codec = scheduler.codecs[0]
    request = scheduler.request(codec, command)
    scheduler.submit(request, at)
    out, _ = scheduler.poll(at)
    assert out == [request]
    scheduler.sent(request, at)
    return request


def test_a_control_commands_own_bytes_fail_it_as_not_executed_and_count() -> None:
    scheduler = Scheduler([MA.bind(1)])
    request = _sent(scheduler, CONTROL, 0.0)
    assert request.echo == CONTROL.encode()
    got = scheduler.receive(_frame(CONTROL.encode(), t=0.001), 0.001)
    assert (got.traffic, got.request, got.reply) == (Traffic.NOT_EXECUTED, request, None)
    assert request.state is RequestState.FAILED and request.reply is None
    assert isinstance(request.error, MotorNotExecuted) and request.error.command == 0xA4
    assert request.error.raw == CONTROL.encode() and "echoed back (A4 00 00 00 28 23 00 00)" in str(
        request.error
    )
    assert scheduler.counts["not_executed"] == 1 and scheduler.counts["failed"] == 1
    # the same bytes again are its duplicate, not anyone's reply
    assert scheduler.receive(_frame(CONTROL.encode(), t=0.002), 0.002).traffic is Traffic.DUPLICATE
    # sent again, its real reply answers it
    again = _sent(scheduler, CONTROL, 0.01)
    real = ma.StatusReply(
        command=ma.StatusCommand.ABSOLUTE_POSITION,
        temperature_c=31,
        current_a=0.5,
        speed_dps=0.0,
        angle_deg=3.0,
    )
    got = scheduler.receive(_frame(real.encode(), t=0.011), 0.011)
    assert got.traffic is Traffic.REPLY and again.reply == real


def test_a_stop_is_judged_an_echo_only_while_the_trip_is_known() -> None:
    scheduler = Scheduler([MA.bind(1)])
    stop = ma.MotorStop()
    normal = _sent(scheduler, stop, 0.0)
    assert normal.echo is None  # its real reply is its own bytes
    assert scheduler.receive(_frame(stop.encode(), t=0.001), 0.001).request is normal
    trip = scheduler.receive(_frame(TRIP, t=0.5), 0.5)
    assert trip.traffic is Traffic.REPORT and isinstance(trip.reply, ma.CommunicationTimeoutTripped)
    echoed = _sent(scheduler, stop, 0.6)
    got = scheduler.receive(_frame(stop.encode(), t=0.601), 0.601)
    assert got.traffic is Traffic.NOT_EXECUTED and isinstance(echoed.error, MotorNotExecuted)
    acknowledged = _sent(scheduler, stop, 0.7)
    assert scheduler.receive(_frame(stop.encode(), t=0.701), 0.701).request is acknowledged
    assert acknowledged.state is RequestState.REPLIED


def test_only_a_frame_whose_data0_is_0xf1_reads_as_the_trip() -> None:
    with pytest.raises(ProtocolError, match=r"DATA\[0\] is not 0xF1"):
        ma.CommunicationTimeoutTripped.decode(b"\xf2")


# ---- the other families send nothing of themselves ----


@pytest.mark.parametrize("family", ["lk", "hollow"])
def test_lk_and_hollow_motors_send_nothing_unasked(family: str) -> None:
    device = LkMotor(3) if family == "lk" else HollowMotor(20)
    network = SimCanNetwork([device])
    codec = get_family(family).bind(3 if family == "lk" else 20)
    command = lk.ReadStatus1() if family == "lk" else ho.Start()
    network.send(codec.encode(command), 0.0)
    heard = network.advance(5.0)
    assert len(heard) == 1 and codec.classify(heard[0][1])[0] is FrameKind.REPLY


# ---- the simulated motor: 0xF1 at the trip and every second, the echo, on both paths ----


def _trip_run(network_class: type[SimCanNetwork | CoreCanNetwork], **options: Any) -> tuple[Any, ...]:
    motor = MyActuatorMotor(1, **options)
    network = network_class([motor])

    def send(command: ma.MyActuatorCommand, at: float) -> None:
        frame = ma_frame(command, 1)
        network.send(frame, at)

    send(ma.SetCommTimeout(timeout_ms=50), 0.0)
    send(ma.SpeedControl(speed_dps=100.0), 0.01)
    heard = network.advance(2.6)  # quiet after 0.01: the protection trips 50 ms after that frame
    tripped_control = motor.control
    send(CONTROL, 2.6)
    heard += network.advance(2.62)
    echoed_control = motor.control
    send(CONTROL, 2.62)  # within the 50 ms: no new trip
    heard += network.advance(2.64)
    return heard, dict(motor.counters), tripped_control, echoed_control, motor.control


@pytest.mark.parametrize("network_class", [SimCanNetwork, CoreCanNetwork])
def test_the_simulated_motor_sends_0xf1_at_the_trip_and_each_second_and_echoes_the_next_command(
    network_class: type[SimCanNetwork | CoreCanNetwork],
) -> None:
    heard, counters, tripped, echoed, executed = _trip_run(network_class)
    trips = [t for t, f in heard if f.data == TRIP]
    assert len(trips) == 3 and trips[1] - trips[0] == pytest.approx(1.0, abs=1e-3)
    assert trips[2] - trips[0] == pytest.approx(2.0, abs=1e-3)
    assert 0.06 < trips[0] < 0.0605  # at the trip: 50 ms after the speed frame ended on the wire
    answers = [f for t, f in heard if t > 2.6]
    assert answers[0].data == CONTROL.encode() and answers[0].arbitration_id == 0x241  # byte for byte
    assert isinstance(ma.decode_reply(0x241, answers[1].data), ma.StatusReply)
    assert answers[1].data != CONTROL.encode()
    assert isinstance(tripped, Off) and isinstance(echoed, Off)  # the echoed command did nothing
    assert isinstance(executed, PositionControl)
    assert (counters["comm_timeouts"], counters["comm_trip_frames"], counters["comm_echoed"]) == (1, 3, 1)
    assert counters["comm_restored"] == 1


def test_both_paths_of_the_simulator_agree_on_a_trip() -> None:
    python, core = _trip_run(SimCanNetwork), _trip_run(CoreCanNetwork)
    assert [(round(t, 9), f) for t, f in python[0]] == [(round(t, 9), f) for t, f in core[0]]
    assert python[1:] == core[1:]


def test_with_trip_echo_off_the_motor_does_as_the_manuals_read() -> None:
    heard, counters, _, echoed, _ = _trip_run(SimCanNetwork, trip_echo=False)
    assert not any(f.data[:1] == b"\xf1" for _, f in heard)
    assert isinstance(echoed, PositionControl) and "comm_echoed" not in counters

"""Each family's restart evidence (codec.RESTART), sans-IO: what proves a restart and what does not."""

from __future__ import annotations

from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols._restart import RestartEvidence, Seen

MA = ma.FAMILY.bind(1).RESTART
LK = lk.FAMILY.bind(1).RESTART
HO = ho.FAMILY.bind(1).RESTART


def _run_time(ms: int, at: float) -> dict[type, Seen]:
    return {ma.RunTimeReply: Seen(ma.RunTimeReply(run_time_ms=ms), at)}


def test_every_family_declares_its_evidence() -> None:
    for evidence in (MA, LK, HO):
        assert isinstance(evidence, RestartEvidence)
    assert MA is not None and [p.__name__ for p in MA.probes] == ["ReadRunTime"]
    assert LK is not None and [p.__name__ for p in LK.probes] == ["ReadMultiTurnAngle"]
    assert HO is not None and HO.probes == ()


def test_myactuator_a_run_time_behind_the_time_known_running_is_a_restart() -> None:
    assert MA is not None
    # first seen at 0.0; back at 1.34 reading 40 ms: it was powered up 1.3 s after it was seen
    assert "went back: 40 ms" in (MA.judge({}, _run_time(40, 1.34), 0.0) or "")
    # reading on since first seen (it was up 5 s before the host saw it): no restart
    assert MA.judge({}, _run_time(6_340, 1.34), 0.0) is None
    # seen within the slack of its power-up: cannot tell
    assert MA.judge({}, _run_time(5, 0.02), 0.0) is None


def test_myactuator_a_reading_below_the_last_one_plus_the_time_since_is_a_restart() -> None:
    assert MA is not None
    before = _run_time(10_000_000, 100.0)
    assert MA.judge(before, _run_time(10_001_000, 101.0), 0.0) is None
    assert MA.judge(before, _run_time(300_000, 101.0), 0.0) is not None  # backwards
    assert MA.judge(before, _run_time(900, 101.0), 0.0) is not None  # up 0.9 s of the last 1 s


def test_myactuator_a_reading_that_may_have_wrapped_proves_nothing() -> None:
    assert MA is not None
    near_wrap = 2**32 - 500
    assert MA.judge(_run_time(near_wrap, 100.0), _run_time(500, 101.0), 0.0) is None


def _angle(deg: float, at: float) -> dict[type, Seen]:
    return {lk.MultiTurnAngleReply: Seen(lk.MultiTurnAngleReply(angle_deg=deg), at)}


def test_lk_an_angle_folded_to_one_turn_is_a_restart_and_one_moved_on_is_not() -> None:
    assert LK is not None
    assert "1041.00° -> 323.00°" in (LK.judge(_angle(1041.0, 1.0), _angle(323.0, 1.4), 0.0) or "")
    assert LK.judge(_angle(1041.0, 1.0), _angle(1257.0, 1.4), 0.0) is None  # ran on
    assert LK.judge(_angle(200.0, 1.0), _angle(20.0, 1.4), 0.0) is None  # within its first turn
    assert LK.judge(_angle(370.0, 1.0), _angle(350.0, 1.4), 0.0) is None  # moved back a little
    assert LK.judge({}, _angle(20.0, 1.4), 0.0) is None  # never read before


def _position(deg: float, at: float) -> dict[type, Seen]:
    reply = ho.NormalReply(motor_id=1, position_deg=deg, speed_rad_s=0.0, current_a=0.0)
    return {ho.NormalReply: Seen(reply, at)}


def test_hollow_a_position_folded_to_one_turn_is_a_restart() -> None:
    assert HO is not None
    assert HO.judge(_position(360.0, 1.0), _position(64.0, 1.4), 0.0) is not None
    assert HO.judge(_position(300.0, 1.0), _position(350.0, 1.4), 0.0) is None
    assert HO.judge(_position(90.0, 1.0), _position(-90.0, 1.4), 0.0) is None

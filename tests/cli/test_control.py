"""The motor commands through the CLI against the simulator: status and monitor read, set-points move
the simulated motors and stop them at the end, one-shots send the family's command; bad values,
commands a family lacks and ROM writes without confirmation send nothing (one line, exit 2 or 1)."""

from __future__ import annotations

import time
from typing import Any

import pytest

from cli._bus_cli import Devices, keep_devices, one_line, pty_simulators, run, run_json
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.plant import Brake, Off, PositionControl, SpeedControl


@pytest.fixture
def received(monkeypatch: pytest.MonkeyPatch) -> list[Frame]:
    """Every frame the simulated MyActuator and LK motors receive."""
    frames: list[Frame] = []
    for cls in (MyActuatorMotor, LkMotor):

        def receive(self: Any, frame: Frame, now_s: float, _original: Any = cls.receive) -> Any:
            frames.append(frame)
            return _original(self, frame, now_s)

        monkeypatch.setattr(cls, "receive", receive)
    return frames


@pytest.fixture
def devices(monkeypatch: pytest.MonkeyPatch) -> Devices:
    return keep_devices(monkeypatch)


def test_status_reads_every_motor(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["status", "--sim", "3"])
    assert [r["id"] for r in rows] == [1, 2, 3]
    for row in rows:
        assert (
            row["temperature_c"] == 25
            and row["voltage_v"] > 0
            and row["errors"] == []
            and row["error"] is None
        )
    out, _ = run(capsys, ["status", "--sim", "2"])
    assert "angle_deg" in out and "temperature_c" in out


def test_status_of_lk_motors_reads_their_angle_too(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["status", "--family", "lk", "--sim", "2"])
    assert [r["id"] for r in rows] == [1, 2]
    assert all(r["angle_deg"] == 0.0 and r["speed_dps"] == 0.0 for r in rows)


def test_status_through_a_real_pty_and_a_missing_motor_is_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pty_simulators() as start:
        path = start("--family", "myactuator", "--motors", "3")
        rows = run_json(capsys, ["status", "-i", "servobus-slcan", "-c", path, "--ids", "1-3"])
        assert [r["id"] for r in rows] == [1, 2, 3] and all(r["error"] is None for r in rows)
        err = one_line(capsys, ["status", "-i", "servobus-slcan", "-c", path, "--ids", "2-4"], code=1)
        assert "1 of 3 motors failed" in err and "motor 4" in err


def test_monitor_prints_a_json_line_per_motor_and_sample(capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = run(capsys, ["monitor", "--sim", "2", "--rate-hz", "20", "--duration", "0.2", "--json"])
    lines = [__import__("json").loads(line) for line in out.splitlines()]
    assert len(lines) >= 4 and {line["id"] for line in lines} == {1, 2}
    assert all("angle_deg" in line and "t" in line for line in lines)


def test_move_reaches_the_angle_then_the_motors_hold(
    capsys: pytest.CaptureFixture[str], devices: Devices
) -> None:
    rows = run_json(capsys, ["move", "--sim", "2", "--angle-deg", "30", "--duration", "5"])
    assert all(abs(r["angle_deg"] - 30) <= 1 for r in rows), rows
    for motor in devices.last:  # the Bus's safe stop (0x81) on the way out: hold where it is
        assert (
            isinstance(motor.plant.control, PositionControl)
            and abs(motor.plant.control.position_deg - 30) <= 1.5
        )


@pytest.mark.parametrize("family", ["myactuator", "lk"])
def test_a_relative_move_is_sent_once_and_ends_where_it_was_asked(
    capsys: pytest.CaptureFixture[str], received: list[Frame], family: str
) -> None:
    """The increment goes out once: resent at --rate-hz, each resend would add another 10 degrees."""
    start = time.monotonic()
    args = ["move", "--family", family, "--sim", "1", "--angle-deg", "10", "--relative", "--duration", "3"]
    rows = run_json(capsys, args)
    assert abs(rows[0]["angle_deg"] - 10) <= 1, rows
    assert time.monotonic() - start < 2.5  # it ended on arrival, not at --duration
    code = {"myactuator": ma.IncrementalPositionControl.CODE, "lk": lk.IncrementalPositionSpeed.CODE}[family]
    assert [f.data[0] for f in received].count(code) == 1


def test_an_lk_move_reads_the_angle_and_ends_on_arrival(capsys: pytest.CaptureFixture[str]) -> None:
    """LK's position set-point replies carry no angle: the move reads it, or it would never arrive."""
    start = time.monotonic()
    rows = run_json(capsys, ["move", "--family", "lk", "--sim", "1", "--angle-deg", "20", "--duration", "5"])
    assert abs(rows[0]["angle_deg"] - 20) <= 1, rows
    assert time.monotonic() - start < 4


def test_speed_runs_for_the_duration_and_keep_leaves_it_running(
    capsys: pytest.CaptureFixture[str], devices: Devices
) -> None:
    rows = run_json(capsys, ["speed", "--sim", "1", "--speed-dps", "90", "--duration", "0.3"])
    assert rows[0]["speed_dps"] > 10
    assert isinstance(devices.last[0].plant.control, PositionControl)  # stopped at the end
    run_json(capsys, ["speed", "--sim", "1", "--speed-dps", "90", "--keep"])
    assert isinstance(devices.last[0].plant.control, SpeedControl)  # --keep: no stop


@pytest.mark.parametrize(
    "args",
    [
        ["torque", "--sim", "1", "--current-a", "0.3", "--duration", "0.1"],
        ["torque", "--family", "lk", "--sim", "1", "--current-a", "0.3", "--duration", "0.1"],
        ["mit", "--sim", "1", "--position-rad", "0.5", "--kp", "20", "--kd", "1", "--duration", "0.1"],
        ["move", "--family", "lk", "--sim", "1", "--angle-deg", "10", "--duration", "0.1"],
        ["move", "--family", "hollow", "--sim", "1", "--angle-deg", "10", "--duration", "2"],
        ["speed", "--family", "hollow", "--sim", "1", "--speed-dps", "30", "--duration", "0.1"],
        ["move", "--sim", "1", "--angle-deg", "10", "--relative", "--duration", "0.1"],
    ],
)
def test_setpoints_of_each_family_get_replies(capsys: pytest.CaptureFixture[str], args: list[str]) -> None:
    rows = run_json(capsys, args)
    assert rows and all(r["error"] is None for r in rows)


@pytest.mark.parametrize(
    ("args", "sent", "state"),
    [
        (["stop", "--sim", "1"], "MotorStop", None),
        (["off", "--sim", "1"], "MotorShutdown", (Off, Brake)),
        (["brake", "--sim", "1", "--release"], "BrakeRelease", None),
        (["brake", "--family", "lk", "--sim", "1", "--lock"], "BrakeControl", None),
        (["reset", "--sim", "1"], "SystemReset", None),
        (["clear-errors", "--family", "lk", "--sim", "1"], "ClearErrors", None),
        (["stop", "--family", "hollow", "--sim", "2"], "Stop", Off),
        (["zero", "--family", "hollow", "--sim", "1"], "SetZero", None),
    ],
)
def test_one_shots_send_the_family_command(
    capsys: pytest.CaptureFixture[str],
    devices: Devices,
    args: list[str],
    sent: str,
    state: type | tuple[type, ...] | None,
) -> None:
    rows = run_json(capsys, args)
    assert all(r["sent"][-1] == sent and r["error"] is None for r in rows), rows
    if state is not None:
        assert all(isinstance(m.plant.control, state) for m in devices.last)


def test_one_shot_replies_are_shown_as_decode_and_record_show_them(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """One rendering of a reply's fields in the whole CLI: servobus.tools.logs.message_values (flat scalars,
    units in the names, flags as their int), under "fields" as in decode --json."""
    rows = run_json(capsys, ["clear-errors", "--family", "lk", "--sim", "1"])
    reply = rows[0]["replies"][0]
    assert reply["type"] == "Status1Reply"
    assert reply["fields"] == {
        "command": 0x9B,
        "temperature_c": 25,
        "voltage_v": 24.0,
        "current_a": 0.0,
        "motor_state": "ON",
        "error_state": 0,
    }
    out, _ = run(capsys, ["clear-errors", "--family", "lk", "--sim", "1"])
    assert "voltage_v=24.0" in out and "error_state=0" in out
    echo = run_json(capsys, ["brake", "--sim", "1", "--lock"])[0]["replies"][0]
    assert echo == {"type": "Echo", "fields": {"command": "BrakeLock"}}


def test_reset_gets_no_reply_by_the_manual(capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = run(capsys, ["reset", "--sim", "1"])
    assert "no reply by the manual" in out


def test_zero_and_set_id_write_rom_only_when_confirmed(
    capsys: pytest.CaptureFixture[str], devices: Devices
) -> None:
    err = one_line(capsys, ["zero", "--sim", "1"], code=1)  # stdin is empty: no answer
    assert "not confirmed" in err and not devices.made  # nothing opened, nothing sent
    run_json(capsys, ["zero", "--sim", "1", "--yes"])
    rows = run_json(capsys, ["set-id", "--sim", "1", "--ids", "1", "7", "--yes"])
    assert rows[0]["sent"] == ["FunctionControl"]
    assert devices.last[0].rom.motor_id == 7  # in ROM; the id changes after a reset


def test_zero_asks_and_a_yes_sends(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from click.testing import CliRunner

    from servobus.cli import cli

    declined = CliRunner().invoke(cli, ["zero", "--sim", "1"], input="n\n")
    assert declined.exit_code == 1 and "Continue?" in declined.output
    accepted = CliRunner().invoke(cli, ["zero", "--sim", "1"], input="y\n")
    assert accepted.exit_code == 0 and "ZeroOffsetReply" in accepted.output


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["speed", "--sim", "1", "--speed-dps", "1e9"], "speed_dps"),
        (["mit", "--sim", "1", "--position-rad", "20", "--kp", "1", "--kd", "1"], "position_rad"),
        (["torque", "--sim", "1", "--current-a", "lots"], "--current-a"),
        (["move", "--sim", "1", "--angle-deg", "10", "--max-speed-dps", "0"], "--max-speed-dps"),
        (["move", "--sim", "1"], "--angle-deg"),
        (["brake", "--sim", "1"], "--lock"),
        (["set-id", "--sim", "2", "5", "--yes"], "one id"),
        (["set-id", "--sim", "1", "40", "--yes"], "[1, 32]"),
        (["clear-errors", "--sim", "1"], "myactuator motors have no clear-errors"),
        (["mit", "--family", "lk", "--sim", "1", "--position-rad", "0", "--kp", "1", "--kd", "0"], "no mit"),
        (["status", "--family", "hollow", "--sim", "1"], "hollow motors have no status"),
        (["brake", "--family", "hollow", "--sim", "1", "--lock"], "no brake"),
        (["move", "--family", "hollow", "--sim", "1", "--fd", "--angle-deg", "5"], "classic CAN only"),
        (["speed", "--family", "lk", "--revision", "V2_35", "--sim", "1", "--speed-dps", "1e9"], "speed_dps"),
        (["status", "--sim", "1", "--bogus"], "--bogus"),
        (["status", "--sim", "0"], "--sim 0"),
        (["status", "--sim", "1", "--revision", "V9"], "no revision 'V9'"),
        (["status", "--sim", "2", "--ids", "3-1"], "empty"),
        (["status", "--sim", "2", "--ids", "1-1000000000"], "--ids"),  # refused, not built
        (["status", "-i", "servobus-slcan"], "-c"),
        (["monitor", "--sim", "1", "--rate-hz", "0"], "--rate-hz"),
        # NaN passes click's ranges (every comparison is false): a --duration nan never ends
        (["speed", "--sim", "1", "--speed-dps", "30", "--duration", "nan"], "--duration"),
        (["speed", "--sim", "1", "--speed-dps", "30", "--rate-hz", "nan"], "--rate-hz"),
        (["move", "--sim", "1", "--angle-deg", "5", "--tolerance-deg", "nan"], "--tolerance-deg"),
        (["monitor", "--sim", "1", "--rate-hz", "nan"], "--rate-hz"),
        (["record", "--sim", "1", "--log", "x.log", "--hz", "nan"], "--hz"),
        (["demo", "--duration", "nan"], "--duration"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2_with_nothing_sent(
    capsys: pytest.CaptureFixture[str], devices: Devices, args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args, code=2)
    assert not devices.made  # refused before a bus was opened

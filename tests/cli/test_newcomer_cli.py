"""The first hour's CLI rough edges (issue 25, "Smaller"): negative values, a setting's range in one
line, a closed stdout, Ctrl-C at a question, run-time ValueErrors, the demo's why line, LK speed."""

from __future__ import annotations

import subprocess

import click
import pytest

from cli._bus_cli import SERVOBUS, Devices, keep_devices, one_line, run, run_json


@pytest.mark.parametrize(
    "args",
    [
        ["speed", "--sim", "1", "--speed-dps", "-30", "--duration", "0.1"],
        ["move", "--sim", "1", "--angle-deg", "-90", "--duration", "0.1"],
        ["torque", "--sim", "1", "--current-a", "-0.5", "--duration", "0.1"],
        ["torque", "--family", "lk", "--sim", "1", "--current-a", "-1.2", "--duration", "0.1"],
    ],
)
def test_negative_option_values_need_no_double_dash(
    capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    rows = run_json(capsys, args)
    assert rows[0]["error"] is None


def test_a_negative_setting_value_needs_no_double_dash(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    devices = keep_devices(monkeypatch)
    args = ["config", "set", "--sim", "1", "limit.max_negative_angle_raw", "-9000", "--yes"]
    assert run_json(capsys, args)[0]["value"] == -9000 and devices.made
    err = one_line(capsys, ["config", "set", "--sim", "1", "position_acceleration_dps_s", "-5", "--yes"])
    assert "acceleration_dps_s=-5.0 is outside [0, 60000]" in err  # the range, not "No such option"
    assert "No such option '-x'" in one_line(
        capsys, ["config", "set", "--sim", "1", "pid.speed_kp", "1", "-x"]
    )


@pytest.mark.parametrize(
    ("value", "naming"),
    [("1e12", "is outside [0, 4294967295]"), ("1.5", "not a whole number"), ("abc", "not a number")],
)
def test_a_setting_out_of_range_is_one_line_naming_it_and_its_range(
    capsys: pytest.CaptureFixture[str], value: str, naming: str
) -> None:
    err = one_line(capsys, ["config", "set", "--sim", "1", "comm_timeout_ms", value, "--yes"])
    assert f"comm_timeout_ms {value}: " in err and naming in err and "invalid literal" not in err


@pytest.mark.parametrize(
    "args",
    [
        ["monitor", "--sim", "2", "--json", "--rate-hz", "200"],  # until stdout closes
        ["status", "--sim", "2"],  # a rich table
        ["speed", "--sim", "2", "--speed-dps", "20", "--duration", "0.2", "--json"],
    ],
)
def test_a_closed_stdout_ends_the_command_quietly_with_exit_0(args: list[str]) -> None:
    process = subprocess.Popen([*SERVOBUS, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stderr is not None
    if args[0] == "monitor":
        assert process.stdout.readline().startswith("{")
    process.stdout.close()  # as head does after its lines
    err = process.stderr.read()
    assert process.wait(timeout=30) == 0, err
    assert "Traceback" not in err and "error" not in err and "Exception ignored" not in err


def test_ctrl_c_at_a_question_exits_130_with_nothing_sent(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    devices: Devices = keep_devices(monkeypatch)

    def interrupted(prompt: str) -> str:
        raise KeyboardInterrupt

    monkeypatch.setattr(click.termui, "visible_prompt_func", interrupted)
    _, err = run(capsys, ["zero", "--sim", "1"], code=130)
    assert err.splitlines()[-1] == "servobus: interrupted: nothing was sent" and not devices.made
    _, err = run(capsys, ["config", "set", "--sim", "1", "comm_timeout_ms", "200"], code=130)
    assert err.splitlines()[-1] == "servobus: interrupted: nothing was sent" and not devices.made


def test_a_value_error_at_run_time_is_the_job_failing_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import servobus.cli._status_view as control

    def broken(*args: object, **kwargs: object) -> dict[str, object]:
        raise ValueError("a reply field out of its range")

    monkeypatch.setattr(control, "status_of", broken)
    assert "a reply field out of its range" in one_line(capsys, ["status", "--sim", "1"], code=1)
    # a value from the command line the library refuses is still bad usage
    assert "speed_dps" in one_line(capsys, ["speed", "--sim", "1", "--speed-dps", "1e9"], code=2)
    assert "no revision" in one_line(capsys, ["status", "--sim", "1", "--revision", "V9"], code=2)


def test_the_why_line_names_a_live_view_redraw_only_when_there_was_one() -> None:
    from servobus.cli._demo_report import Summary

    values = dict(
        hz=1000.0, motors=3, buses=1, seconds=5.0, ticks=4000, missed_ticks=1000, late_p99_ms=5.0,
        tick_p50_ms=0.3, wire_ms=0.75, pairs=12000, latency_p50_ms=0.2, latency_p99_ms=0.3,
        bus_load_mean_pct=10.0, bus_load_max_pct=10.5, timeouts=0, not_sent=0, malformed=0, faults=0,
        cpu_s=4.9, simulator_cpu_s=1.0,
    )  # fmt: skip
    under_duration = Summary(**values).why()  # type: ignore[arg-type]
    assert under_duration is not None and "paused now and then" in under_duration
    assert "live view" not in under_duration
    live = Summary(**values, live=True).why()  # type: ignore[arg-type]
    assert live is not None and "a redraw of the live view" in live
    assert "live" not in Summary(**values).as_dict()  # type: ignore[arg-type]


def test_lk_speed_is_sent_with_the_full_scale_current_limit_or_max_current_a(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["speed", "--family", "lk", "--sim", "1", "--speed-dps", "30", "--duration", "0.3"]
    assert run_json(capsys, args)[0]["error"] is None  # was: current_limit_a is required for MG
    assert run_json(capsys, [*args, "--max-current-a", "2"])[0]["error"] is None
    assert "current_limit_a=200.0 is outside" in one_line(capsys, [*args, "--max-current-a", "200"])


def test_max_current_a_limits_hollow_set_points_and_is_refused_where_nothing_carries_it(
    capsys: pytest.CaptureFixture[str],
) -> None:
    move = ["move", "--family", "hollow", "--sim", "1", "--angle-deg", "10", "--duration", "0.2"]
    assert run_json(capsys, [*move, "--max-current-a", "1"])[0]["error"] is None
    assert "current_a=1000.0 is outside" in one_line(capsys, [*move, "--max-current-a", "1000"])
    speed = ["speed", "--sim", "1", "--speed-dps", "30", "--duration", "0.2", "--max-current-a", "2"]
    assert "carries no current limit" in one_line(capsys, speed)


@pytest.mark.parametrize("family", ["myactuator", "lk", "hollow"])
def test_a_move_is_stopped_at_rest_not_while_still_coming_in_within_the_tolerance(
    capsys: pytest.CaptureFixture[str], family: str
) -> None:
    rows = run_json(capsys, ["move", "--family", family, "--sim", "1", "--angle-deg", "15"])
    assert abs(rows[0]["speed_dps"]) <= 1.0  # (LK was stopped at 14.79°, 5 dps: frozen short)
    assert rows[0]["angle_deg"] == pytest.approx(15.0, abs=0.1)
